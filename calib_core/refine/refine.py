"""Nonlinear refinement of ``T_lidar_cam`` on scan residuals (``scipy.optimize.least_squares``)."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from scipy.optimize import least_squares, leastsq

from ..data.observations import ScanData
from ..errors import CalibrationError
from ..geometry.mounting import MountingPrior
from ..geometry.transforms import so3_left_jacobian
from ..model.residuals import RESIDUALS, perturb


class Loss(StrEnum):
    """The robust losses of ``scipy.optimize.least_squares`` (``rho`` of the squared, scaled residual)."""

    LINEAR = "linear"
    SOFT_L1 = "soft_l1"
    HUBER = "huber"
    CAUCHY = "cauchy"
    ARCTAN = "arctan"


MAX_NFEV = 100
"""The evaluation budget of a refinement (``least_squares``' ``max_nfev``) wherever a caller gives none: the one
default of every method and stage that refines."""

F_SCALE_SIGMAS = 2.5
"""Default scale of a robust loss, in units of the range-noise std (residuals beyond 2.5 stds are down-weighted)."""


def loss_name(loss) -> str:
    """The scipy name of ``loss`` (a ``Loss`` or its name); CalibrationError for an unknown one."""
    try:
        return Loss(loss).value
    except ValueError:
        raise CalibrationError(f"unknown loss {loss!r}; choose from {sorted(m.value for m in Loss)}") from None


@dataclass(frozen=True, eq=False)
class RefineResult:
    """Outcome of a refinement.

    Attributes:
        T_lidar_cam: refined 4x4 extrinsic. cost: final ``0.5 * sum(rho(e^2))``; initial_cost likewise at
        the start. residuals: (K,) final residuals (metres). jacobian: (K,6) at the optimum, parameters
        (w, dt) as in ``calib_core.model.residuals``. success, message, nfev: from scipy.
    """

    T_lidar_cam: np.ndarray
    cost: float
    initial_cost: float
    residuals: np.ndarray
    jacobian: np.ndarray
    success: bool
    message: str
    nfev: int


def refine(data: ScanData, T0: np.ndarray, *, residual: str = "range", loss: str = "linear",
           f_scale_m: float | None = None, max_nfev: int = MAX_NFEV, x_scale: np.ndarray | None = None,
           prior: MountingPrior | None = None, prior_scale_m: float = 1.0) -> RefineResult:
    """Minimise ``sum rho(e_k^2)`` over the 6-dof extrinsic from ``T0``.

    Args:
        data: the problem's scan points and planes.
        T0: initial 4x4 ``T_lidar_cam``.
        residual: ``"range"`` (along-beam, the true noise model) or ``"plane"`` (point-to-plane distance).
        loss: a ``Loss`` or its scipy name; ``f_scale_m`` its scale (metres), e.g. ``F_SCALE_SIGMAS`` times the
            range noise std (required for a robust loss).
        prior: a mounting prior (``geometry.mounting.MountingPrior``): its six normalised residuals times
            ``prior_scale_m`` (the range-noise std, so that the whole is that std times the negative
            log-likelihood's residuals) are minimised with the scan residuals; ``residuals`` and ``jacobian`` of
            the result are the scan's, ``cost`` holds both.
    """
    loss = loss_name(loss)
    if loss != Loss.LINEAR and f_scale_m is None:
        raise CalibrationError(f"the robust loss {loss!r} needs its scale f_scale_m (metres)")
    f_scale = 1.0 if f_scale_m is None else float(f_scale_m)
    try:
        fn = RESIDUALS[residual]
    except KeyError:
        raise CalibrationError(f"unknown residual {residual!r}; choose from {sorted(RESIDUALS)}") from None
    T0 = np.asarray(T0, float)
    if prior is not None:
        fn = _with_prior(fn, prior, float(prior_scale_m))
    last: dict = {}  # the latest step: its pose, residuals and Jacobian (computed when first asked for)

    def at(x):
        if not _same(last.get("x"), x):
            T = perturb(T0, x)
            e, J = fn(T, data, jacobian="later")  # a rejected step needs no Jacobian
            last.update(x=x.copy(), T=T, e=e, J=J, jac=None)
        return last

    def linearised(x):
        step = at(x)
        if callable(step["J"]):
            step["J"] = step["J"]()
        return step["e"], step["J"]

    def fun(x):  # a copy: MINPACK keeps the first array it is given as its work space
        return at(x)["e"].copy()

    def jac(x):
        # d/dx of f(exp(w) R0): the left-perturbation Jacobian at the current pose times the left
        # Jacobian of SO(3) at w (exp(w + dw) = exp(J_l(w) dw) exp(w) to first order); kept for the step, whose
        # Jacobian leastsq asks twice at the start (a copy each time: the solver may write into it)
        step = at(x)
        if step["jac"] is None:
            J = linearised(x)[1].copy()
            J[:, :3] = J[:, :3] @ so3_left_jacobian(x[:3])
            step["jac"] = J
        return step["jac"].copy()

    e0 = fun(np.zeros(6))
    if loss == Loss.LINEAR and len(e0) >= 6:
        x, success, message, nfev = _levenberg_marquardt(fun, jac, max_nfev, x_scale)
        cost = None
    else:  # robust losses need least_squares' trust-region reflective solver
        sol = least_squares(fun, np.zeros(6), jac=jac, method="trf", loss=loss, f_scale=f_scale,
                            max_nfev=max_nfev, x_scale=x_scale if x_scale is not None else "jac")
        x, success, message, nfev, cost = sol.x, bool(sol.success), str(sol.message), int(sol.nfev), float(sol.cost)
    e, J = linearised(x)
    T = at(x)["T"]
    K = len(data.points)
    return RefineResult(T, robust_cost(e) if cost is None else cost, robust_cost(e0, loss, f_scale), e[:K], J[:K],
                        success, message, nfev)


def _same(a: np.ndarray | None, b: np.ndarray) -> bool:
    """``np.array_equal(a, b)`` for a kept (6,) step ``a`` (or None) and the solver's ``b`` (6,), with less overhead."""
    return a is not None and bool((a == b).all())


def _with_prior(fn, prior: MountingPrior, scale_m: float):
    """``fn(T, data, jacobian=...)`` (``True`` or ``"later"``) with the prior's residuals and Jacobian (times
    ``scale_m``) appended."""
    def both(T, data, jacobian=True):
        e, J = fn(T, data, jacobian="later")
        J_all = functools.partial(_stacked, J, lambda: scale_m * prior.jacobian(T))
        return np.concatenate([e, scale_m * prior.residuals(T)]), (J_all if jacobian == "later" else J_all())

    return both


def _stacked(*parts) -> np.ndarray:
    """The rows of every part's answer, one under the other (each part a function of no arguments)."""
    return np.concatenate([p() for p in parts])


LM_TOLERANCE = 1e-8
"""``ftol``, ``xtol`` and ``gtol`` of the Levenberg-Marquardt refinement (those of ``least_squares``)."""


def _levenberg_marquardt(fun, jac, max_nfev: int, x_scale: np.ndarray | None) -> tuple[np.ndarray, bool, str, int]:
    """The plain likelihood from ``x = 0`` by MINPACK's Levenberg-Marquardt (``scipy.optimize.leastsq``: the solver
    of ``least_squares(method="lm")`` with its tolerances and scaling, the Jacobian's unless ``x_scale``, without
    its per-call wrappers): (x, success, message, nfev)."""
    diag = None if x_scale is None else 1.0 / np.asarray(x_scale, float)
    x, _, info, message, ier = leastsq(fun, np.zeros(6), Dfun=jac, full_output=True, ftol=LM_TOLERANCE,
                                       xtol=LM_TOLERANCE, gtol=LM_TOLERANCE, maxfev=max_nfev, diag=diag)
    return x, ier in (1, 2, 3, 4), str(message), int(info["nfev"])


_RHO = {"linear": lambda z: z, "huber": lambda z: np.where(z <= 1, z, 2 * np.sqrt(z) - 1),
        "soft_l1": lambda z: 2 * (np.sqrt(1 + z) - 1), "cauchy": np.log1p, "arctan": np.arctan}


def robust_cost(e: np.ndarray, loss: str = "linear", scale: float = 1.0) -> float:
    """``0.5 * f^2 * sum rho((e/f)^2)``, ``f = scale`` in the residuals' units: the cost scipy's ``least_squares``
    minimises for that loss."""
    loss = loss_name(loss)
    if loss == "linear":
        return 0.5 * float(e @ e)
    return 0.5 * scale**2 * float(np.sum(_RHO[loss]((np.asarray(e) / scale) ** 2)))

