"""A vectorised 2D lidar: beam-board ray casting (nearest hit wins), range noise, chords (the beam geometry itself
is ``calib_core.geometry.beams``).

Frame: ``{L}``, x forward, z up, scan plane z = 0, beams from the origin. Boards are given by their poses
``T_lidar_board`` (M,4,4) and a shared outline (V,2) in the board plane z = 0. Units: metres, radians.
"""

from __future__ import annotations

import numpy as np

from calib_core.geometry.beams import beam_bearings, beam_directions, board_ranges, points_in_polygon

__all__ = ["beam_bearings", "beam_directions", "board_ranges", "cast_scan", "nearest_hits", "points_in_polygon",
           "scan_chords"]


def nearest_hits(ranges: np.ndarray, max_range_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Nearest hit per beam over boards: (owner (K,) board index or -1, range (K,) in metres or inf).

    ``ranges`` (M,K) from ``board_ranges``; hits beyond ``max_range_m`` are dropped.
    """
    ranges = np.asarray(ranges, float)
    if ranges.shape[0] == 0:
        K = ranges.shape[1]
        return np.full(K, -1), np.full(K, np.inf)
    owner = np.argmin(ranges, axis=0)
    r = np.take_along_axis(ranges, owner[None], axis=0)[0]
    hit = np.isfinite(r) & (r <= max_range_m)
    return np.where(hit, owner, -1), np.where(hit, r, np.inf)


def cast_scan(bearings: np.ndarray, T_lidar_board: np.ndarray, outline: np.ndarray, max_range_m: float,
              range_sigma_m: float = 0.0, rng: np.random.Generator | None = None) -> list[np.ndarray]:
    """One scan over all boards at once: per board the (K_m,2) points in ``{L}`` (z = 0), ordered by bearing.

    Nearest hit wins where boards overlap; each hit range gets zero-mean Gaussian noise of standard
    deviation ``range_sigma_m`` along its beam (drawn from ``rng``, in bearing order, only for hits).
    """
    bearings = np.asarray(bearings, float)
    M = np.asarray(T_lidar_board).reshape(-1, 4, 4).shape[0]
    owner, r = nearest_hits(board_ranges(bearings, T_lidar_board, outline), max_range_m)
    hit = owner >= 0
    if range_sigma_m > 0:
        if rng is None:
            raise ValueError("cast_scan: range_sigma_m > 0 needs an rng")
        r = r.copy()
        r[hit] += rng.normal(0.0, range_sigma_m, int(hit.sum()))
    pts = np.where(hit, r, 0.0)[:, None] * beam_directions(bearings)[:, :2]
    return [pts[owner == m] for m in range(M)]


def scan_chords(T_lidar_board: np.ndarray, outline: np.ndarray) -> np.ndarray:
    """Where the scan plane z = 0 cuts each board: chord ends (M,2,2) in ``{L}`` xy, NaN where it misses.

    Assumes a convex outline (the plane then crosses exactly two edges); the ends are ordered by bearing.
    """
    T = np.asarray(T_lidar_board, float).reshape(-1, 4, 4)
    outline = np.asarray(outline, float)
    V = len(outline)
    P = np.einsum("mij,vj->mvi", T[:, :3, :3], np.column_stack([outline, np.zeros(V)])) + T[:, None, :3, 3]
    Q = np.roll(P, -1, axis=1)                                  # edge v: P[v] -> P[v+1]
    z0, z1 = P[..., 2], Q[..., 2]
    crosses = (z0 > 0) != (z1 > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(crosses, z0 / (z0 - z1), np.nan)
    X = P[..., :2] + s[..., None] * (Q[..., :2] - P[..., :2])  # (M,V,2), NaN where no crossing
    out = np.full((len(T), 2, 2), np.nan)
    ok = crosses.sum(axis=1) == 2
    idx = np.argsort(~crosses, axis=1, kind="stable")[:, :2]    # the two crossed edges
    ends = np.take_along_axis(X, idx[..., None], axis=1)
    ang = np.arctan2(ends[..., 1], ends[..., 0])
    order = np.argsort(ang, axis=1)
    ends = np.take_along_axis(ends, order[..., None], axis=1)
    out[ok] = ends[ok]
    return out
