"""Pinhole + equidistant distortion (Kannala-Brandt with four coefficients; Kalibr's ``pinhole``/``equidistant``,
OpenCV's ``cv2.fisheye``, ROS's ``equidistant``).

For a point ``(X, Y, Z)`` of ``{C}`` (metres) with ``rho = sqrt(X^2 + Y^2)`` and ``theta = atan2(rho, Z)`` (the
angle from the optical axis, beyond 90 deg where ``Z < 0``):

    theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8),   (mx, my) = theta_d (X, Y) / rho,
    u = fx mx + cx,  v = fy my + cy.

The model is one-to-one while ``theta_d`` increases: ``theta < theta_max``, the first angle in (0, pi] where
``d theta_d / d theta`` reaches 0 (pi when it never does).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .base import FieldCamera


@dataclass(frozen=True, eq=False)
class Equidistant(FieldCamera):
    """Kannala-Brandt camera: ``K`` (3x3, pixels), ``dist`` = (k1, k2, k3, k4) (unitless; 0 or 4 given), width,
    height (pixels), ``std_intrinsics`` (1-sigma of fx, fy, cx, cy[, k1..k4])."""

    K: np.ndarray
    dist: np.ndarray
    width: int
    height: int
    std_intrinsics: np.ndarray | None = None

    distortion_model = "equidistant"
    dist_lengths = (0, 4)

    @property
    def theta_max(self) -> float:
        """The largest angle from the optical axis (rad) the model projects one-to-one (module docstring)."""
        if "_theta_max" not in self.__dict__:
            t = np.linspace(0.0, np.pi, 20001)
            bad = np.flatnonzero(_theta_d(self.dist, t)[1] <= 0)
            object.__setattr__(self, "_theta_max", float(t[bad[0]]) if len(bad) else np.pi)
        return self.__dict__["_theta_max"]

    def valid(self, P_cam: np.ndarray) -> np.ndarray:
        P = np.asarray(P_cam, float)
        theta = np.arctan2(np.hypot(P[..., 0], P[..., 1]), P[..., 2])
        return np.isfinite(theta) & (theta < self.theta_max) & (np.linalg.norm(P, axis=-1) > 0)

    def _terms(self, P):
        X, Y, Z = P[..., 0], P[..., 1], P[..., 2]
        rho = np.hypot(X, Y)
        theta = np.arctan2(rho, Z)
        axis = rho == 0
        s = np.where(axis, 1.0 / np.where(Z != 0, Z, 1.0), theta / np.where(axis, 1.0, rho))   # theta / rho
        g, dg = _theta_d(self.dist, theta)
        return X, Y, Z, rho, theta, s, g, dg, axis

    def project(self, P_cam: np.ndarray, jacobian: bool = False):
        P = np.asarray(P_cam, float)
        X, Y, Z, rho, theta, s, g, dg, axis = self._terms(P)
        f = g / np.where(theta > 0, theta, 1.0)                          # theta_d / theta (1 on the axis)
        f = np.where(theta > 0, f, 1.0)
        m = (f * s)[..., None] * P[..., :2]                               # theta_d / rho (X, Y)
        uv = self._uv(m)
        if not jacobian:
            return uv
        R2 = rho**2 + Z**2
        r = np.where(axis, 1.0, rho)
        c = np.where(axis, 0.0, dg * Z / (r**2 * R2) - f * s / r**2)      # d(theta_d / rho)/d rho / rho
        mm = f * s
        J = np.empty(P.shape[:-1] + (2, 3))
        J[..., 0, 0] = mm + X * X * c
        J[..., 0, 1] = X * Y * c
        J[..., 1, 0] = X * Y * c
        J[..., 1, 1] = mm + Y * Y * c
        J[..., 0, 2] = -X * dg / R2
        J[..., 1, 2] = -Y * dg / R2
        J[..., 0, :] *= self.K[0, 0]
        J[..., 1, :] *= self.K[1, 1]
        return uv, J

    def intrinsics_jacobian(self, P_cam: np.ndarray) -> np.ndarray:
        """d(u, v)/d(fx, fy, cx, cy, k1, k2, k3, k4) (...,2,8)."""
        P = np.asarray(P_cam, float)
        X, Y, Z, rho, theta, s, g, dg, axis = self._terms(P)
        f = np.where(theta > 0, g / np.where(theta > 0, theta, 1.0), 1.0)
        m = (f * s)[..., None] * P[..., :2]
        dm = [(theta**(2 * i) * s)[..., None] * P[..., :2] for i in range(1, 5)]
        return self._k_jacobian(m, dm)

    def unproject(self, uv: np.ndarray):
        """Unit rays (...,3) of pixels (...,2) and the mask of those with one (``theta_d`` inverted by Newton's
        method inside ``theta_max``)."""
        mx, my = self._m(uv)
        rd = np.hypot(mx, my)
        theta = np.minimum(rd, 0.5 * self.theta_max)
        for _ in range(40):
            g, dg = _theta_d(self.dist, theta)
            new = np.clip(theta - (g - rd) / np.where(dg > 1e-12, dg, 1e-12), 0.0, self.theta_max)
            done = np.nanmax(np.abs(new - theta), initial=0.0) < 1e-14
            theta = new
            if done:
                break
        ok = (np.abs(_theta_d(self.dist, theta)[0] - rd) < 1e-10) & (theta < self.theta_max)
        k = np.where(rd > 0, np.sin(theta) / np.where(rd > 0, rd, 1.0), 1.0)
        return np.stack([k * mx, k * my, np.cos(theta)], axis=-1), ok & np.isfinite(rd)


def _theta_d(dist: np.ndarray, theta: np.ndarray):
    """``theta_d(theta)`` and its derivative in ``theta``."""
    k1, k2, k3, k4 = dist
    t2 = theta * theta
    g = theta * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))
    dg = 1 + t2 * (3 * k1 + t2 * (5 * k2 + t2 * (7 * k3 + t2 * 9 * k4)))
    return g, dg
