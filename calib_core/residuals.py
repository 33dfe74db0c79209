"""Scan residuals of an extrinsic against the board planes, with analytic Jacobians.

Parameterisation: ``T_lidar_cam = (exp([w]x) R0, t0 + dt)``, a left perturbation of the rotation in the
lidar frame; the 6 parameters are ``x = (w, dt)`` (radians, metres). Board planes are given in the camera
frame (``n . p_C = d``); in the lidar frame the plane of board i is ``m . p_L = d + m . t`` with ``m = R n``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .observations import Observations
from .transforms import rotvec_to_matrix


@dataclass(frozen=True, eq=False)
class ScanData:
    """All scan points of a problem, flattened, with the plane of the board each lies on.

    Attributes:
        points: (K,3) lidar-frame points, z = 0 (metres).
        board: (K,) board index of each point.
        normals: (N,3) board unit normals in the camera frame; offsets: (N,) plane offsets (metres).
    """

    points: np.ndarray
    board: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray

    @classmethod
    def from_observations(cls, obs: Observations) -> ScanData:
        pts = np.concatenate([b.scan_3d for b in obs.boards])
        idx = np.concatenate([np.full(len(b.scan), i) for i, b in enumerate(obs.boards)])
        n, d = obs.planes_cam()
        return cls(pts, idx, n, d)


def perturb(T0: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``T_lidar_cam`` at parameters ``x = (w, dt)`` around ``T0`` (left rotation perturbation)."""
    T = np.array(T0, float)
    T[:3, :3] = rotvec_to_matrix(x[:3]) @ T0[:3, :3]
    T[:3, 3] = T0[:3, 3] + x[3:]
    return T


def plane_residuals(T: np.ndarray, data: ScanData, jacobian: bool = False):
    """Signed point-to-plane distances (metres) of every scan point to its board plane, in the lidar frame.

    ``e_k = m_i . (p_k - t) - d_i`` with ``m_i = R n_i``. With ``jacobian``, also (K,6) de/d(w, dt) at ``T``.
    """
    R, t = T[:3, :3], T[:3, 3]
    m = data.normals @ R.T                                  # (N,3) normals in the lidar frame
    mk = m[data.board]
    q = data.points - t
    e = np.einsum("kj,kj->k", mk, q) - data.offsets[data.board]
    if not jacobian:
        return e
    J = np.empty((len(e), 6))
    J[:, :3] = np.cross(mk, q)
    J[:, 3:] = -mk
    return e, J


def range_residuals(T: np.ndarray, data: ScanData, jacobian: bool = False):
    """Range residuals (metres): measured range minus the range at which the beam meets its board plane.

    The lidar noise is along each beam, so this is the likelihood's residual. Beam ``b = p/|p|``, measured
    range ``r = |p|``, predicted ``r* = (d_i + m_i . t) / (m_i . b)``; ``e = r - r*``. With ``jacobian``,
    also (K,6) de/d(w, dt). Beams nearly parallel to their plane give large residuals, as they should.
    """
    R, t = T[:3, :3], T[:3, 3]
    m = data.normals @ R.T
    mk = m[data.board]
    r = np.linalg.norm(data.points, axis=1)
    b = data.points / r[:, None]
    mb = np.einsum("kj,kj->k", mk, b)
    num = data.offsets[data.board] + mk @ t
    e = r - num / mb
    if not jacobian:
        return e
    J = np.empty((len(e), 6))
    # d(num)/dw = m x t, d(mb)/dw = m x b  (from dm = w x m)
    J[:, :3] = -(np.cross(mk, t) * mb[:, None] - np.cross(mk, b) * num[:, None]) / (mb**2)[:, None]
    J[:, 3:] = -mk / mb[:, None]
    return e, J


RESIDUALS = {"plane": plane_residuals, "range": range_residuals}
