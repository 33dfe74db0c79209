"""Mei's unified omnidirectional camera with radial-tangential distortion (Kalibr's ``omni``/``radtan``; Mei and
Rives, ICRA 2007).

A point ``P = (X, Y, Z)`` of ``{C}`` (metres, ``d = |P|``) goes onto the unit sphere, then through a pinhole moved
``xi`` behind the sphere's centre: ``(mx, my) = (X, Y) / (Z + xi d)``; OpenCV's distortion (``Camera``'s: k1, k2,
p1, p2[, k3, ...]) bends ``m``; ``u = fx mx'' + cx``, ``v = fy my'' + cy``.

The projection is one-to-one for ``Z > -w d`` with ``w = xi`` when ``xi <= 1``, ``1 / xi`` otherwise (Usenko et al.
2018, the unified model's domain), and inside the distortion's fold (``fold_radius``); pixels lift back to the
sphere where ``xi <= 1`` or ``r^2 <= 1 / (xi^2 - 1)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import (
    DIST_LENGTHS,
    field_error,
    fold_radius_cached,
    opencv_distort,
    opencv_distort_jacobian,
    opencv_distort_params_jacobian,
    undistort,
)
from .base import FieldCamera


@dataclass(frozen=True, eq=False)
class Omni(FieldCamera):
    """Unified (Mei) camera: ``K`` (pixels), ``dist`` (OpenCV order; Kalibr's radtan is k1, k2, p1, p2), width,
    height, ``std_intrinsics`` (1-sigma of fx, fy, cx, cy, xi[, dist]), ``xi`` (>= 0, unitless)."""

    K: np.ndarray
    dist: np.ndarray
    width: int
    height: int
    std_intrinsics: np.ndarray | None = None
    xi: float = 0.0

    camera_model = "omni"
    param_names = ("xi",)
    dist_lengths = DIST_LENGTHS[:-1]

    def check_params(self) -> None:
        if self.xi < 0:
            raise field_error(f"must be >= 0, got {self.xi:g}", "xi")

    @property
    def _w(self) -> float:
        return self.xi if self.xi <= 1 else 1.0 / self.xi

    def valid(self, P_cam: np.ndarray) -> np.ndarray:
        P = np.asarray(P_cam, float)
        d = np.linalg.norm(P, axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            m = np.hypot(P[..., 0], P[..., 1]) / (P[..., 2] + self.xi * d)
        return (P[..., 2] > -self._w * d) & (d > 0) & (m < fold_radius_cached(self))

    def _sphere(self, P):
        d = np.linalg.norm(P, axis=-1)
        w = P[..., 2] + self.xi * d
        return P[..., 0] / w, P[..., 1] / w, d, w

    def project(self, P_cam: np.ndarray, jacobian: bool = False):
        P = np.asarray(P_cam, float)
        x, y, d, w = self._sphere(P)
        r2, a, b, rad, xd, yd = opencv_distort(self.dist, x, y)
        uv = self._uv(np.stack([xd, yd], axis=-1))
        if not jacobian:
            return uv
        D = opencv_distort_jacobian(self.dist, x, y, r2, a, b, rad)
        e = P / d[..., None]                                              # d d / dP
        dw = self.xi * e
        dw[..., 2] += 1
        N = np.zeros(P.shape[:-1] + (2, 3))                               # d(mx, my)/dP
        N[..., 0, 0] = 1 / w
        N[..., 1, 1] = 1 / w
        N[..., 0, :] -= (x / w)[..., None] * dw
        N[..., 1, :] -= (y / w)[..., None] * dw
        J = np.einsum("...ab,...bc->...ac", D, N)
        J[..., 0, :] *= self.K[0, 0]
        J[..., 1, :] *= self.K[1, 1]
        return uv, J

    def intrinsics_jacobian(self, P_cam: np.ndarray) -> np.ndarray:
        """d(u, v)/d(fx, fy, cx, cy, xi, k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4) (...,2,17)."""
        P = np.asarray(P_cam, float)
        x, y, d, w = self._sphere(P)
        r2, a, b, rad, xd, yd = opencv_distort(self.dist, x, y)
        D = opencv_distort_jacobian(self.dist, x, y, r2, a, b, rad)
        dm_dxi = np.stack([-x * d / w, -y * d / w], axis=-1)
        dx, dy = opencv_distort_params_jacobian(x, y, r2, a, b)
        cols = [np.einsum("...ab,...b->...a", D, dm_dxi)] + [np.stack([u, v], -1) for u, v in zip(dx, dy, strict=True)]
        return self._k_jacobian(np.stack([xd, yd], axis=-1), cols)

    def unproject(self, uv: np.ndarray):
        """Unit rays (...,3) of pixels (...,2) and the mask of those with one (undistorted by Newton's method, then
        lifted onto the sphere)."""
        mx, my = self._m(uv)
        x, y, ok = undistort(self.dist, mx, my)
        r2 = x * x + y * y
        disc = 1 + (1 - self.xi**2) * r2
        ok &= (disc >= 0) & (np.sqrt(r2) < fold_radius_cached(self))
        k = (self.xi + np.sqrt(np.maximum(disc, 0))) / (1 + r2)
        ray = np.stack([k * x, k * y, k - self.xi], axis=-1)
        ok &= ray[..., 2] > -self._w * np.linalg.norm(ray, axis=-1)
        return ray / np.linalg.norm(ray, axis=-1, keepdims=True), ok
