"""Derived methods by name suffix: ``X+ml`` (maximum-likelihood refinement on the range residuals), ``X+plane``
(refinement on point-to-plane distances) and ``X+joint`` (joint maximum likelihood over image corners and ranges,
``calib_core.refine.joint``) for any method ``X``, each with a covariance and ``info["covariance_model"]``."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..checks.degeneracy import explain_failure
from ..data.lines import range_sigma
from ..data.observations import Observations
from ..data.outcome import CovariancePart, InfoParts
from ..errors import SolveFailure
from ..model.board_error import BoardErrorScale
from ..model.intrinsics import RANGE_ONLY_INTRINSICS
from ..refine.joint import RANGE_ONLY_MODEL, JointOptions
from ..refine.refine import F_SCALE_SIGMAS, MAX_NFEV, refine
from ..refine.systematic import ESTIMATED, board_error_estimate
from ..refine.uncertainty import conditioning
from ..registry import Method, derived
from ..robust.choose import ChooseOptions
from .last_steps import (
    fixed_calibration,
    fold_covariance,
    profile_floor,
    range_covariance,
    refuse_undetermined,
    try_joint,
)

REFINE_OPTIONS = ("loss", "f_scale_m", "range_sigma_m", "max_nfev", "fixed")
"""Options of an ``X+ml`` / ``X+plane`` method that go to the refinement (metres); all others go to ``X``."""


def refine_and_cover(obs: Observations, T0: np.ndarray, residual: str, *, loss: str = "linear",
                     f_scale_m: float | None = None, range_sigma_m: float | None = None, max_nfev: int = MAX_NFEV,
                     board_error: BoardErrorScale | None = None):
    """Refine ``T0`` on ``residual`` (robust scale ``f_scale_m`` metres, default ``F_SCALE_SIGMAS`` noise stds)
    and compute the covariance, holding the per-board systematic error ``board_error`` where given (range
    residual; ``model.board_error``); returns (RefineResult, the info's parts: the refinement's report, the
    covariance with its model, the warnings).

    Directions the board geometry leaves free (``calib_core.checks.degeneracy``) are not presented as estimated: a
    SolveFailure names them, with the analysis in its info."""
    data = obs.scan_data
    if f_scale_m is None:
        f_scale_m = F_SCALE_SIGMAS * range_sigma(obs, range_sigma_m)
    r = refine(data, T0, residual=residual, loss=loss, f_scale_m=f_scale_m, max_nfev=max_nfev)
    deg = refuse_undetermined(obs, r.T_lidar_cam, np.stack([r.T_lidar_cam, T0]), "refinement", range_sigma_m)
    term = board_error if residual == "range" else None
    cov = fold_covariance(obs, r.T_lidar_cam, deg, term) if residual == "range" and deg.profile.any() else \
        range_covariance(obs, r.T_lidar_cam, T0[None], "refinement", residual, range_sigma_m, board_error=term)
    cov = profile_floor(r.T_lidar_cam, cov, deg)
    report = {"refine_cost": r.cost, "refine_initial_cost": r.initial_cost, "refine_nfev": r.nfev,
              "refine_residual": residual, "refine_loss": str(loss)}
    part = CovariancePart(cov, RANGE_ONLY_MODEL, RANGE_ONLY_INTRINSICS, conditioning(obs, r.T_lidar_cam))
    return r, InfoParts(refinement=report, covariance=part, warnings=[deg.message()] if len(deg.directions) else None)


def board_error_term(obs: Observations, T0: np.ndarray, range_sigma_m: float | None):
    """The per-board systematic error at the base method's answer ``T0`` (``refine.systematic.board_error_estimate``,
    ``range_sigma_m`` metres or None: the scan lines') and the term a suffix's covariance holds: its scale, or None
    for a zero one (the per-beam path)."""
    est = board_error_estimate(obs, T0, range_sigma_m)
    return est, est.scale if est.scale.active else None


def _refine_options(options: dict) -> dict:
    """The refinement's options popped from ``options`` (``calibrate`` has checked them against the schema)."""
    return {k: options.pop(k) for k in REFINE_OPTIONS if k in options}


def refined_method(base: Method, residual: str, suffix: str) -> Method:
    """The method ``base.name + "+" + suffix``: run ``base``, then refine its answer on ``residual``
    (``"range"``: maximum likelihood under range noise; ``"plane"``: point-to-plane distances), with the
    covariance of the refined extrinsic, holding the per-board systematic error on the range residual as
    ``lidarcam`` does (``refine.systematic.board_error_estimate`` at the base's answer; ``info["board_error"]``).
    Options ``loss``, ``f_scale_m`` (metres, default ``F_SCALE_SIGMAS`` x the
    noise std), ``range_sigma_m`` (default: estimated), ``max_nfev`` and ``fixed`` (mounting parameters held at
    given values, as for ``lidarcam``) go to the refinement, the rest to ``base``."""
    def func(obs: Observations, **options):
        ropts = _refine_options(options)
        fixed = ropts.pop("fixed", None)
        if fixed is not None:
            choose = ChooseOptions(**{k: ropts.pop(k) for k in ("loss", "f_scale_m", "max_nfev") if k in ropts})
            T, starts, parts = fixed_calibration(obs, fixed, lambda: base.func(obs, **options)[0], choose,
                                                 residual=residual, **ropts)
            return T, starts, parts.to_info()
        try:
            T0, cands, info = base.func(obs, **options)
        except SolveFailure as fail:
            raise explain_failure(obs, fail, ropts.get("range_sigma_m")) from None
        T0 = np.asarray(T0, float)
        est, term = board_error_term(obs, T0, ropts.get("range_sigma_m")) if residual == "range" else (None, None)
        r, parts = refine_and_cover(obs, T0, residual, board_error=term, **ropts)
        warnings = info.get("warnings", []) + (parts.warnings or [])
        return r.T_lidar_cam, cands, replace(parts, base=info, base_T_lidar_cam=T0,
                                             board_error=None if est is None else est.to_dict(),
                                             warnings=warnings or None).to_info()

    what = "maximum-likelihood refinement on the range residuals" if residual == "range" else \
        "refinement on the point-to-plane distances"
    return derived(base, suffix, func, f"{base.name}, then {what}, with covariance", REFINE_OPTIONS)


JOINT_OPTIONS = ("loss", "f_scale_sigmas", "range_sigma_m", "corner_sigma_px", "max_iter", "widen", "outline",
                 "board_error")
"""Options of an ``X+joint`` method that go to the joint refinement (``f_scale_sigmas`` in noise stds;
``board_error``: whether its covariance holds the per-board systematic error, as ``lidarcam``'s); all others go to
``X``."""


def joint_method(base: Method) -> Method:
    """The method ``base.name + "+joint"``: run ``base``, then the joint maximum likelihood over the image corners
    and the ranges from its answer (``refine.joint_step``; options ``JOINT_OPTIONS``, ``f_scale_sigmas`` in noise
    stds), with the extrinsic's covariance, board poses marginalised, holding the per-board systematic error as
    ``lidarcam`` does (``refine.systematic.board_error_estimate`` at the base's answer; ``info["board_error"]``).
    Without corners on every board it is ``X+ml`` and says so in ``info["warnings"]`` (its covariance ignores the
    camera's noise; it holds the per-board term)."""
    def func(obs: Observations, **options):
        jopts = {k: options.pop(k) for k in JOINT_OPTIONS if k in options}
        T0, cands, info = base.func(obs, **options)
        T0 = np.asarray(T0, float)
        loss, sigma = jopts.pop("loss", "linear"), jopts.pop("range_sigma_m", None)
        jo = JointOptions(**jopts)
        est, term = board_error_term(obs, T0, sigma) if jo.board_error else (None, None)
        held = est is not None and est.source == ESTIMATED
        berr = est.to_dict() if est is not None else None
        joint, why = try_joint(obs, T0, range_sigma_m=sigma, loss=loss, options=jo, board_error=term,
                               spread_held=held)
        if joint is not None:
            T = joint.T_lidar_cam
            warnings = [*info.get("warnings", []), *joint.warnings]
            cov = replace(joint.covariance, conditioning=conditioning(obs, T))
            return T, cands, InfoParts(base=info, covariance=cov, joint=joint.fit, base_T_lidar_cam=T0,
                                       board_error=berr, warnings=warnings or None).to_info()
        r, parts = refine_and_cover(obs, T0, "range", loss=loss, range_sigma_m=sigma, board_error=term)
        warn = f"{why}: range-only maximum likelihood; its covariance ignores the camera's noise"
        return r.T_lidar_cam, cands, replace(parts, base=info, base_T_lidar_cam=T0, board_error=berr,
                                             warnings=[*info.get("warnings", []), warn]).to_info()

    return derived(base, "joint", func, f"{base.name}, then joint maximum likelihood over image corners and "
                   "lidar ranges (board poses estimated), with covariance", JOINT_OPTIONS)


SUFFIX_FACTORIES = {
    "ml": lambda base: refined_method(base, "range", "ml"),
    "plane": lambda base: refined_method(base, "plane", "plane"),
    "joint": joint_method,
}
