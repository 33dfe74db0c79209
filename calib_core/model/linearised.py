"""The ``lidarcam`` cost's residuals and their analytic Jacobian (the polish's linearisation), at one extrinsic or
at a batch of extrinsics in one pass (every start of a polish round at once): each row of a batch is, bit for bit,
the linearisation at that row's extrinsic alone. ``x = (w, dt)`` is ``calib_core.model.residuals``' left
perturbation (radians, metres); residuals are normalised by their scales (metres)."""

from __future__ import annotations

import functools

import numpy as np

from ..data.observations import Observations
from ..geometry.mounting import MountingPrior
from .chords import lower_bound_boards
from .lower_bound import (
    CHORD_CAP,
    CHORD_SIGMA_M,
    MARGIN_SIGMA_M,
    chord_residuals,
    lower_bound_rows,
    margin_residuals,
)
from .residuals import (
    board_frame_rows,
    board_frames,
    outside_outlines,
    point_line_errors,
    range_residuals,
    scan_points_in_boards,
)
from .score import DEFAULT_RANGE_SIGMA_M, EDGE_SIGMA_M, OUTLINE_SIGMA_M, evidence_constants


def lidarcam_linearised(obs: Observations, T_lidar_cam: np.ndarray, *, jacobian: bool | str = True, **options) -> tuple:
    """``score.lidarcam_residuals`` (n,) at one (4,4) ``T_lidar_cam`` and their analytic Jacobian (n,6) with
    respect to ``x = (w, dt)`` (``lidarcam_linearised_many`` of one extrinsic; ``options``: its keywords).
    ``jacobian="later"``: the Jacobian as a function of no arguments, the same numbers computed only when asked (a
    rejected step of the polish needs none)."""
    F, jac = lidarcam_linearised_many(obs, np.asarray(T_lidar_cam, float)[None], **options)
    J = functools.partial(_first, jac)
    return F[0], (J if jacobian == "later" else J())


def _first(jac) -> np.ndarray:
    """The (n,6) Jacobian of row 0 of a one-extrinsic ``lidarcam_linearised_many``."""
    return jac(np.zeros(1, int))[0]


def lidarcam_linearised_many(obs: Observations, C: np.ndarray, *, range_sigma_m: float = DEFAULT_RANGE_SIGMA_M,
                             edge_sigma_m: float = EDGE_SIGMA_M, outline_sigma_m: float = OUTLINE_SIGMA_M,
                             behind_penalty: float = np.inf, chord_sigma_m: float = CHORD_SIGMA_M,
                             chord_cap: float = CHORD_CAP, margin_sigma_m: float = MARGIN_SIGMA_M,
                             prior: MountingPrior | None = None) -> tuple:
    """``score.lidarcam_residuals`` (M,n) of (M,4,4) extrinsics ``C`` and ``jac(rows)``: the analytic Jacobians
    (k',n,6) at rows ``rows`` (k',) with respect to ``x = (w, dt)``, computed when asked. Range rows from
    ``range_residuals``; endpoint, outline, chord and margin rows by the chain rule through the board-frame
    coordinates of the scan points (``board_frame_rows``), each endpoint's edge pairing and each point's nearest
    outline edge held fixed (both are piecewise constant); the prior's rows from ``MountingPrior.jacobian``. The
    board-frame maps and every scan point's board-frame coordinates are computed once per call; every step is
    elementwise or per extrinsic, so a row equals the call on its extrinsic alone. ``behind_penalty`` is not a
    residual; it is accepted for the scorer's keywords."""
    C = np.asarray(C, float).reshape(-1, 4, 4)
    M, data = len(C), obs.scan_data
    exact, on_exact, _ = obs.derived("scorers.evidence_constants", evidence_constants)
    ends = obs.derived("scorers.linearised_rows", _linearised_rows)[0]
    rng, J_rng = range_residuals(C, data, jacobian="later")
    frames = board_frames(obs, C)                           # every board-frame map below, computed once
    P = scan_points_in_boards(obs, C, frames=frames)        # every scan point in its board's frame, once
    edge, g_edge = point_line_errors(obs, C, gradient="later", frames=frames, ends=P[:, ends])
    out, g_out = outside_outlines(obs, C, gradient="later", frames=frames, points=P[..., :2])
    if len(exact) < obs.n_boards:                           # rows of the exact outlines only
        edge, out = edge[:, exact], out[:, on_exact]
    parts = [rng / range_sigma_m, edge.reshape(M, -1) / edge_sigma_m, out / outline_sigma_m]
    if len(lower_bound_boards(obs)):
        parts += [chord_residuals(obs, C, chord_sigma_m, chord_cap, frames),
                  margin_residuals(obs, C, margin_sigma_m, frames)]
    if prior is not None:
        parts.append(prior.residuals(C))
    jac = functools.partial(_jacobians, obs, C, frames, (J_rng, g_edge, g_out), (chord_sigma_m, chord_cap,
                            margin_sigma_m), prior, (range_sigma_m, edge_sigma_m, outline_sigma_m))
    return np.concatenate(parts, axis=1), jac


def _jacobians(obs: Observations, C: np.ndarray, frames: tuple, lazy: tuple, lower: tuple,
               prior: MountingPrior | None, sigmas: tuple, rows: np.ndarray) -> np.ndarray:
    """``lidarcam_linearised_many``'s Jacobians (k',n,6) at rows ``rows`` of ``C`` from its board frames, the range
    rows' and the board-frame gradients' functions (``lazy``: ``range_residuals``, ``point_line_errors``,
    ``outside_outlines``, each computed for the whole batch), the lower-bound scales (chord sigma, cap, margin
    sigma, metres), the prior and the range, endpoint and outline sigmas (metres)."""
    exact, on_exact, _ = obs.derived("scorers.evidence_constants", evidence_constants)
    lin_rows = obs.derived("scorers.linearised_rows", _linearised_rows)[1]
    points = obs.derived("scorers.linearised_points", _linearised_points)
    n_edge = 2 * len(exact)
    every = len(rows) == len(C) and rows.tolist() == list(range(len(C)))    # every row, in order: no copy
    J_rng, g_edge, g_out = (f() if every else f()[rows] for f in lazy)
    if len(exact) < obs.n_boards:
        g_edge, g_out = g_edge[:, exact], g_out[:, on_exact]
    range_sigma_m, edge_sigma_m, outline_sigma_m = sigmas
    k, n_rows = J_rng.shape[1], len(lin_rows)
    J = None
    for i, r in enumerate(rows):
        # the endpoint and outline rows at once: the outline's gradient has no board-frame z part
        g = np.zeros((n_rows, 3))
        g[:n_edge] = g_edge[i].reshape(-1, 3)
        g[n_edge:, :2] = g_out[i]
        one = (frames[0][r:r + 1], frames[1][r:r + 1])
        J_ends_out = board_frame_rows(obs, C[r], *points, g, one)
        _, Jc, _, Jm = lower_bound_rows(obs, C[r], one, *lower)
        Jp = prior.jacobian(C[r]) if prior is not None else np.zeros((0, 6))
        if J is None:
            J = np.empty((len(rows), k + n_rows + len(Jc) + len(Jm) + len(Jp), 6))
        np.divide(J_rng[i], range_sigma_m, out=J[i, :k])
        np.divide(J_ends_out[:n_edge], edge_sigma_m, out=J[i, k:k + n_edge])
        np.divide(J_ends_out[n_edge:], outline_sigma_m, out=J[i, k + n_edge:k + n_rows])
        if len(Jc) + len(Jm) + len(Jp):
            J[i, k + n_rows:] = np.concatenate([Jc, Jm, Jp], axis=0)
    return np.zeros((0, 0, 6)) if J is None else J


def _linearised_points(obs: Observations) -> tuple[np.ndarray, np.ndarray]:
    """The lidar-frame points (K',3) and boards (K',) of the endpoint and outline rows (``_linearised_rows``)."""
    rows = obs.derived("scorers.linearised_rows", _linearised_rows)[1]
    return obs.scan_data.points[rows], obs.scan_data.board[rows]


def _linearised_rows(obs: Observations) -> tuple[np.ndarray, np.ndarray]:
    """(N,2) the rows of ``obs.scan_data`` of every board's first and last scan point (its endpoints), and the rows
    of the endpoints of the exact-outline boards followed by those of their scan points."""
    stops = np.cumsum([len(b.scan) for b in obs.boards])
    ends = np.stack([stops - [len(b.scan) for b in obs.boards], stops - 1], axis=1)
    exact, on_exact, _ = obs.derived("scorers.evidence_constants", evidence_constants)
    return ends, np.concatenate([ends[exact].ravel(), np.flatnonzero(on_exact)])
