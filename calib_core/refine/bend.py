"""The joint covariance's second-order part: where the likelihood's ridge bends within its own 1-sigma.

The joint model's covariance (``refine.joint``) is the inverse information at the answer: it takes the likelihood
as Gaussian in the extrinsic's parameters ``x = (w, dt)`` (``data.residuals``' left perturbation about the answer,
radians and metres). Where the boards determine a direction poorly (three boards, far boards, a narrow spread of
normals) the likelihood's ridge along that direction is long and curved: moving along it, the best values of the
other parameters move off the straight line the information predicts, often by many of their own sigmas. The
Gaussian then holds the ridge's tangent only, and answers off along the bend look impossibly far (a NEES in the
hundreds for an error of one sigma per axis).

The correction: the weakest direction ``v`` of the covariance ``P`` (rotation scaled by the boards' distance, so
that a direction is a displacement at the boards), its 1-sigma ``s = sqrt(v^T P v)``. At the three-point
Gauss-Hermite nodes ``u = 0, +-sqrt(3) s`` the answer is re-fitted with ``v . x`` held at ``u`` (``HeldDirection``:
one Gaussian row of std ``HOLD_STD_FRACTION s``); the Gaussian's own prediction there is the conditional mean
``P v u / (v^T P v)``. The re-fit's departure ``d(u)`` from it is what the Gaussian misses, and its second moment
over the nodes is added: ``P' = P + (1/6) (d(+) d(+)^T + d(-) d(-)^T)`` (the node at 0 departs by 0). ``P' = P``
where the likelihood is Gaussian along ``v``; where it bends, ``P'`` holds the bend to the rule's order (exact for
a departure quadratic in ``u``). The answer does not change.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..geometry.metrics import pose_error_vector, sigma_rot_deg, sigma_trans_m
from ..geometry.transforms import so3_left_jacobian

BEND_NODE = np.sqrt(3.0)
"""The outer nodes of the three-point Gauss-Hermite rule (in sigmas) ..."""
BEND_WEIGHT = 1.0 / 6.0
"""... and the weight of each (the node at 0 has 2/3 and departs by 0)."""
HOLD_STD_FRACTION = 1e-2
"""A held direction's row: its std as a fraction of the direction's 1-sigma (the re-fit lands within about
``HOLD_STD_FRACTION^2`` of the node, in the direction's sigmas)."""
REFIT_COST_RTOL = 1e-8
"""A re-fit has converged when a step lowers its cost by less than this fraction (a cost of a few hundred: the
answer within about 0.002 of a sigma along its ridge)."""


@dataclass(frozen=True, eq=False)
class HeldDirection:
    """One Gaussian row on the extrinsic, ``(v . x(T) - at) / std``, with ``x(T)`` the offset of ``T`` from
    ``T0`` in ``(w, dt)`` (``geometry.metrics.pose_error_vector``: rotation vector of ``R R0^T`` in the lidar frame,
    radians; ``t - t0``, metres). The protocol of ``geometry.mounting.MountingPrior`` (``residuals``, ``jacobian``),
    so that ``refine.joint`` adds it to its cost the same way."""

    T0: np.ndarray
    v: np.ndarray
    at: float
    std: float

    def offset(self, T: np.ndarray) -> np.ndarray:
        """``x(T)`` (6,): rotation (rad) then translation (m) of ``T`` from ``T0``."""
        return pose_error_vector(T, self.T0)

    def residuals(self, T: np.ndarray) -> np.ndarray:
        """The row's normalised residual (1,) at one (4,4) ``T``."""
        return np.array([(self.v @ self.offset(T) - self.at) / self.std])

    def jacobian(self, T: np.ndarray) -> np.ndarray:
        """(1,6) d residual / d (w, dt) at ``T`` (``data.residuals``' left perturbation of ``T``): the rotation
        vector of ``exp(w) R R0^T`` moves by ``J_l(phi)^-1 w`` (``phi`` that of ``R R0^T``)."""
        x = self.offset(T)
        J = np.eye(6)
        J[:3, :3] = np.linalg.inv(so3_left_jacobian(x[:3]))
        return (self.v @ J)[None] / self.std


def weakest_direction(cov: np.ndarray, length_m: float) -> tuple[np.ndarray, float]:
    """The unit direction ``v`` (6,) in ``(w, dt)`` of the largest spread of ``cov`` (6x6, rad then m) with the
    rotation scaled by ``length_m`` (a rotation by ``w`` read as the displacement ``length_m |w|`` of a point that
    far), and the 1-sigma of ``v . x`` (``sqrt(v^T cov v)``, mixed units as ``v``)."""
    S = np.r_[[float(length_m)] * 3, [1.0] * 3]
    _, V = np.linalg.eigh(S[:, None] * cov * S[None, :])
    v = V[:, -1] * S
    v /= np.linalg.norm(v)
    return v, float(np.sqrt(v @ cov @ v))


def bent_covariance(cov: np.ndarray, v: np.ndarray, refit: Callable[[float, np.ndarray], np.ndarray]) \
        -> tuple[np.ndarray, np.ndarray]:
    """``cov`` plus the second moment of the ridge's departure from the Gaussian along ``v`` (module docstring).

    ``refit(u, x0) -> x``: the answer re-fitted with ``v . x`` held at ``u``, from the start ``x0`` (the Gaussian's
    conditional mean there), returned as its offset ``x`` (6,) from the answer. Returns (covariance, departures
    (2,6) at ``+sqrt(3) s`` and ``-sqrt(3) s``).
    """
    cov = np.asarray(cov, float)
    s2 = float(v @ cov @ v)
    gain = cov @ v / s2                                  # the Gaussian's conditional mean per unit of v . x
    nodes = BEND_NODE * np.sqrt(s2) * np.array([1.0, -1.0])
    dep = np.array([refit(float(u), gain * u) - gain * u for u in nodes])
    bent = cov + BEND_WEIGHT * dep.T @ dep
    return 0.5 * (bent + bent.T), dep


def bend_summary(cov: np.ndarray, bent: np.ndarray, v: np.ndarray, dep: np.ndarray) -> dict:
    """What a result reports of the correction: the direction (6,), how far the re-fits departed from the
    Gaussian in units of the covariance (the largest Mahalanobis length of a departure) and the 1-sigma rotation
    (degrees) and translation (mm) before and after."""
    maha = [float(np.sqrt(d @ np.linalg.solve(cov, d))) for d in dep]
    return {"direction": [float(a) for a in v], "departure_sigmas": max(maha),
            "sigma_rot_deg_laplace": sigma_rot_deg(cov), "sigma_trans_mm_laplace": 1e3 * sigma_trans_m(cov),
            "sigma_rot_deg": sigma_rot_deg(bent), "sigma_trans_mm": 1e3 * sigma_trans_m(bent)}
