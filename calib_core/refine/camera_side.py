"""The camera side's error of each board's plane: what a board pose fitted to image corners leaves uncertain.

A board's pose ``T_cam_board`` comes from its image corners through the file's camera (PnP). Its error has two
parts (parameters of ``calib_core.refine.joint``: rotation rad then translation m, left perturbation in the camera
frame):

- the corner noise: ``sigma_c^2 (J_c^T J_c)^-1``, with ``J_c`` (2J,6) the board's corner Jacobian and ``sigma_c``
  (pixels) estimated from the boards' own pose fits (``corner_noise_px``);
- where the file states ``camera.std_intrinsics``, the intrinsics' error carried through the pose fit: the pose's
  first-order response to an intrinsics error ``dk`` is ``A dk`` with ``A = -(J_c^T J_c)^-1 J_c^T J_k`` (``J_k``
  (2J,m) the corners' Jacobian in the stated intrinsics), so it adds ``A C_k A^T`` (``C_k`` the diagonal of the
  stated variances). One camera serves every board, so this part is shared by the boards; each board's own
  marginal is what a per-board test needs.

On a board's scan points the pose error moves the range residuals (metres, along each beam) by ``J_b dx`` (``J_b``
the range Jacobian in the board's pose): an error shared by the board's points, not independent noise
(``pose_explained`` takes it out at its cost; ``calib_core.checks.verdict`` tests what is left).
"""

from __future__ import annotations

import numpy as np

from ..data.lines import residual_sigma
from ..data.observations import Observations
from ..errors import JointError, UncertaintyError
from ..model.corners import board_poses, corner_residuals, joint_range_residuals
from ..model.intrinsics import IntrinsicsPrior
from .uncertainty import inverse_information

POSE_RCOND = 1e-12
"""Relative eigenvalue below which a board's corner information leaves its pose undetermined."""


def corner_noise_px(obs: Observations) -> float:
    """Corner noise std (pixels) from the boards' own pose fits: the RMS reprojection error at the observed board
    poses with ``2J - 6N`` degrees of freedom (no extrinsic involved)."""
    return residual_sigma(corner_residuals(obs, board_poses(obs)), 6 * obs.n_boards)


def board_pose_covariances(obs: Observations, corner_sigma_px: float, intrinsics: bool = True) -> np.ndarray:
    """(N,6,6) covariance of each board's pose from its corners at ``corner_sigma_px`` (module docstring), with
    the stated intrinsics' part when ``intrinsics`` and the camera has ``std_intrinsics``.

    Needs corners on every board (``Observations.has_corners``): JointError otherwise; UncertaintyError when a
    board's corners do not determine its pose."""
    prior = IntrinsicsPrior.of(obs.camera) if intrinsics else None
    poses = board_poses(obs)
    if prior is None:
        _, Jc = corner_residuals(obs, poses, jacobian=True)
    else:
        _, Jc, Jk = corner_residuals(obs, poses, jacobian=True, free=prior.free)
    counts = np.array([len(b.corners_px) for b in obs.boards])
    first = np.r_[0, np.cumsum(counts)[:-1]]
    H = np.add.reduceat(np.einsum("jra,jrb->jab", Jc, Jc), first)                   # (N,6,6), pixels^-2 aside
    try:
        H_inv = np.stack([inverse_information(h, POSE_RCOND) for h in H])
    except UncertaintyError:
        raise UncertaintyError("a board's pose is not determined by its corners") from None
    if prior is None:
        return H_inv * corner_sigma_px**2
    A = -H_inv @ np.add.reduceat(np.einsum("jra,jrb->jab", Jc, Jk), first)          # (N,6,m)
    return H_inv * corner_sigma_px**2 + np.einsum("nam,m,nbm->nab", A, prior.std**2, A)


def pose_covariances(obs: Observations) -> np.ndarray | None:
    """``board_pose_covariances`` at the corner noise the boards' own pose fits show (computed once per
    ``Observations``); None where the boards carry no image corners or their corners do not determine the poses."""
    return obs.derived("camera_side.pose_covariances", _pose_covariances_or_none)


def _pose_covariances_or_none(obs: Observations) -> np.ndarray | None:
    if not obs.has_corners:
        return None
    sigma = corner_noise_px(obs)
    if not np.isfinite(sigma):
        return None
    try:
        return board_pose_covariances(obs, sigma)
    except (JointError, UncertaintyError):
        return None


def pose_explained(obs: Observations, T_lidar_cam: np.ndarray, r: np.ndarray, keep: np.ndarray,
                   sigma_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The range residuals ``r`` (metres) of the scan points ``keep`` (bool over ``obs.scan_data``) under
    ``T_lidar_cam``, less what a move of each board's pose within its camera-side covariance ``C_i``
    (``pose_covariances``) explains, and the moves' costs.

    Each board's move ``d_i = argmin |r_i - J_i d|^2 / sigma_m^2 + d^T C_i^-1 d`` (``J_i`` the range Jacobian in its
    pose), so that ``|r_i - J_i d_i|^2 / sigma_m^2 + d_i^T C_i^-1 d_i = r_i^T (sigma_m^2 I + J_i C_i J_i^T)^-1 r_i``:
    the board's residuals against the range noise and the camera side's error of its plane together. Returns
    ``(r - J d, d^T C^-1 d per board (N,))``; ``r`` and zeros where the boards carry no usable corners."""
    N = obs.n_boards
    C = pose_covariances(obs)
    if C is None:
        return r, np.zeros(N)
    try:
        _, _, Jb = joint_range_residuals(obs, np.asarray(T_lidar_cam, float), board_poses(obs), jacobian=True)
    except JointError:
        return r, np.zeros(N)
    J, board = Jb[keep] / sigma_m, obs.scan_data.board[keep]
    z = r / sigma_m
    H = np.zeros((N, 6, 6))
    g = np.zeros((N, 6))
    np.add.at(H, board, np.einsum("ka,kb->kab", J, J))
    np.add.at(g, board, J * z[:, None])
    # (C H + I) d = C g: no inverse of C, which may be ill-conditioned along well-measured directions
    d = np.linalg.solve(C @ H + np.eye(6), np.einsum("nab,nb->na", C, g)[..., None])[..., 0]
    cost = np.einsum("na,na->n", d, g - np.einsum("nab,nb->na", H, d))          # d^T C^-1 d = d^T (g - H d)
    return r - sigma_m * np.einsum("ka,ka->k", J, d[board]), cost
