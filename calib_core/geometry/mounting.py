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

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import CalibrationError
from .transforms import make_T

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
    """(6,6) ``d(w, dt) / d theta``: how the parameters of ``calib_core.data.residuals`` (left rotation perturbation
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


def parse_fixed(fixed: dict) -> tuple[np.ndarray, np.ndarray]:
    """(mask (6,) bool of the fixed parameters, values (6,) in radians and metres, NaN where free) of a
    ``{"z_m": 0.12, "roll_deg": 0.0, ...}`` dict; CalibrationError naming a bad key or value."""
    mask = np.zeros(6, bool)
    values = np.full(6, np.nan)
    for key, value in dict(fixed).items():
        if key not in UNIT_NAMES:
            raise CalibrationError(f"fixed: unknown parameter {key!r}; known: {', '.join(UNIT_NAMES)}")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise CalibrationError(f"fixed: {key} must be a number, got {value!r}") from None
        if not np.isfinite(v):
            raise CalibrationError(f"fixed: {key} must be finite, got {value!r}")
        j = UNIT_NAMES.index(key)
        mask[j] = True
        values[j] = np.radians(v) if j < 3 else v
    if mask.all():
        raise CalibrationError("fixed: all six parameters are fixed; nothing is left to calibrate")
    return mask, values


def with_units(theta: np.ndarray) -> dict[str, float]:
    """``{"roll_deg": ..., ..., "z_m": ...}`` of ``theta`` (radians, metres)."""
    theta = np.asarray(theta, float)
    return {k: float(np.degrees(v) if j < 3 else v) for j, (k, v) in enumerate(zip(UNIT_NAMES, theta, strict=True))}
