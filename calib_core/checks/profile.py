"""The profile likelihood of the range model along one direction of the extrinsic: how far the answer can move
along it before the data object, the other five directions re-fitted at every step.

Used by the degeneracy analysis (``checks.degeneracy``) where the range model's first-order information vanishes
along a direction although the board geometry does not leave it free: at a fold of the board set's solutions.
With three boards the six range constraints meet the six unknowns exactly, and where the scan noise has pushed
two of the minimal solver's real solutions together (or just past the point where they turn complex) the
least-squares answer sits where they meet; there the residuals change only at second order along the direction
joining them, so the Fisher information says "no information" while the likelihood itself still rises. The
linear analysis cannot tell this from a direction the boards leave free at every order (vertical boards, fewer
than three planes); the profile can.

Axes and units as ``checks.degeneracy``: a small rigid motion ``T_lidar_cam -> [exp(w) | dt] T_lidar_cam`` about
the lidar's origin, rotations in radians, translations in units of the typical range ``scale_m``.
"""

from __future__ import annotations

import numpy as np

from ..data.observations import ScanData
from ..data.residuals import range_residuals
from ..geometry.transforms import rotvec_to_matrix, skew

PROFILE_ONE_SIGMA = 0.5
"""A profile rise of this (negative log-likelihood, i.e. half a chi-square with one degree of freedom) marks the
1-sigma bound along the direction: the same rule as ``sigma`` of a quadratic profile."""
PROFILE_GN_STEPS = 8
"""Gauss-Newton steps of the other five directions at each point of the profile (they are well determined, so
a few steps converge; the profile is then an upper bound only by their residual error)."""
PROFILE_DOUBLINGS = 12
"""``profile_sigma`` steps out from ``span`` / 2^12 (scaled units) by doublings ..."""
PROFILE_BISECTIONS = 10
"""... then bisects the step where the profile first reaches its 1-sigma this many times (to 2^-10 of it)."""


def move(T: np.ndarray, x: np.ndarray, scale_m: float) -> np.ndarray:
    """``T_lidar_cam`` moved by ``x`` (6,) in the scaled lidar-origin axes: ``[exp(w) | dt L] T``."""
    M = np.eye(4)
    M[:3, :3] = rotvec_to_matrix(x[:3])
    M[:3, 3] = x[3:] * scale_m
    return M @ np.asarray(T, float)


def _origin_jacobian(J: np.ndarray, T: np.ndarray, scale_m: float) -> np.ndarray:
    """The residual Jacobian of ``data.residuals`` in the scaled lidar-origin axes (``degeneracy.origin_jacobian``
    with translations scaled)."""
    t = np.asarray(T, float)[:3, 3]
    return np.concatenate([J[:, :3] - J[:, 3:] @ skew(t), J[:, 3:] * scale_m], axis=1)


def profile_rise(data: ScanData, T: np.ndarray, v: np.ndarray, delta: float, scale_m: float,
                 sigma_m: float) -> float:
    """The range model's negative log-likelihood at ``T`` moved ``delta`` along the unit direction ``v`` (scaled
    axes), minimised over the five directions orthogonal to ``v`` (``PROFILE_GN_STEPS`` Gauss-Newton steps from
    there), less its value at ``T``: ``(|e|^2 - |e_0|^2) / (2 sigma^2)``. At an optimum it is >= 0 up to the
    re-fit's error."""
    v = np.asarray(v, float) / np.linalg.norm(v)
    B = np.linalg.svd(np.eye(6) - np.outer(v, v))[0][:, :5]               # the orthogonal complement of v
    e0 = range_residuals(np.asarray(T, float), data)
    Tk = move(T, delta * v, scale_m)
    e = range_residuals(Tk, data)
    for _ in range(PROFILE_GN_STEPS):
        e, J = range_residuals(Tk, data, jacobian=True)
        step = np.linalg.lstsq(_origin_jacobian(J, Tk, scale_m) @ B, -e, rcond=None)[0]
        T_next = move(Tk, B @ step, scale_m)
        e_next = range_residuals(T_next, data)
        if e_next @ e_next >= e @ e:
            break
        Tk, e = T_next, e_next
    return float((e @ e - e0 @ e0) / (2.0 * sigma_m**2))


def profile_sigma(data: ScanData, T: np.ndarray, v: np.ndarray, span: float, scale_m: float,
                  sigma_m: float) -> float:
    """The profile 1-sigma along ``v`` (scaled units): on each side the nearest ``delta`` at which the profile
    (``profile_rise``) reaches ``PROFILE_ONE_SIGMA``, stepping out from ``span`` / 2^``PROFILE_DOUBLINGS`` by
    doublings and then bisecting (the nearest crossing: far out, the five re-fitted directions can find other
    poses); the larger of the two sides, or ``inf`` when a side does not reach it within ``span``."""
    out = 0.0
    for sign in (1.0, -1.0):
        def rises(delta, sign=sign):
            return profile_rise(data, T, v, sign * delta, scale_m, sigma_m) >= PROFILE_ONE_SIGMA

        steps = span * 0.5 ** np.arange(PROFILE_DOUBLINGS, -1, -1)
        first = next((k for k, d in enumerate(steps) if rises(d)), None)
        if first is None:
            return float("inf")
        lo, hi = (0.0 if first == 0 else steps[first - 1]), steps[first]
        for _ in range(PROFILE_BISECTIONS):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if rises(mid) else (mid, hi)
        out = max(out, hi)
    return float(out)
