"""Time sync of an image stream and a scan stream: nearest-scan pairing within a tolerance, and an estimate of a
constant clock offset from the moving board.

Convention: ``offset_s`` is the scan clock minus the image clock, so a scan stamped ``t`` was taken at image-clock
time ``t - offset_s``. Stamps are nanoseconds (int); everything returned is in seconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DEFAULT_TOL_FRACTION = 0.5  # default pairing tolerance, as a fraction of the scan period


def median_period(stamps_ns: np.ndarray) -> float:
    """Median spacing of sorted stamps, seconds (NaN with fewer than two)."""
    t = np.sort(np.asarray(stamps_ns, np.int64))
    return float(np.median(np.diff(t))) / 1e9 if len(t) > 1 else math.nan


@dataclass(frozen=True)
class Pairing:
    """Scan paired with each image: ``scan`` index (-1 when refused), ``dt_s`` scan minus image time after the
    offset (NaN when there is no scan), ``tol_s`` the tolerance used, ``offset_s`` the clock offset applied."""

    scan: np.ndarray
    dt_s: np.ndarray
    tol_s: float
    offset_s: float


def pair_nearest(image_ns: np.ndarray, scan_ns: np.ndarray, tol_s: float | None = None, offset_s: float = 0.0
                 ) -> Pairing:
    """Pair each image with the scan nearest in time (scan stamps corrected by ``offset_s``); refuse the pair
    (index -1) when the nearest scan is more than ``tol_s`` away (default ``DEFAULT_TOL_FRACTION`` x the scan
    period). ``scan_ns`` must be sorted."""
    img = np.asarray(image_ns, np.int64)
    sc = np.asarray(scan_ns, np.int64) - int(round(offset_s * 1e9))
    if tol_s is None:
        tol_s = DEFAULT_TOL_FRACTION * median_period(scan_ns)
    if len(sc) == 0:
        return Pairing(np.full(len(img), -1), np.full(len(img), np.nan), float(tol_s), float(offset_s))
    j = np.clip(np.searchsorted(sc, img), 1, max(len(sc) - 1, 1))
    lo = np.clip(j - 1, 0, len(sc) - 1)
    hi = np.clip(j, 0, len(sc) - 1)
    best = np.where(np.abs(sc[lo] - img) <= np.abs(sc[hi] - img), lo, hi)
    dt = (sc[best] - img) / 1e9
    ok = np.abs(dt) <= tol_s if math.isfinite(tol_s) else np.ones(len(img), bool)
    return Pairing(np.where(ok, best, -1), dt, float(tol_s), float(offset_s))


IMAGE_MOTION_PERCENTILE = 99.9  # a board filling a small part of the image still dominates this percentile


def image_motion(thumbs: np.ndarray) -> np.ndarray:
    """(N,) change of each thumbnail from the previous one (NaN for the first): the ``IMAGE_MOTION_PERCENTILE``
    percentile of the absolute grey-level differences, so a small moving board is not averaged away by a still
    background."""
    out = np.full(len(thumbs), np.nan)
    for i in range(1, len(thumbs)):  # one frame at a time: a float copy of every thumbnail would not be small
        d = np.abs(thumbs[i].astype(np.float32) - thumbs[i - 1].astype(np.float32))
        out[i] = float(np.percentile(d, IMAGE_MOTION_PERCENTILE))
    return out


def scan_motion(ranges: np.ndarray, clip_m: float = 0.5) -> np.ndarray:
    """(M,) mean absolute range change (metres, each beam clipped at ``clip_m``) of each scan from the previous,
    over beams with a return in both (NaN for the first scan)."""
    r = np.asarray(ranges, np.float32)
    out = np.full(len(r), np.nan)
    if len(r) > 1:
        d = np.minimum(np.abs(np.diff(r, axis=0)), clip_m)
        both = np.isfinite(d)
        n = both.sum(axis=1)
        out[1:] = np.where(n > 0, np.where(both, d, 0).sum(axis=1) / np.maximum(n, 1), np.nan)
    return out


@dataclass(frozen=True)
class OffsetEstimate:
    """``offset_s`` (scan clock minus image clock), ``correlation`` at the peak (Pearson, -1..1), ``halves_s`` the
    estimates from the first and the second half of the recording, ``reliable`` (peak correlation >= 0.5, peak
    not at the edge of the +-``window_s`` searched, and the halves within ``consistency_s`` of each other)."""

    offset_s: float
    correlation: float
    reliable: bool
    window_s: float
    halves_s: tuple[float, float] = (math.nan, math.nan)


def _midpoints(t_ns: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(t_ns, np.float64) / 1e9
    ok = np.isfinite(m[1:])
    return (0.5 * (t[1:] + t[:-1]))[ok], np.asarray(m[1:], float)[ok]


def _pearson(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a - a.mean(), b - b.mean()
    return float(np.mean(a * b) / (a.std() * b.std() + 1e-12))


def _peak(lags: np.ndarray, corr: np.ndarray) -> tuple[float, int]:
    """Lag of the correlation maximum, refined by a parabola through its neighbours; and its index."""
    k = int(np.argmax(corr))
    off = float(lags[k])
    if 0 < k < len(lags) - 1:
        c0, c1, c2 = corr[k - 1], corr[k], corr[k + 1]
        den = c0 - 2 * c1 + c2
        if den < 0:
            off += float(0.5 * (c0 - c2) / den * (lags[1] - lags[0]))
    return off, k


def estimate_offset(image_ns: np.ndarray, image_m: np.ndarray, scan_ns: np.ndarray, scan_m: np.ndarray,
                    max_offset_s: float = 0.5, step_s: float = 0.002, consistency_s: float = 0.01
                    ) -> OffsetEstimate:
    """Constant clock offset between the streams from their motion signals (``image_motion``, ``scan_motion``):
    the lag, within +-``max_offset_s``, that maximises the Pearson correlation of the image motion at ``t`` with
    the scan motion at ``t + lag`` (both resampled every ``step_s``; parabolic refinement of the peak). Needs the
    board to move and rest; smooth moves give a broad peak, which the split-half test flags as unreliable."""
    ti, mi = _midpoints(image_ns, np.asarray(image_m, float))
    ts, ms = _midpoints(scan_ns, np.asarray(scan_m, float))
    lags = np.arange(-max_offset_s, max_offset_s + step_s / 2, step_s)
    if len(ti) < 4 or len(ts) < 4:
        return OffsetEstimate(0.0, math.nan, False, max_offset_s)
    lo, hi = max(ti[0], ts[0] + max_offset_s), min(ti[-1], ts[-1] - max_offset_s)
    if hi - lo < 20 * step_s:
        return OffsetEstimate(0.0, math.nan, False, max_offset_s)
    grid = np.arange(lo, hi, step_s)
    a = np.interp(grid, ti, mi)
    half = len(grid) // 2
    corr = np.empty((3, len(lags)))
    for k, lag in enumerate(lags):  # loop over lags (hundreds), vectorised over the signal
        b = np.interp(grid + lag, ts, ms)
        corr[:, k] = _pearson(a, b), _pearson(a[:half], b[:half]), _pearson(a[half:], b[half:])
    off, k = _peak(lags, corr[0])
    h1, h2 = _peak(lags, corr[1])[0], _peak(lags, corr[2])[0]
    reliable = bool(corr[0, k] >= 0.5 and 0 < k < len(lags) - 1 and abs(h1 - h2) <= consistency_s)
    return OffsetEstimate(off, float(corr[0, k]), reliable, max_offset_s, (h1, h2))
