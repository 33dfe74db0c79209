"""The enhanced unified camera model (Kalibr's ``eucm``; Khomutenko, Garcia and Martinet, RA-L 2016).

A point ``P = (X, Y, Z)`` of ``{C}`` (metres) with ``d = sqrt(beta (X^2 + Y^2) + Z^2)`` projects as

    u = fx X / den + cx,  v = fy Y / den + cy,   den = alpha d + (1 - alpha) Z.

One-to-one for ``Z > -w d`` with ``w = alpha / (1 - alpha)`` when ``alpha <= 0.5``, ``(1 - alpha) / alpha``
otherwise (Usenko et al. 2018); a pixel has a ray when ``alpha <= 0.5`` or ``r^2 <= 1 / (beta (2 alpha - 1))``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..camera import field_error
from .base import FieldCamera


@dataclass(frozen=True, eq=False)
class EUCM(FieldCamera):
    """Enhanced unified camera: ``K`` (pixels), ``dist`` (empty), width, height, ``std_intrinsics`` (1-sigma of
    fx, fy, cx, cy, alpha, beta), ``alpha`` (in [0, 1)) and ``beta`` (> 0)."""

    K: np.ndarray
    dist: np.ndarray
    width: int
    height: int
    std_intrinsics: np.ndarray | None = None
    alpha: float = 0.0
    beta: float = 1.0

    camera_model = "eucm"
    distortion_model = "none"
    param_names = ("alpha", "beta")

    def check_params(self) -> None:
        if not 0 <= self.alpha < 1:
            raise field_error(f"must be in [0, 1), got {self.alpha:g}", "alpha")
        if not self.beta > 0:
            raise field_error(f"must be > 0, got {self.beta:g}", "beta")

    @property
    def _w(self) -> float:
        a = self.alpha
        return a / (1 - a) if a <= 0.5 else (1 - a) / a

    def _d(self, P):
        return np.sqrt(self.beta * (P[..., 0]**2 + P[..., 1]**2) + P[..., 2]**2)

    def valid(self, P_cam: np.ndarray) -> np.ndarray:
        P = np.asarray(P_cam, float)
        d = self._d(P)
        return (P[..., 2] > -self._w * d) & (d > 0)

    def project(self, P_cam: np.ndarray, jacobian: bool = False):
        P = np.asarray(P_cam, float)
        d = self._d(P)
        den = self.alpha * d + (1 - self.alpha) * P[..., 2]
        m = P[..., :2] / den[..., None]
        uv = self._uv(m)
        if not jacobian:
            return uv
        dd = P * np.array([self.beta, self.beta, 1.0]) / d[..., None]
        dden = self.alpha * dd
        dden[..., 2] += 1 - self.alpha
        J = -(m / den[..., None])[..., :, None] * dden[..., None, :]
        J[..., 0, 0] += 1 / den
        J[..., 1, 1] += 1 / den
        J[..., 0, :] *= self.K[0, 0]
        J[..., 1, :] *= self.K[1, 1]
        return uv, J

    def intrinsics_jacobian(self, P_cam: np.ndarray) -> np.ndarray:
        """d(u, v)/d(fx, fy, cx, cy, alpha, beta) (...,2,6)."""
        P = np.asarray(P_cam, float)
        d = self._d(P)
        den = self.alpha * d + (1 - self.alpha) * P[..., 2]
        m = P[..., :2] / den[..., None]
        dden_da = d - P[..., 2]
        dden_db = self.alpha * (P[..., 0]**2 + P[..., 1]**2) / (2 * d)
        return self._k_jacobian(m, [-m * (dden_da / den)[..., None], -m * (dden_db / den)[..., None]])

    def unproject(self, uv: np.ndarray):
        """Unit rays (...,3) of pixels (...,2) (the paper's closed form) and the mask of those with one."""
        mx, my = self._m(uv)
        a, b = self.alpha, self.beta
        r2 = mx * mx + my * my
        q = 1 - (2 * a - 1) * b * r2
        mz = (1 - b * a * a * r2) / (a * np.sqrt(np.maximum(q, 0)) + 1 - a)
        ray = np.stack([mx, my, mz], axis=-1)
        ray = ray / np.linalg.norm(ray, axis=-1, keepdims=True)
        ok = (q >= 0) & np.isfinite(r2) & (ray[..., 2] > -self._w * np.sqrt(b * (1 - ray[..., 2]**2) + ray[..., 2]**2))
        return ray, ok
