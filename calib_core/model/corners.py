"""The joint model's residuals: every corner's reprojection and every scan point's range against its board's current
plane, with their Jacobians in the parameters of ``calib_core.refine.joint`` (board poses ``(phi_i, d_i)``, left
perturbation in the camera frame; the extrinsic ``(w, dt)``; the camera's intrinsics, ``Camera.intrinsics`` order).
Units: pixels for corners, metres for ranges.
"""

from __future__ import annotations

import numpy as np

from ..data.camera import Camera, intrinsics_jacobian, project
from ..data.observations import Observations, ScanData
from ..errors import JointError
from ..geometry.transforms import rotvec_to_matrix, skew
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


def corner_residuals(obs: Observations, T_cam_board: np.ndarray, jacobian: bool = False, camera: Camera | None = None,
                     free: np.ndarray | None = None):
    """Reprojection errors (J,2) in pixels of every corner under board poses ``T_cam_board`` (N,4,4) through
    ``camera`` (default the file's); with ``jacobian`` also (J,2,6) d e/d(phi, d) of each corner's own board, and
    with ``free`` (indices into ``Camera.intrinsics``) also (J,2,len(free)) d e/d(those intrinsics)."""
    camera = obs.camera if camera is None else camera
    P, uv, idx = _corner_arrays(obs)
    RP = np.einsum("jab,jb->ja", T_cam_board[idx, :3, :3], P)
    X = RP + T_cam_board[idx, :3, 3]
    if np.any(X[:, 2] <= 0):
        bad = int(idx[np.argmax(X[:, 2] <= 0)])
        raise JointError(f"board {bad}: a corner lies behind the camera under the current pose")
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
