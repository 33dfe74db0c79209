"""Rigid transforms as 4x4 numpy arrays; ``T_a_b`` maps points of frame b into frame a (metres)."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

ROTATION_TOL = 1e-6


def make_T(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """4x4 (or ...x4x4) homogeneous transform from rotation(s) ``R`` (...,3,3) and translation(s) ``t`` (...,3)."""
    R = np.asarray(R, dtype=float)
    t = np.asarray(t, dtype=float)
    T = np.zeros(R.shape[:-2] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def invert_T(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid transform(s) ``T`` (...,4,4): ``T_b_a`` from ``T_a_b``."""
    T = np.asarray(T, dtype=float)
    R = T[..., :3, :3]
    t = T[..., :3, 3]
    Rt = np.swapaxes(R, -1, -2)
    return make_T(Rt, -np.einsum("...ij,...j->...i", Rt, t))


def transform_points(T: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Apply ``T_a_b`` (4x4) to points ``P`` (N,3) of frame b; returns (N,3) in frame a."""
    T = np.asarray(T, dtype=float)
    return np.asarray(P, dtype=float) @ T[:3, :3].T + T[:3, 3]


def rotation_defect(R: np.ndarray) -> float:
    """Largest deviation of ``R`` from a proper rotation: max |R^T R - I| entry, or inf if det <= 0."""
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        return float("inf")
    if np.linalg.det(R) <= 0:
        return float("inf")
    return float(np.max(np.abs(R.T @ R - np.eye(3))))


def is_rigid(T: np.ndarray, tol: float = ROTATION_TOL) -> bool:
    """True when ``T`` is a finite 4x4 rigid transform (orthonormal rotation to ``tol``, last row 0 0 0 1)."""
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        return False
    if not np.allclose(T[3], [0, 0, 0, 1], atol=tol):
        return False
    return rotation_defect(T[:3, :3]) <= tol


def project_to_so3(M: np.ndarray) -> np.ndarray:
    """Closest rotation(s) to ``M`` (...,3,3) in the Frobenius norm (SVD, determinant fixed to +1)."""
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=float))
    D = np.ones(U.shape[:-1])
    D[..., -1] = np.sign(np.linalg.det(U @ Vt))
    return (U * D[..., None, :]) @ Vt


def rotvec_to_matrix(w: np.ndarray) -> np.ndarray:
    """Rotation matrices (...,3,3) from rotation vectors (...,3) in radians (scipy)."""
    w = np.asarray(w, dtype=float)
    return Rotation.from_rotvec(w.reshape(-1, 3)).as_matrix().reshape(w.shape[:-1] + (3, 3))


def matrix_to_rotvec(R: np.ndarray) -> np.ndarray:
    """Rotation vectors (...,3) in radians from rotation matrices (...,3,3) (scipy)."""
    R = np.asarray(R, dtype=float)
    return Rotation.from_matrix(R.reshape(-1, 3, 3)).as_rotvec().reshape(R.shape[:-2] + (3,))


def quaternion_xyzw(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w), scalar last, w >= 0, of rotation ``R`` (3x3)."""
    q = Rotation.from_matrix(np.asarray(R, dtype=float)).as_quat()
    return q if q[3] >= 0 else -q


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices (...,3,3) of vectors (...,3): ``skew(a) @ b == cross(a, b)``."""
    v = np.asarray(v, dtype=float)
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def so3_left_jacobian(w: np.ndarray) -> np.ndarray:
    """Left Jacobian ``J_l(w)`` of SO(3) (``w`` a rotation vector, radians): ``exp(w + dw) = exp(J_l(w) dw) exp(w)``
    to first order."""
    w = np.asarray(w, dtype=float)
    th = math.sqrt(w.dot(w))  # numpy.linalg.norm's root of w . w; the coefficients below as Python floats
    w0, w1, w2 = w.tolist()
    W = np.array([[0.0, -w2, w1], [w2, 0.0, -w0], [-w1, w0, 0.0]])  # skew(w), built at once
    if th < 1e-8:
        return _EYE3 + 0.5 * W
    return _EYE3 + (1 - math.cos(th)) / th**2 * W + (th - math.sin(th)) / th**3 * (W @ W)


_EYE3 = np.eye(3)
_EYE3.setflags(write=False)  # ``so3_left_jacobian``'s identity, built once (it runs at every refinement step)
