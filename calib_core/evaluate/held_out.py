"""Held-out scores of one leave-one-pose-out fold beyond the point-to-plane distance (``calib_core.evaluate.crossval``).

- Residuals in units of their predicted spread: the held-out board's range residuals (lidar frame, metres, along
  each beam) against its plane as the camera sees it, through the fold's extrinsic, with their predicted (K,K)
  covariance ``S = sigma_r^2 I + J_e C_e J_e^T + J_b C_b J_b^T``: range noise, the fold's extrinsic covariance
  ``C_e`` (rotation rad then translation m, left perturbation) and, where the board carries image corners, its
  pose's covariance from the corners alone ``C_b = sigma_c^2 (J_c^T J_c)^-1``. ``spread_summary`` pools the folds:
  the normalised residuals' RMS and 90% quantile, the Mahalanobis statistic per residual, and the factor on every
  predicted sigma, or on the board poses' sigmas alone (camera-side error the corner noise does not hold, such as
  intrinsics taken as exact), that would make it 1.
- The joint held-out residual: the held-out board's pose re-estimated from its corners and its scan with the
  fold's extrinsic held (``held_out_joint``), its corner (pixels) and range (metres) residuals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq, least_squares

from ..data.observations import Observations
from ..model.residuals import range_residuals
from ..refine.camera_side import board_pose_covariances
from ..refine.joint import board_poses, corner_residuals, joint_range_residuals, scan_data_at

GAUSS_Q90 = 1.6449
"""The 90% quantile of ``|z|`` for a standard normal ``z``."""
MAX_BOARD_FACTOR = 1000.0
"""Upper end of the search for the factor on the board poses' sigmas that explains the held-out residuals."""


@dataclass(frozen=True, eq=False)
class HeldOutPart:
    """One held-out board: its range residuals ``r`` (K,) and their predicted covariance in two parts, ``A`` (K,K)
    from the range noise and the extrinsic, ``B`` (K,K) from its pose (zero without corners); ``S = A + B``."""

    r: np.ndarray
    A: np.ndarray
    B: np.ndarray


def held_out_spread(obs: Observations, i: int, T_lidar_cam: np.ndarray, covariance: np.ndarray,
                    range_sigma_m: float, corner_sigma_px: float | None) -> HeldOutPart:
    """Board ``i``'s range residuals through ``T_lidar_cam`` against its observed plane and their predicted
    covariance (module docstring); the board-pose term only where ``corner_sigma_px`` is given and the board
    carries corners."""
    o1 = obs.subset([i])
    T = np.asarray(T_lidar_cam, float)
    r, Je = range_residuals(T, o1.scan_data, jacobian=True)
    A = range_sigma_m**2 * np.eye(len(r)) + Je @ np.asarray(covariance, float) @ Je.T
    B = np.zeros_like(A)
    if corner_sigma_px is not None and o1.boards[0].corners_px is not None and o1.camera is not None:
        _, _, Jb = joint_range_residuals(o1, T, board_poses(o1), jacobian=True)
        B = Jb @ board_pose_covariances(o1, corner_sigma_px, intrinsics=False)[0] @ Jb.T
    return HeldOutPart(r, A, B)


def _chi2(parts: list[HeldOutPart], board_factor: float = 1.0) -> float:
    return sum(float(p.r @ np.linalg.solve(p.A + board_factor**2 * p.B, p.r)) for p in parts)


@dataclass(frozen=True)
class HeldOutSpread:
    """Pooled held-out residuals in units of their predicted spread (Gaussian: ``rms_z`` 1, ``q90_ratio`` 1,
    ``chi2_per_point`` 1).

    Attributes:
        n_points: residuals pooled; rms_z: RMS of ``r_k / sqrt(S_kk)``; q90_ratio: 90% quantile of ``|z|`` over
        ``GAUSS_Q90``; chi2_per_point: ``sum r^T S^-1 r / n_points`` (a board's points are correlated through the
        extrinsic and its pose); inflation: ``sqrt(chi2_per_point)``, the factor on every predicted sigma that
        makes it 1; board_factor: the factor on the board poses' sigmas (from their corners) that makes it 1
        (NaN when none within ``MAX_BOARD_FACTOR`` does, 1 when it is already at most 1 or without corners);
        chi2_boards_free: the statistic with the board poses' sigmas times ``MAX_BOARD_FACTOR`` (what is left
        when any plane error is allowed: scatter about the plane within each board).
    """

    n_points: int
    rms_z: float
    q90_ratio: float
    chi2_per_point: float
    inflation: float
    board_factor: float
    chi2_boards_free: float

    def to_dict(self) -> dict:
        """JSON-able form (NaN as None)."""
        return {k: int(v) if k == "n_points" else (float(v) if np.isfinite(v) else None)
                for k, v in self.__dict__.items()}


def spread_summary(parts: list[HeldOutPart]) -> HeldOutSpread | None:
    """Pool the folds' ``held_out_spread`` (None when there are none)."""
    if not parts:
        return None
    z = np.concatenate([p.r / np.sqrt(np.diag(p.A + p.B)) for p in parts])
    n = len(z)
    chi2 = _chi2(parts) / n
    free = _chi2(parts, MAX_BOARD_FACTOR) / n
    factor = 1.0
    if chi2 > 1 and any(p.B.any() for p in parts):
        factor = float("nan")
        if free < 1:
            factor = float(brentq(lambda k: _chi2(parts, k) / n - 1.0, 1.0, MAX_BOARD_FACTOR, xtol=1e-4))
    return HeldOutSpread(n, float(np.sqrt(np.mean(z**2))), float(np.quantile(np.abs(z), 0.9) / GAUSS_Q90),
                         float(chi2), float(np.sqrt(chi2)), factor, float(free))


def held_out_joint(obs: Observations, i: int, T_lidar_cam: np.ndarray, corner_sigma_px: float,
                   range_sigma_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Board ``i``'s pose re-estimated from its corners and its scan with the extrinsic ``T_lidar_cam`` held
    (least squares on both, each in units of its noise std, from the observed pose); its corner residuals (J,2)
    in pixels and range residuals (K,) in metres at that pose. Needs corners on the board and the camera."""
    o1 = obs.subset([i])
    T = np.asarray(T_lidar_cam, float)
    T0 = board_poses(o1)

    def fun(x):
        Tb = board_poses(o1, x[None], T0)
        return np.r_[corner_residuals(o1, Tb).ravel() / corner_sigma_px,
                     joint_range_residuals(o1, T, Tb) / range_sigma_m]

    def jac(x):
        Tb = board_poses(o1, x[None], T0)
        _, Jc = corner_residuals(o1, Tb, jacobian=True)
        _, _, Jb = joint_range_residuals(o1, T, Tb, jacobian=True)
        return np.r_[Jc.reshape(-1, 6) / corner_sigma_px, Jb / range_sigma_m]

    x = least_squares(fun, np.zeros(6), jac=jac, method="lm").x
    Tb = board_poses(o1, x[None], T0)
    return corner_residuals(o1, Tb), range_residuals(T, scan_data_at(o1, Tb))
