"""The joint model's residuals: every corner's reprojection and every scan point's range against its board's current
plane, with their Jacobians in the parameters of ``calib_core.refine.joint`` (board poses ``(phi_i, d_i)``, left
perturbation in the camera frame; the extrinsic ``(w, dt)``; the camera's intrinsics, ``camera.intrinsics`` order).
Units: pixels for corners, metres for ranges.
"""

from __future__ import annotations

import numpy as np

from ..data.camera import CameraModel, intrinsics_jacobian, project
from ..data.observations import Observations, ScanData
from ..errors import JointError
from ..geometry.transforms import rotvec_to_matrix, skew
from .intrinsics import IntrinsicsPrior
from .residuals import MIN_BEAM_INCIDENCE, range_residuals


def _corner_arrays(obs: Observations):
    if not obs.has_corners:
        raise JointError("the joint model needs image corners on every board and the camera intrinsics")
    P = np.concatenate([b.corners_board for b in obs.boards])
    uv = np.concatenate([b.corners_px for b in obs.boards])
    idx = np.concatenate([np.full(len(b.corners_px), i) for i, b in enumerate(obs.boards)])
    return P, uv, idx


def board_poses(obs: Observations, x_boards: np.ndarray | None = None, T0: np.ndarray | None = None) -> np.ndarray:
    """(N,4,4) board poses ``T_cam_board`` at parameters ``x_boards`` (N,6) around ``T0`` (default: the observed)."""
    T0 = np.array([b.T_cam_board for b in obs.boards]) if T0 is None else np.asarray(T0, float)
    if x_boards is None:
        return T0.copy()
    T = T0.copy()
    T[:, :3, :3] = rotvec_to_matrix(x_boards[:, :3]) @ T0[:, :3, :3]
    T[:, :3, 3] += x_boards[:, 3:]
    return T


def corner_residuals(obs: Observations, T_cam_board: np.ndarray, jacobian: bool = False,
                     camera: CameraModel | None = None, free: np.ndarray | None = None):
    """Reprojection errors (J,2) in pixels of every corner under board poses ``T_cam_board`` (N,4,4) through
    ``camera`` (default the file's); with ``jacobian`` also (J,2,6) d e/d(phi, d) of each corner's own board, and
    with ``free`` (indices into ``camera.intrinsics``) also (J,2,len(free)) d e/d(those intrinsics)."""
    camera = obs.camera if camera is None else camera
    P, uv, idx = _corner_arrays(obs)
    RP = np.einsum("jab,jb->ja", T_cam_board[idx, :3, :3], P)
    X = RP + T_cam_board[idx, :3, 3]
    out = ~camera.valid(X)
    if np.any(out):
        bad = int(idx[np.argmax(out)])
        where = "behind the camera" if X[np.argmax(out), 2] <= 0 and camera.name == "pinhole-radtan" else \
            f"outside the {camera.name} model's field of view"
        raise JointError(f"board {bad}: a corner lies {where} under the current pose")
    if not jacobian:
        return project(camera, X) - uv
    proj, Jp = project(camera, X, jacobian=True)
    J = np.concatenate([Jp @ -skew(RP), Jp], axis=2)
    if free is None:
        return proj - uv, J
    return proj - uv, J, intrinsics_jacobian(camera, X)[..., free]


def scan_data_at(obs: Observations, T_cam_board: np.ndarray) -> ScanData:
    """The problem's scan points with the planes of the board poses ``T_cam_board`` (N,4,4)."""
    base = obs.scan_data
    n = T_cam_board[:, :3, 2]
    return ScanData(base.points, base.board, n, np.einsum("na,na->n", n, T_cam_board[:, :3, 3]))


def joint_range_residuals(obs: Observations, T_lidar_cam: np.ndarray, T_cam_board: np.ndarray,
                          jacobian: bool = False):
    """Range residuals (K,) in metres under both the extrinsic and the board poses; with ``jacobian`` also
    (K,6) d e/d(w, dt) and (K,6) d e/d(phi, d) of each point's own board."""
    data = scan_data_at(obs, T_cam_board)
    if not jacobian:
        return range_residuals(T_lidar_cam, data)
    e, J_e = range_residuals(T_lidar_cam, data, jacobian=True)
    R, t = T_lidar_cam[:3, :3], T_lidar_cam[:3, 3]
    n = data.normals[data.board]
    Delta = T_cam_board[data.board, :3, 3]
    m = n @ R.T
    b = data.points / np.linalg.norm(data.points, axis=1, keepdims=True)
    mb = np.einsum("kj,kj->k", m, b)
    mb = np.where(np.abs(mb) < MIN_BEAM_INCIDENCE, np.copysign(MIN_BEAM_INCIDENCE, mb), mb)
    num = data.offsets[data.board] + m @ t
    g = -((t[None] * mb[:, None] - b * num[:, None]) / (mb**2)[:, None]) @ R   # de/dn (camera frame)
    de_dd = -1.0 / mb                                                          # de/d(plane offset)
    # dn = phi x n, d(offset) = phi . (n x Delta) + n . d
    J_b = np.concatenate([np.cross(n, g) + de_dd[:, None] * np.cross(n, Delta), de_dd[:, None] * n], axis=1)
    return e, J_e, J_b


def normalised_rows(obs: Observations, T_lidar_cam: np.ndarray, T_cam_board: np.ndarray, corner_sigma_px: float,
                    range_sigma_m: float, jacobian: bool, prior: IntrinsicsPrior | None = None,
                    k: np.ndarray | None = None):
    """The joint model's residual rows divided by their noise stds (unitless): every corner's reprojection error
    (``corner_residuals``, pixels, over ``corner_sigma_px``; 2J rows, u then v of each corner, grouped by board),
    then every scan point's range residual (``joint_range_residuals``, metres, over ``range_sigma_m``; K rows,
    grouped by board), at the extrinsic ``T_lidar_cam`` (4x4) and the board poses ``T_cam_board`` (N,4,4).

    Without ``jacobian``: the residuals (2J+K,). With it: (residuals, the corner rows' Jacobian (2J,6) in their
    own board's pose (``phi``, ``d``: left perturbation in the camera frame, rad and m), the range rows' Jacobian
    (K,6) in the extrinsic (``w``, ``dt``: left perturbation in the lidar frame, rad and m) and (K,6) in their
    board's pose), all divided by the same stds. With an intrinsics ``prior`` (``model.intrinsics``) the corners
    go through the camera at its free intrinsics ``k`` (the prior's order and units), and with ``jacobian`` the
    corner rows' Jacobian in them (2J,m) comes last. ``board_row_offsets`` gives each board's first rows."""
    cam = None if prior is None else prior.camera_at(k)
    sc, sr = corner_sigma_px, range_sigma_m
    if not jacobian:
        ec = corner_residuals(obs, T_cam_board, camera=cam)
        return np.r_[ec.ravel() / sc, joint_range_residuals(obs, T_lidar_cam, T_cam_board) / sr]
    er, Je, Jb = joint_range_residuals(obs, T_lidar_cam, T_cam_board, jacobian=True)
    if prior is None:
        ec, Jc = corner_residuals(obs, T_cam_board, jacobian=True)
        return np.r_[ec.ravel() / sc, er / sr], Jc.reshape(-1, 6) / sc, Je / sr, Jb / sr
    ec, Jc, Jk = corner_residuals(obs, T_cam_board, jacobian=True, camera=cam, free=prior.free)
    return np.r_[ec.ravel() / sc, er / sr], Jc.reshape(-1, 6) / sc, Je / sr, Jb / sr, Jk.reshape(-1, prior.size) / sc


def board_row_offsets(obs: Observations) -> tuple[np.ndarray, np.ndarray]:
    """Each board's first row (N,) among the corner rows (2J, two per corner) and among the range rows (K, one per
    scan point) of ``normalised_rows``, whose rows are grouped by board in ``obs.boards`` order: the ``indices``
    of ``np.add.reduceat`` summing them per board."""
    nc = np.array([2 * len(b.corners_px) for b in obs.boards])
    ns = np.array([len(b.scan) for b in obs.boards])
    return np.r_[0, np.cumsum(nc)[:-1]], np.r_[0, np.cumsum(ns)[:-1]]
