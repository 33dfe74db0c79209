"""Contaminated scans for the robustness benchmark (``SimOptions.wrong_segments``, ``gross_outlier_frac``,
``mixed_pixel_frac``; all off by default).

Lidar frame ``{L}`` (scan plane z = 0), metres, radians. Every scan stays ordered by bearing. The random stream
is its own (``contamination_rng``), so switching contamination on leaves the geometry and the clean noise of a
trial as they were.
"""

from __future__ import annotations

import numpy as np

from .options import SimOptions

WRONG_RANGE_FACTOR = (0.85, 1.15)
"""The wrong object's centre lies at this factor times the board's range ..."""
WRONG_BEARING_DEG = 6.0
"""... within this many degrees of the board's bearing ..."""
WRONG_LENGTH_M = (0.5, 1.5)
"""... is a straight segment of this length (metres) ..."""
WRONG_FACING_DEG = 60.0
"""... whose normal is within this angle of the line of sight."""
GROSS_RANGE_M = (1.0, 30.0)
"""Range interval of gross outlier returns (metres)."""
BACKGROUND_GAP_M = (0.2, 3.0)
"""How far the background lies behind a board end (metres); a mixed pixel's range is between the two."""


def contamination_rng(seed: int, contamination_hash: int, trial: int) -> np.random.Generator:
    """The contamination stream of one trial (independent of the geometry, lidar and camera streams)."""
    return np.random.default_rng(np.random.SeedSequence(entropy=int(seed), spawn_key=(contamination_hash, int(trial))))


def _bearing(P: np.ndarray) -> np.ndarray:
    return np.arctan2(P[:, 1], P[:, 0])


def _polar(bearing: np.ndarray, rng_m: np.ndarray) -> np.ndarray:
    return np.column_stack([rng_m * np.cos(bearing), rng_m * np.sin(bearing)])


def wrong_segment(scan: np.ndarray, o: SimOptions, rng: np.random.Generator) -> np.ndarray:
    """A straight segment of another object near where ``scan`` (K,2) lies, sampled on the lidar's beam grid with
    the range noise; re-drawn until it has ``min_points_per_board`` points (falls back to the clean scan)."""
    c = scan.mean(axis=0)
    rho, beta = float(np.linalg.norm(c)), float(np.arctan2(c[1], c[0]))
    res = np.radians(o.lidar_res_deg)
    for _ in range(50):
        b = beta + np.radians(rng.uniform(-WRONG_BEARING_DEG, WRONG_BEARING_DEG))
        centre = rho * rng.uniform(*WRONG_RANGE_FACTOR) * np.array([np.cos(b), np.sin(b)])
        a = b + np.radians(rng.uniform(-WRONG_FACING_DEG, WRONG_FACING_DEG))
        n = np.array([np.cos(a), np.sin(a)])
        t = np.array([-n[1], n[0]])
        half = 0.5 * rng.uniform(*WRONG_LENGTH_M)
        ends = _bearing(np.array([centre - half * t, centre + half * t]))
        lo, hi = np.ceil(ends.min() / res), np.floor(ends.max() / res)
        bearings = np.arange(lo, hi + 1) * res
        u = np.column_stack([np.cos(bearings), np.sin(bearings)])
        r = (centre @ n) / (u @ n)
        r = r + rng.normal(0.0, o.noise_mm / 1000.0, len(r))
        if len(r) >= o.min_points_per_board and np.all(r > 0):
            return _polar(bearings, r)
    return scan


def add_gross_outliers(scan: np.ndarray, frac: float, rng: np.random.Generator) -> np.ndarray:
    """``scan`` plus ``round(frac K)`` returns at ranges uniform in ``GROSS_RANGE_M`` on bearings uniform within the
    scan's bearing span, merged in bearing order."""
    n = int(round(frac * len(scan)))
    if n == 0:
        return scan
    be = _bearing(scan)
    extra = _polar(rng.uniform(be.min(), be.max(), n), rng.uniform(*GROSS_RANGE_M, n))
    allp = np.concatenate([scan, extra])
    return allp[np.argsort(_bearing(allp), kind="stable")]


def add_mixed_pixels(scan: np.ndarray, frac: float, res_deg: float, rng: np.random.Generator) -> np.ndarray:
    """``scan`` plus ``round(frac K)`` mixed pixels on the beams just beyond its two ends (alternating), each at a
    range uniform between the end's range and a background ``BACKGROUND_GAP_M`` behind it."""
    n = int(round(frac * len(scan)))
    if n == 0:
        return scan
    be = _bearing(scan)
    order = np.argsort(be)
    res = np.radians(res_deg)
    out = [scan]
    for end, sign, count in ((order[0], -1.0, (n + 1) // 2), (order[-1], 1.0, n // 2)):
        if count == 0:
            continue
        r_end = float(np.linalg.norm(scan[end]))
        k = np.arange(1, count + 1)
        gap = rng.uniform(*BACKGROUND_GAP_M, count)
        out.append(_polar(be[end] + sign * k * res, r_end + rng.uniform(0.0, 1.0, count) * gap))
    allp = np.concatenate(out)
    return allp[np.argsort(_bearing(allp), kind="stable")]


def contaminate(scans: list[np.ndarray], o: SimOptions, rng: np.random.Generator) -> tuple[list[np.ndarray], list[int]]:
    """The scans with the options' contamination applied, and the indices of the boards given a wrong segment."""
    scans = list(scans)
    wrong = sorted(int(i) for i in rng.choice(len(scans), size=o.wrong_segments, replace=False)) \
        if o.wrong_segments else []
    for i in wrong:
        scans[i] = wrong_segment(scans[i], o, rng)
    if o.gross_outlier_frac > 0:
        scans = [add_gross_outliers(s, o.gross_outlier_frac, rng) for s in scans]
    if o.mixed_pixel_frac > 0:
        scans = [add_mixed_pixels(s, o.mixed_pixel_frac, o.lidar_res_deg, rng) for s in scans]
    return scans, wrong
