"""Metrics of docs/METHOD.md eq. 13-15: e_R is the geodesic angle, e_t the distance, validity is strict."""

from __future__ import annotations

import zlib

import numpy as np

from calib_core.geometry.metrics import (
    VALID_MAX_ROT_DEG,
    VALID_MAX_TRANS_M,
    is_valid,
    mu_t_m,
    pose_errors,
    rotation_error_deg,
    theta_R_deg,
    translation_error_m,
)
from calib_core.geometry.transforms import make_T, rotvec_to_matrix


def rng_for(name: str) -> np.random.Generator:
    return np.random.default_rng(zlib.crc32(name.encode()))


def test_rotation_error_is_the_geodesic_angle():
    rng = rng_for("test_rotation_error_is_the_geodesic_angle")
    angles = np.array([1e-3, 0.5, 8.0, 45.0, 90.0, 135.0, 179.0])
    for ang in angles:
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        dR = rotvec_to_matrix(np.radians(ang) * axis)
        R0 = rotvec_to_matrix(rng.normal(size=3))
        assert np.isclose(rotation_error_deg(dR, np.eye(3)), ang, atol=1e-6)
        assert np.isclose(rotation_error_deg(R0 @ dR, R0), ang, atol=1e-6)     # invariant to a common rotation
        assert np.isclose(rotation_error_deg(dR @ R0, R0), ang, atol=1e-6)
        assert np.isclose(theta_R_deg(dR), ang, atol=1e-5)
    stacked = np.stack([rotvec_to_matrix([0, 0, np.radians(a)]) for a in angles])
    assert np.allclose(rotation_error_deg(stacked, np.eye(3)), angles, atol=1e-6)


def test_translation_error_and_pose_errors():
    rng = rng_for("test_translation_error_and_pose_errors")
    t = rng.normal(size=3)
    d = rng.normal(size=3)
    assert np.isclose(translation_error_m(t + d, t), np.linalg.norm(d))
    T_true = make_T(rotvec_to_matrix(rng.normal(size=3)), t)
    T = make_T(T_true[:3, :3] @ rotvec_to_matrix([0, np.radians(3.0), 0]), t + [0.1, 0, 0])
    e_R, e_t = pose_errors(T, T_true)
    assert np.isclose(e_R, 3.0) and np.isclose(e_t, 0.1)
    assert np.isclose(mu_t_m(t), np.linalg.norm(t))


def test_validity_thresholds():
    assert VALID_MAX_ROT_DEG == 8.0 and VALID_MAX_TRANS_M == 0.8
    e_R = np.array([7.999, 8.0, 1.0, 1.0, np.nan, 1.0, 0.0])
    e_t = np.array([0.799, 0.1, 0.8, 0.81, 0.1, np.nan, 0.0])
    assert is_valid(e_R, e_t).tolist() == [True, False, False, False, False, False, True]
    assert is_valid(9.0, 0.1, max_rot_deg=10.0) and not is_valid(9.0, 0.1)
