"""Error metrics (the paper's eq. 13-15, docs/METHOD.md): e_R (degrees), e_t (metres), validity, theta_R, mu_t;
and the 1-sigma figures of a covariance. The one home of the validity thresholds."""

from __future__ import annotations

import numpy as np

VALID_MAX_ROT_DEG = 8.0
"""A solution is valid when its rotation error is below this (degrees; the paper's threshold)."""
VALID_MAX_TRANS_M = 0.8
"""... and its translation error below this (metres; the paper's threshold)."""
TRUTH_MAX_ROT_DEG = 1.0
"""A candidate "is the truth" when within this rotation error (degrees) ..."""
TRUTH_MAX_TRANS_M = 0.05
"""... and this translation error (metres) of the ground truth."""


def rotation_error_deg(R: np.ndarray, R_true: np.ndarray) -> np.ndarray:
    """Eq. 13: ``e_R = (180/pi) 2 asin(|R - R_true|_F / (2 sqrt 2))`` in degrees (geodesic angle).

    Broadcasts over leading dimensions of ``R`` (...,3,3).
    """
    diff = np.linalg.norm(np.asarray(R, float) - np.asarray(R_true, float), axis=(-2, -1))
    return np.degrees(2.0 * np.arcsin(np.clip(diff / (2.0 * np.sqrt(2.0)), 0.0, 1.0)))


def translation_error_m(t: np.ndarray, t_true: np.ndarray) -> np.ndarray:
    """Eq. 14: ``e_t = |t - t_true|`` in metres; broadcasts over leading dimensions."""
    return np.linalg.norm(np.asarray(t, float) - np.asarray(t_true, float), axis=-1)


def pose_errors(T: np.ndarray, T_true: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(e_R in degrees, e_t in metres) of transform(s) ``T`` (...,4,4) against ``T_true`` (4,4).

    Both are ``T_lidar_cam``: the translation compared is that of the lidar-from-camera map, as in the paper.
    """
    T = np.asarray(T, float)
    T_true = np.asarray(T_true, float)
    return (rotation_error_deg(T[..., :3, :3], T_true[:3, :3]),
            translation_error_m(T[..., :3, 3], T_true[:3, 3]))


def pose_error_vector(T: np.ndarray, T_true: np.ndarray) -> np.ndarray:
    """The error of ``T`` in the covariance's parameters: (rotation vector of ``R R_true^T`` (rad, lidar frame),
    ``t - t_true`` (m)), a 6-vector; its rotation norm is ``e_R`` in radians."""
    from scipy.spatial.transform import Rotation

    T, T_true = np.asarray(T, float), np.asarray(T_true, float)
    return np.r_[Rotation.from_matrix(T[:3, :3] @ T_true[:3, :3].T).as_rotvec(), T[:3, 3] - T_true[:3, 3]]


def nees(T: np.ndarray, T_true: np.ndarray, covariance: np.ndarray) -> float:
    """Normalised estimation error squared ``e^T P^-1 e`` (``e = pose_error_vector``): chi-square with 6 degrees
    of freedom (mean 6) when the covariance ``P`` is honest."""
    e = pose_error_vector(T, T_true)
    return float(e @ np.linalg.solve(np.asarray(covariance, float), e))


def is_valid(e_R_deg, e_t_m, max_rot_deg: float = VALID_MAX_ROT_DEG,
             max_trans_m: float = VALID_MAX_TRANS_M) -> np.ndarray:
    """A valid solution: ``e_R < max_rot_deg`` and ``e_t < max_trans_m`` (paper: 8 deg, 0.8 m). NaN is invalid."""
    e_R = np.asarray(e_R_deg, float)
    e_t = np.asarray(e_t_m, float)
    return (e_R < max_rot_deg) & (e_t < max_trans_m)


def theta_R_deg(R: np.ndarray) -> np.ndarray:
    """Eq. 15: rotation angle ``(180/pi) acos((trace R - 1)/2)`` in degrees, over leading dimensions."""
    tr = np.trace(np.asarray(R, float), axis1=-2, axis2=-1)
    return np.degrees(np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0)))


def mu_t_m(t: np.ndarray) -> np.ndarray:
    """Eq. 15: translation length ``|t|`` in metres, over leading dimensions."""
    return np.linalg.norm(np.asarray(t, float), axis=-1)


def sigma_rot_deg(covariance: np.ndarray) -> float:
    """1-sigma rotation (degrees): root of the trace of the rotation block of a 6x6 covariance (rad^2 first)."""
    return float(np.degrees(np.sqrt(np.trace(np.asarray(covariance, float)[:3, :3]))))


def sigma_trans_m(covariance: np.ndarray) -> float:
    """1-sigma translation (metres): root of the trace of the translation block of a 6x6 covariance."""
    return float(np.sqrt(np.trace(np.asarray(covariance, float)[3:, 3:])))

