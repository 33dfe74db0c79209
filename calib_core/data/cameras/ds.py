"""The double sphere camera (Kalibr's ``ds``; Usenko, Demmel and Cremers, 3DV 2018).

A point ``P = (X, Y, Z)`` of ``{C}`` (metres) with ``d1 = |P|``, ``w = xi d1 + Z`` and
``d2 = sqrt(X^2 + Y^2 + w^2)`` projects as

    u = fx X / den + cx,  v = fy Y / den + cy,   den = alpha d2 + (1 - alpha) w.

One-to-one for ``Z > -w2 d1`` with ``w2 = (w1 + xi) / sqrt(2 w1 xi + xi^2 + 1)``, ``w1 = alpha / (1 - alpha)``
when ``alpha <= 0.5``, ``(1 - alpha) / alpha`` otherwise; a pixel has a ray when ``alpha <= 0.5`` or
``r^2 <= 1 / (2 alpha - 1)`` (``r`` the radius of ``((u - cx) / fx, (v - cy) / fy)``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import field_error
from .base import FieldCamera


@dataclass(frozen=True, eq=False)
class DoubleSphere(FieldCamera):
    """Double sphere camera: ``K`` (pixels), ``dist`` (empty), width, height, ``std_intrinsics`` (1-sigma of fx,
    fy, cx, cy, xi, alpha), ``xi`` (unitless, > -1) and ``alpha`` (in [0, 1))."""

    K: np.ndarray
    dist: np.ndarray
    width: int
    height: int
    std_intrinsics: np.ndarray | None = None
    xi: float = 0.0
    alpha: float = 0.0

    camera_model = "ds"
    distortion_model = "none"
    param_names = ("xi", "alpha")

    def check_params(self) -> None:
        if not -1 < self.xi:
            raise field_error(f"must be > -1, got {self.xi:g}", "xi")
        if not 0 <= self.alpha < 1:
            raise field_error(f"must be in [0, 1), got {self.alpha:g}", "alpha")

    @property
    def _w2(self) -> float:
        a, xi = self.alpha, self.xi
        w1 = a / (1 - a) if a <= 0.5 else (1 - a) / a
        return (w1 + xi) / np.sqrt(2 * w1 * xi + xi * xi + 1)

    def valid(self, P_cam: np.ndarray) -> np.ndarray:
        P = np.asarray(P_cam, float)
        d1 = np.linalg.norm(P, axis=-1)
        return (P[..., 2] > -self._w2 * d1) & (d1 > 0)

    def _terms(self, P):
        d1 = np.linalg.norm(P, axis=-1)
        w = self.xi * d1 + P[..., 2]
        d2 = np.sqrt(P[..., 0]**2 + P[..., 1]**2 + w * w)
        den = self.alpha * d2 + (1 - self.alpha) * w
        return d1, w, d2, den

    def project(self, P_cam: np.ndarray, jacobian: bool = False):
        P = np.asarray(P_cam, float)
        d1, w, d2, den = self._terms(P)
        m = P[..., :2] / den[..., None]
        uv = self._uv(m)
        if not jacobian:
            return uv
        dw = self.xi * P / d1[..., None]
        dw[..., 2] += 1
        dd2 = (np.concatenate([P[..., :2], np.zeros(P.shape[:-1] + (1,))], -1) + w[..., None] * dw) / d2[..., None]
        dden = self.alpha * dd2 + (1 - self.alpha) * dw
        J = -(m / den[..., None])[..., :, None] * dden[..., None, :]
        J[..., 0, 0] += 1 / den
        J[..., 1, 1] += 1 / den
        J[..., 0, :] *= self.K[0, 0]
        J[..., 1, :] *= self.K[1, 1]
        return uv, J

    def intrinsics_jacobian(self, P_cam: np.ndarray) -> np.ndarray:
        """d(u, v)/d(fx, fy, cx, cy, xi, alpha) (...,2,6)."""
        P = np.asarray(P_cam, float)
        d1, w, d2, den = self._terms(P)
        m = P[..., :2] / den[..., None]
        dden_dxi = self.alpha * w * d1 / d2 + (1 - self.alpha) * d1
        dden_da = d2 - w
        return self._k_jacobian(m, [-m * (dden_dxi / den)[..., None], -m * (dden_da / den)[..., None]])

    def unproject(self, uv: np.ndarray):
        """Unit rays (...,3) of pixels (...,2) (the paper's closed form) and the mask of those with one."""
        mx, my = self._m(uv)
        a, xi = self.alpha, self.xi
        r2 = mx * mx + my * my
        q = 1 - (2 * a - 1) * r2
        ok = (q >= 0) & np.isfinite(r2)
        mz = (1 - a * a * r2) / (a * np.sqrt(np.maximum(q, 0)) + 1 - a)
        s = mz * mz + r2
        k = (mz * xi + np.sqrt(np.maximum(mz * mz + (1 - xi * xi) * r2, 0))) / s
        ray = np.stack([k * mx, k * my, k * mz - xi], axis=-1)
        ray = ray / np.linalg.norm(ray, axis=-1, keepdims=True)
        ok &= (mz * mz + (1 - xi * xi) * r2 >= 0) & (ray[..., 2] > -self._w2)
        return ray, ok
