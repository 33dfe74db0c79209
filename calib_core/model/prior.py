"""The mounting prior (``geometry.mounting.MountingPrior``) in the joint model: its six Gaussian rows on the
extrinsic ``(w, dt)`` (``data.residuals``' left perturbation, radians and metres), added to the Gauss-Newton blocks of
``refine.joint`` and to its cost, so that the joint answer is the posterior's mode. The same functions add any rows
of that protocol (``residuals(T)``, ``jacobian(T)``): ``refine.bend``'s held direction."""

from __future__ import annotations

import numpy as np

from ..geometry.mounting import MountingPrior


def with_mounting(blocks: tuple, mounting: MountingPrior, T_e: np.ndarray) -> tuple:
    """The Gauss-Newton blocks (``_normal_equations``' order) with the mounting prior's rows added to the
    extrinsic's (its first six global parameters)."""
    g_e, g_b, H_ee, H_eb, H_bb = blocks
    J, r = mounting.jacobian(T_e), mounting.residuals(T_e)
    g_e, H_ee = g_e.copy(), H_ee.copy()
    g_e[:6] += J.T @ r
    H_ee[:6, :6] += J.T @ J
    return g_e, g_b, H_ee, H_eb, H_bb


def mounting_cost(mounting: MountingPrior | None, T_e: np.ndarray) -> float:
    """Minus the mounting prior's log-density at ``T_e`` (up to a constant): half its squared residuals; 0 without
    one."""
    return 0.0 if mounting is None else 0.5 * float(np.sum(mounting.residuals(T_e) ** 2))
