"""Beam geometry of a 2D lidar: beam bearings and directions, the even-odd point-in-outline test, and where each
beam hits a planar board (the simulator's ray caster and the capture planner's noise-free scans share it).

Frame: ``{L}``, x forward, z up, scan plane z = 0, beams from the origin. Boards are given by their poses
``T_lidar_board`` (M,4,4) and a shared outline (V,2) in the board plane z = 0. Units: metres, radians.
"""

from __future__ import annotations

import numpy as np


def beam_bearings(fov_deg: float, res_deg: float) -> np.ndarray:
    """Bearings (K,) in radians, every ``res_deg`` from ``-fov/2`` to ``+fov/2`` (both ends kept when they fall
    on the grid), centred on the lidar x axis, increasing (counter-clockwise seen from +z)."""
    n = int(np.floor(fov_deg / res_deg + 1e-9))
    k = np.arange(n + 1) - n / 2.0
    if n * res_deg >= 360.0 - 1e-9:
        k = k[:-1]  # a full turn: -180 and +180 deg are the same beam
    return np.radians(k * res_deg)


def beam_directions(bearings: np.ndarray) -> np.ndarray:
    """Unit beam directions (K,3) in ``{L}`` for bearings (K,) in radians."""
    b = np.asarray(bearings, float)
    return np.column_stack([np.cos(b), np.sin(b), np.zeros_like(b)])


def points_in_polygon(xy: np.ndarray, outline: np.ndarray) -> np.ndarray:
    """Even-odd test: True where points ``xy`` (...,2) lie inside the simple polygon ``outline`` (V,2).

    Loops over the V edges only; points exactly on an edge may go either way.
    """
    x, y = xy[..., 0], xy[..., 1]
    inside = np.zeros(x.shape, bool)
    V = len(outline)
    for i in range(V):
        (x1, y1), (x2, y2) = outline[i], outline[(i + 1) % V]
        if y1 == y2:
            continue
        crosses = (y1 > y) != (y2 > y)
        x_at = x1 + (y - y1) * (x2 - x1) / (y2 - y1)
        inside ^= crosses & (x < x_at)
    return inside


def board_ranges(bearings: np.ndarray, T_lidar_board: np.ndarray, outline: np.ndarray) -> np.ndarray:
    """Range (M,K) in metres along each beam k to each board m, ``inf`` where the beam misses the board.

    A beam ``r u_k`` (r > 0) hits board m when it crosses the board plane inside ``outline``; boards are
    treated independently here (see ``nearest_hits`` for occlusion).
    """
    T = np.asarray(T_lidar_board, float).reshape(-1, 4, 4)
    u = beam_directions(bearings)                              # (K,3)
    R, o = T[:, :3, :3], T[:, :3, 3]                           # (M,3,3), (M,3)
    n = R[:, :, 2]                                             # board normals in {L}
    denom = n @ u.T                                            # (M,K)
    num = np.einsum("mi,mi->m", n, o)[:, None]                 # (M,1)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(np.abs(denom) > 1e-12, num / denom, np.inf)
    r = np.where(r > 0, r, np.inf)
    finite = np.isfinite(r)
    p = np.where(finite[..., None], r[..., None], 0.0) * u[None]            # (M,K,3) hit points in {L}
    d = p - o[:, None, :]
    # board-frame x, y = R^T d, summed j = 0, 1, 2 in einsum's order (bitwise equal to einsum("mji,mkj->mki"),
    # which runs unoptimised and dominated the simulator's time)
    xy = np.stack([d[..., 0] * R[:, None, 0, i] + d[..., 1] * R[:, None, 1, i] + d[..., 2] * R[:, None, 2, i]
                   for i in (0, 1)], axis=-1)
    inside = points_in_polygon(xy, np.asarray(outline, float)) & finite
    return np.where(inside, r, np.inf)
