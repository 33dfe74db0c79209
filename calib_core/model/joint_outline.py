"""The lower-bound outline's evidence in the joint model (an option, ``joint_outline=True``; docs/lidarcam.md says
why it is off by default): the chord-coverage and margin terms of
``calib_core.model.lower_bound`` (the same residuals, scales and caps the selection, the consensus and the polish
read), as rows of the joint cost that touch the extrinsic and their own board's pose.

A scan end reaches its board's frame through both unknowns: ``p_W = Phi^T (R^T (p_L - t) - Delta)`` with
``T_lidar_cam = (R, t)`` and ``T_cam_board = (Phi, Delta)``. With the joint model's left perturbations (``w, dt`` of
the extrinsic in the lidar frame, ``phi, d`` of the board in the camera frame) and ``g`` a residual's gradient in
the end's board-frame coordinates, the extrinsic row is ``(v x (p_L - t), -v)`` with ``v = A^T g``, ``A = Phi^T
R^T`` (``data.residuals.board_frame_rows``), and the board row is ``(u x q, -u)`` with ``u = Phi g`` and
``q = R^T (p_L - t) - Delta`` (the end in the camera frame, from the board's origin): ``d p_W = Phi^T ([q]_x phi -
d)``. Each crossing's edge and each end's paired edge are held fixed (piecewise constant), as in the polish.

The rows enter the joint solve (cost and Gauss-Newton blocks) and its covariance, the inverse of the information
of the cost it minimises: they are one-sided (zero wherever the scan covers its chord and ends beside the printed
edges) and capped, so they add information only where active, as at three boards whose range optimum lies where
two minimal solutions meet (a fold, ``checks.profile``), where the corners and ranges alone determine a direction
only to second order.
"""

from __future__ import annotations

import numpy as np

from .chords import lower_bound_boards
from .lower_bound import chord_residuals, margin_residuals
from .residuals import board_frame_rows, scan_endpoints


def _frames(T_e: np.ndarray, T_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``data.residuals.board_frames`` at the board poses ``T_b`` (N,4,4) rather than the file's, for one
    ``T_e``: ((1,N,3,3) ``A``, (1,N,3) ``c``)."""
    Pt = np.swapaxes(T_b[:, :3, :3], -1, -2)
    A = Pt @ T_e[:3, :3].T
    c = -(A @ T_e[:3, 3]) - (Pt @ T_b[:, :3, 3, None])[..., 0]
    return A[None], c[None]


def outline_residuals(obs, T_e: np.ndarray, T_b: np.ndarray) -> np.ndarray:
    """(4n,) the chord (2n) then margin (2n) residuals of the n lower-bound boards at the extrinsic ``T_e`` and the
    board poses ``T_b`` (in units of their scales; half their squares are the costs)."""
    if not len(lower_bound_boards(obs)):
        return np.zeros(0)
    frames = _frames(T_e, T_b)
    return np.r_[chord_residuals(obs, T_e[None], frames=frames)[0], margin_residuals(obs, T_e[None], frames=frames)[0]]


def _board_rows(T_e: np.ndarray, T_b: np.ndarray, points: np.ndarray, board: np.ndarray, g: np.ndarray) -> np.ndarray:
    """(K,6) rows ``g_k . d p_W,k / d (phi, d)`` of board ``board[k]``'s pose (module docstring); ``g`` (K,r)."""
    g3 = np.zeros((len(g), 3))
    g3[:, :g.shape[1]] = g
    Phi = T_b[board, :3, :3]
    u = np.einsum("kab,kb->ka", Phi, g3)
    q = (points - T_e[:3, 3]) @ T_e[:3, :3] - T_b[board, :3, 3]
    return np.concatenate([np.cross(u, q), -u], axis=1)


def outline_rows(obs, T_e: np.ndarray, T_b: np.ndarray):
    """At the extrinsic ``T_e`` and board poses ``T_b``: (residuals (4n,), extrinsic rows (4n,6), board rows (4n,6),
    each row's board (4n,)); empty without lower-bound boards."""
    lb = lower_bound_boards(obs)
    if not len(lb):
        return np.zeros(0), np.zeros((0, 6)), np.zeros((0, 6)), np.zeros(0, int)
    frames = _frames(T_e, T_b)
    rc, gc = chord_residuals(obs, T_e[None], frames=frames, gradient=True)
    rm, gm = margin_residuals(obs, T_e[None], frames=frames, gradient=True)
    ends = scan_endpoints(obs)[lb]                                             # (n,2,3)
    board = np.repeat(lb, 2)
    Je_c = Jb_c = 0.0
    for j in (0, 1):  # a chord residual moves with both ends of its segment
        pts = np.repeat(ends[:, j], 2, axis=0)
        Je_c = Je_c + board_frame_rows(obs, T_e, pts, board, gc[0][:, j], frames)
        Jb_c = Jb_c + _board_rows(T_e, T_b, pts, board, gc[0][:, j])
    pts = ends.reshape(-1, 3)
    Je_m = board_frame_rows(obs, T_e, pts, board, gm[0], frames)
    Jb_m = _board_rows(T_e, T_b, pts, board, gm[0])
    return np.r_[rc[0], rm[0]], np.r_[Je_c, Je_m], np.r_[Jb_c, Jb_m], np.r_[board, board]


def has_outline_rows(obs) -> bool:
    """Whether any board has a lower-bound outline (and so rows here)."""
    return bool(len(lower_bound_boards(obs)))


def outline_cost(obs, T_e: np.ndarray, T_b: np.ndarray) -> float:
    """The outline terms' part of the joint cost, ``0.5 sum r^2``."""
    r = outline_residuals(obs, T_e, T_b)
    return 0.5 * float(r @ r)


def with_outline(blocks, obs, T_e: np.ndarray, T_b: np.ndarray):
    """The joint model's Gauss-Newton blocks (``joint._blocks``'s: global gradient, boards' gradient, global
    information, global-board blocks, board blocks; the extrinsic first in the global block) with the outline rows
    added."""
    r, Je, Jb, board = outline_rows(obs, T_e, T_b)
    if not len(r):
        return blocks
    g_g, g_b, H_gg, H_gb, H_bb = (np.array(b, float) for b in blocks)
    N = len(g_b)
    g_g[:6] += Je.T @ r
    H_gg[:6, :6] += Je.T @ Je
    g_b += np.stack([np.bincount(board, Jb[:, a] * r, N) for a in range(6)], axis=1)
    H_gb[:, :6, :] += np.einsum("k,kn,ka,kb->nab", np.ones(len(r)), np.eye(N)[board], Je, Jb)
    H_bb += np.einsum("kn,ka,kb->nab", np.eye(N)[board], Jb, Jb)
    return g_g, g_b, H_gg, H_gb, H_bb
