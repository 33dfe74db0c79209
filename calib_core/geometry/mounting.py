"""The extrinsic as six mounting parameters (the camera's pose in the lidar frame), and user-given fixed values.

Parameters ``theta = (roll, pitch, yaw, x, y, z)`` (radians, metres) of ``T_lidar_cam``:

- ``x, y, z``: the camera's optical centre in the lidar frame (the translation of ``T_lidar_cam``); ``z`` is the
  height of the camera above the lidar's scan plane (negative when the camera sits below the lidar).
- ``roll, pitch, yaw``: Z-Y-X Euler angles of the camera's *body* frame in the lidar frame,
  ``R_lidar_cam = Rz(yaw) Ry(pitch) Rx(roll) R_BODY_OPTICAL``. The body frame has x along the optical axis,
  y to the left of the image, z up the image (the optical frame's z, -x, -y). All zero: the camera looks along
  the lidar's x axis with its image rows parallel to the scan plane. ``yaw`` turns the camera about the lidar's
  z axis (positive to the left), ``pitch`` about its own left axis (positive looks down), ``roll`` about its
  own optical axis. Singular at pitch = +-90 deg (a camera looking straight up or down).

At the edges (user options, reports) the names carry their units: ``roll_deg``, ``pitch_deg``, ``yaw_deg``,
``x_m``, ``y_m``, ``z_m``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import CalibrationError
from .transforms import make_T, so3_left_jacobian

PARAMS = ("roll", "pitch", "yaw", "x", "y", "z")
"""The mounting parameters, in the order of ``theta``."""

UNIT_NAMES = ("roll_deg", "pitch_deg", "yaw_deg", "x_m", "y_m", "z_m")
"""The parameters' names with their units, as users give them (degrees and metres)."""

R_BODY_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
"""Maps camera optical axes (z forward, x right, y down) onto body axes (x forward, y left, z up)."""


def params_from_T(T_lidar_cam: np.ndarray) -> np.ndarray:
    """``theta = (roll, pitch, yaw, x, y, z)`` (radians, metres) of a 4x4 ``T_lidar_cam``."""
    T = np.asarray(T_lidar_cam, float)
    yaw, pitch, roll = Rotation.from_matrix(T[:3, :3] @ R_BODY_OPTICAL.T).as_euler("ZYX")
    return np.r_[roll, pitch, yaw, T[:3, 3]]


def T_from_params(theta: np.ndarray) -> np.ndarray:
    """4x4 ``T_lidar_cam`` of ``theta = (roll, pitch, yaw, x, y, z)`` (radians, metres)."""
    theta = np.asarray(theta, float)
    R = Rotation.from_euler("ZYX", theta[2::-1]).as_matrix() @ R_BODY_OPTICAL
    return make_T(R, theta[3:])


def params_jacobian(theta: np.ndarray) -> np.ndarray:
    """(6,6) ``d(w, dt) / d theta``: how the parameters of ``calib_core.model.residuals`` (left rotation perturbation
    ``w`` in the lidar frame, translation ``dt``) move with ``theta``; a residual Jacobian in ``theta`` is the
    residual Jacobian in ``(w, dt)`` times this matrix.

    ``w = Rz(yaw) Ry(pitch) e_x droll + Rz(yaw) e_y dpitch + e_z dyaw``; ``dt = d(x, y, z)``.
    """
    _, pitch, yaw = np.asarray(theta, float)[:3]
    Rz = Rotation.from_euler("Z", yaw).as_matrix()
    Rzy = Rz @ Rotation.from_euler("Y", pitch).as_matrix()
    M = np.zeros((6, 6))
    M[:3, 0], M[:3, 1], M[:3, 2] = Rzy[:, 0], Rz[:, 1], [0.0, 0.0, 1.0]
    M[3:, 3:] = np.eye(3)
    return M


def parse_params(values: dict, who: str = "fixed") -> tuple[np.ndarray, np.ndarray]:
    """(mask (6,) bool of the parameters given, values (6,) in radians and metres, NaN where not given) of a
    ``{"z_m": 0.12, "roll_deg": 0.0, ...}`` dict; CalibrationError naming ``who`` and a bad key or value."""
    mask = np.zeros(6, bool)
    out = np.full(6, np.nan)
    for key, value in dict(values).items():
        if key not in UNIT_NAMES:
            raise CalibrationError(f"{who}: unknown parameter {key!r}; known: {', '.join(UNIT_NAMES)}")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise CalibrationError(f"{who}: {key} must be a number, got {value!r}") from None
        if not np.isfinite(v):
            raise CalibrationError(f"{who}: {key} must be finite, got {value!r}")
        j = UNIT_NAMES.index(key)
        mask[j] = True
        out[j] = np.radians(v) if j < 3 else v
    return mask, out


def parse_fixed(fixed: dict) -> tuple[np.ndarray, np.ndarray]:
    """``parse_params`` of user-fixed values, refusing all six (nothing would be left to calibrate)."""
    mask, values = parse_params(fixed, "fixed")
    if mask.all():
        raise CalibrationError("fixed: all six parameters are fixed; nothing is left to calibrate")
    return mask, values


def with_units(theta: np.ndarray) -> dict[str, float]:
    """``{"roll_deg": ..., ..., "z_m": ...}`` of ``theta`` (radians, metres)."""
    theta = np.asarray(theta, float)
    return {k: float(np.degrees(v) if j < 3 else v) for j, (k, v) in enumerate(zip(UNIT_NAMES, theta, strict=True))}


@dataclass(frozen=True, eq=False)
class MountingPrior:
    """A rough guess of the mounting (from CAD or a tape measure), as a Gaussian prior on ``T_lidar_cam``.

    Attributes:
        T_lidar_cam: (4,4) the guessed pose (``T_from_params`` of the guessed roll, pitch, yaw, x, y, z).
        sigma_rot_rad: 1-sigma of the rotation (radians), the same about every axis.
        sigma_trans_m: 1-sigma of the translation (metres), the same along every axis.

    Its residuals (``residuals``): ``log(R_0^T R) / sigma_rot`` (the rotation vector of the error, scipy's) and
    ``(t - t_0) / sigma_trans``; their squared norm halved is minus the prior's log-density (up to a constant).
    """

    T_lidar_cam: np.ndarray
    sigma_rot_rad: float
    sigma_trans_m: float

    def __post_init__(self) -> None:
        T = np.array(self.T_lidar_cam, float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise CalibrationError("prior: T_lidar_cam must be a finite 4x4 matrix")
        for name in ("sigma_rot_rad", "sigma_trans_m"):
            v = float(getattr(self, name))
            if not (np.isfinite(v) and v > 0):
                raise CalibrationError(f"prior: {name} must be finite and > 0, got {v!r}")
            object.__setattr__(self, name, v)
        T.setflags(write=False)
        object.__setattr__(self, "T_lidar_cam", T)

    @classmethod
    def from_params(cls, pose: dict, sigma_rot_deg: float, sigma_trans_m: float) -> MountingPrior:
        """From ``{"roll_deg": ..., "x_m": ...}`` (``UNIT_NAMES``; every one of the six is needed) and sigmas in
        degrees and metres."""
        mask, values = parse_params(pose, "prior")
        if not mask.all():
            missing = [UNIT_NAMES[j] for j in np.flatnonzero(~mask)]
            raise CalibrationError(f"prior: every mounting parameter is needed; missing {', '.join(missing)}")
        return cls(T_from_params(values), np.radians(float(sigma_rot_deg)), float(sigma_trans_m))

    def residuals(self, candidates: np.ndarray) -> np.ndarray:
        """(M,6) the prior's normalised residuals of (M,4,4) candidates (or (6,) of one (4,4))."""
        T = np.asarray(candidates, float)
        C = T.reshape(-1, 4, 4)
        R0 = self.T_lidar_cam[:3, :3]
        w = Rotation.from_matrix(R0.T @ C[:, :3, :3]).as_rotvec()
        r = np.concatenate([w / self.sigma_rot_rad, (C[:, :3, 3] - self.T_lidar_cam[:3, 3]) / self.sigma_trans_m],
                           axis=1)
        return r[0] if T.ndim == 2 else r

    def jacobian(self, T: np.ndarray) -> np.ndarray:
        """(6,6) d residuals / d (w, dt) at one (4,4) ``T`` (``calib_core.model.residuals``' left perturbation
        ``R = exp([w]x) R``): ``log(R_0^T exp(w) R) = log(exp(R_0^T w) R_0^T R)``, whose derivative is
        ``J_l(phi)^-1 R_0^T`` with ``phi = log(R_0^T R)`` and ``J_l`` the left Jacobian of SO(3)."""
        R0 = self.T_lidar_cam[:3, :3]
        phi = Rotation.from_matrix(R0.T @ np.asarray(T, float)[:3, :3]).as_rotvec()
        J = np.zeros((6, 6))
        J[:3, :3] = np.linalg.solve(so3_left_jacobian(phi), R0.T) / self.sigma_rot_rad
        J[3:, 3:] = np.eye(3) / self.sigma_trans_m
        return J

