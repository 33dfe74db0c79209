"""The evidence of a lower-bound outline (``outline_kind`` ``lower_bound``: the physical board contains the printed
outline): the scan segment of a board, mapped into its board frame, must cover the chord the scan line cuts through
the outline, and its ends may lie outside the outline only by the board's margin.

Board frame ``{W}_i`` (plane z = 0, metres); the scan's first and last points ``p_0``, ``p_1`` (lidar frame, by
bearing) reach it through ``residuals.board_frames``; only their (x, y) are read. On the line ``p_0 + s u``
(``u = (p_1 - p_0) / L``, ``L = |p_1 - p_0|``) the outline's edges are crossed at ``s_min <= s_max`` (the chord);
the segment is ``[0, L]``. The shortfalls are ``f_0 = max(0, -s_min)`` (the first point stops short of where the
line enters the outline) and ``f_1 = max(0, s_max - L)`` (the last point stops short of where it leaves); both 0
when the segment covers the chord or when the line misses the outline (it may cross the margin only).

Per edge ``a -> a + e`` crossed: ``s = cross(a - p_0, e) / cross(u, e)`` with ``cross(x, y) = x_0 y_1 - x_1 y_0``, so
``ds/dp_0 |_u = -g / cross(u, e)`` and ``ds/du = -s g / cross(u, e)`` with ``g = (e_1, -e_0)``, and
``du/dp_1 = -du/dp_0 = (I - u u^T) / L``: the gradients below, each crossing's edge held fixed (piecewise constant).
"""

from __future__ import annotations

import numpy as np

from ..data.observations import Observations
from .residuals import given_frames, outline_groups, scan_endpoints

MIN_CROSSING_SIN = 1e-9
"""An outline edge whose direction makes a sine below this with the scan line is not crossed (parallel)."""
MIN_SEGMENT_M = 1e-9
"""A scan segment shorter than this (metres, in the board frame) has no direction: no chord evidence."""


def lower_bound_groups(obs: Observations) -> list[tuple[np.ndarray, np.ndarray]]:
    """(board indices, outline) of each distinct lower-bound outline among the boards
    (``residuals.outline_groups``)."""
    return outline_groups(obs, "lower_bound")


def lower_bound_boards(obs: Observations) -> np.ndarray:
    """Indices of the boards with a lower-bound outline (sorted, read-only); computed once per observation set."""
    return obs.derived("chords.lower_bound_boards", _lower_bound_boards)


def _lower_bound_boards(obs: Observations) -> np.ndarray:
    groups = lower_bound_groups(obs)
    out = np.sort(np.concatenate([idx for idx, _ in groups])) if groups else np.zeros(0, int)
    out.setflags(write=False)
    return out


def endpoints_2d(obs: Observations, candidates: np.ndarray, frames: tuple | None = None) -> np.ndarray:
    """(M,N,2,2) the (x, y) of every board's first and last scan point in its board frame, per candidate."""
    A, c = given_frames(obs, candidates, 2, frames)
    return scan_endpoints(obs)[None] @ np.swapaxes(A, -1, -2) + c[:, :, None, :]


def chord_shortfalls(obs: Observations, candidates: np.ndarray, gradient: bool = False,
                     frames: tuple | None = None):
    """(M,N,2) the shortfalls ``f_0, f_1`` (metres, see the module doc) of every board's scan segment against its
    lower-bound outline's chord, per candidate ``T_lidar_cam`` (M,4,4); 0 on the other boards. With ``gradient``
    also (M,N,2,2,2): ``d f_r / d p_j`` in the board-frame (x, y) of endpoint ``j``. ``frames``: the candidates'
    ``residuals.board_frames``, when the caller has them."""
    P = endpoints_2d(obs, np.asarray(candidates, float).reshape(-1, 4, 4), frames)
    M, N = P.shape[:2]
    out, grad = np.zeros((M, N, 2)), np.zeros((M, N, 2, 2, 2))
    for idx, outline in lower_bound_groups(obs):
        f, g = _shortfalls(P[:, idx, 0], P[:, idx, 1], np.asarray(outline, float), gradient)
        out[:, idx] = f
        if gradient:
            grad[:, idx] = g
    return (out, grad) if gradient else out


def _cross(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return x[..., 0] * y[..., 1] - x[..., 1] * y[..., 0]


def _shortfalls(p0: np.ndarray, p1: np.ndarray, a: np.ndarray, gradient: bool):
    """Shortfalls (...,2) of segments ``p0 -> p1`` (...,2) against the polygon ``a`` (V,2), and their gradients
    (...,2 residuals,2 endpoints,2) when asked (else None)."""
    e = np.roll(a, -1, axis=0) - a                                              # (V,2) edges
    d = p1 - p0
    L = np.linalg.norm(d, axis=-1)
    ok = L > MIN_SEGMENT_M
    u = d / np.where(ok, L, 1.0)[..., None]
    cue = _cross(u[..., None, :], e)                                            # (...,V)
    w = a - p0[..., None, :]                                                    # (...,V,2)
    par = np.abs(cue) < MIN_CROSSING_SIN * np.linalg.norm(e, axis=-1)
    safe = np.where(par, 1.0, cue)
    s = _cross(w, e) / safe
    lam = _cross(w, u[..., None, :]) / safe
    hit = ~par & (lam >= 0.0) & (lam <= 1.0) & ok[..., None]
    k_in = np.argmin(np.where(hit, s, np.inf), axis=-1)
    k_out = np.argmax(np.where(hit, s, -np.inf), axis=-1)
    any_hit = hit.any(axis=-1)
    s_in = np.take_along_axis(s, k_in[..., None], -1)[..., 0]
    s_out = np.take_along_axis(s, k_out[..., None], -1)[..., 0]
    f = np.stack([np.where(any_hit, np.maximum(0.0, -s_in), 0.0),
                  np.where(any_hit, np.maximum(0.0, s_out - L), 0.0)], axis=-1)
    if not gradient:
        return f, None
    g = np.zeros(f.shape + (2, 2))
    P_perp = (np.eye(2) - u[..., :, None] * u[..., None, :]) / np.where(ok, L, 1.0)[..., None, None]
    for r, (k, sk, sign) in enumerate(((k_in, s_in, -1.0), (k_out, s_out, 1.0))):
        ek = e[k]                                                               # (...,2)
        gk = np.stack([ek[..., 1], -ek[..., 0]], axis=-1)
        ck = np.take_along_axis(safe, k[..., None], -1)
        ds_du = -sk[..., None] * gk / ck
        ds_dd = np.einsum("...i,...ij->...j", ds_du, P_perp)
        ds_dp0 = -gk / ck - ds_dd
        g0, g1 = sign * ds_dp0, sign * ds_dd
        if r == 1:                                                              # f_1 = s_out - L
            g0, g1 = g0 + u, g1 - u
        live = (f[..., r] > 0)[..., None]
        g[..., r, 0, :] = np.where(live, g0, 0.0)
        g[..., r, 1, :] = np.where(live, g1, 0.0)
    return f, g
