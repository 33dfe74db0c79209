"""Derived methods by name suffix: ``X+ml`` (maximum-likelihood refinement on the range residuals), ``X+plane``
(refinement on point-to-plane distances) and ``X+joint`` (joint maximum likelihood over image corners and ranges,
``calib_core.refine.joint``) for any method ``X``, each with a covariance and ``info["covariance_model"]``."""

from __future__ import annotations

import numpy as np

from ..checks.degeneracy import board_set_warnings, explain_failure, undetermined_directions
from ..data.observations import Observations
from ..data.result import SolveFailure
from ..geometry.mounting import parse_fixed
from ..refine.joint import RANGE_ONLY_MODEL, JointError, joint_step
from ..refine.partial import calibrate_fixed, fixed_starts
from ..refine.refine import refine
from ..refine.uncertainty import UncertaintyError, conditioning, refinement_covariance, scan_noise_estimate
from ..registry import Method, derived

REFINE_OPTIONS = ("loss", "f_scale", "range_sigma_m", "max_nfev", "fixed")
"""Options of an ``X+ml`` / ``X+plane`` method that go to the refinement; all others go to ``X``."""

F_SCALE_SIGMAS = 2.5
"""Default robust-loss scale, in units of the range noise std."""


def refine_and_cover(obs: Observations, T0: np.ndarray, residual: str, *, loss: str = "linear",
                     f_scale: float | None = None, range_sigma_m: float | None = None, max_nfev: int = 100):
    """Refine ``T0`` on ``residual`` and compute the covariance; returns (RefineResult, covariance, info).

    Directions the board geometry leaves free (``calib_core.checks.degeneracy``) are not presented as estimated: a
    SolveFailure names them, with the analysis in its info."""
    data = obs.scan_data
    if f_scale is None:
        f_scale = F_SCALE_SIGMAS * (range_sigma_m if range_sigma_m is not None else scan_noise_estimate(obs))
    r = refine(data, T0, residual=residual, loss=loss, f_scale=f_scale, max_nfev=max_nfev)
    deg = undetermined_directions(obs, r.T_lidar_cam, range_sigma_m)
    if not deg.determined:
        raise SolveFailure(f"refinement: {deg.message()}", np.stack([r.T_lidar_cam, T0]),
                           {"degeneracy": deg.to_dict(), "warnings": board_set_warnings(obs)})
    try:
        cov = refinement_covariance(data, r.T_lidar_cam, residual, range_sigma_m)
    except UncertaintyError as err:
        raise SolveFailure(f"refinement: {err}", T0[None]) from None
    info = {"refine_cost": r.cost, "refine_initial_cost": r.initial_cost, "refine_nfev": r.nfev,
            "refine_residual": residual, "refine_loss": loss, "covariance": cov, "covariance_model": RANGE_ONLY_MODEL,
            "conditioning": conditioning(obs, r.T_lidar_cam)}
    if len(deg.directions):
        info["warnings"] = [deg.message()]
    return r, cov, info


def refine_fixed(base: Method, obs: Observations, residual: str, fixed: dict, options: dict, *, loss: str = "linear",
                 f_scale: float | None = None, range_sigma_m: float | None = None, max_nfev: int = 100):
    """``X+ml`` / ``X+plane`` with ``fixed`` mounting parameters (``calib_core.refine.partial``): the free ones refined
    on ``residual`` from a closed-form start (roll, pitch and z given) or from ``X``'s answer."""
    mask, values = parse_fixed(fixed)
    if f_scale is None:
        f_scale = F_SCALE_SIGMAS * (range_sigma_m if range_sigma_m is not None else scan_noise_estimate(obs))
    starts = fixed_starts(obs, mask, values, lambda: base.func(obs, **options)[0])
    T, info = calibrate_fixed(obs, mask, values, starts, residual=residual, loss=loss, f_scale=f_scale,
                              range_sigma_m=range_sigma_m, max_nfev=max_nfev)
    return T, np.asarray(starts), {**info, "refine_residual": residual, "refine_loss": loss,
                                   "warnings": board_set_warnings(obs)}


def refined_method(base: Method, residual: str, suffix: str) -> Method:
    """The method ``base.name + "+" + suffix``: run ``base``, then refine its answer on ``residual``
    (``"range"``: maximum likelihood under range noise; ``"plane"``: point-to-plane distances), with the
    covariance of the refined extrinsic. Options ``loss``, ``f_scale`` (default ``F_SCALE_SIGMAS`` x the noise
    std), ``range_sigma_m`` (default: estimated), ``max_nfev`` and ``fixed`` (mounting parameters held at given
    values, as for ``lidarcam``) go to the refinement, the rest to ``base``."""
    def func(obs: Observations, **options):
        ropts = {k: options.pop(k) for k in REFINE_OPTIONS if k in options}
        fixed = ropts.pop("fixed", None)
        if fixed is not None:
            return refine_fixed(base, obs, residual, fixed, options, **ropts)
        try:
            T0, cands, info = base.func(obs, **options)
        except SolveFailure as fail:
            raise explain_failure(obs, fail, ropts.get("range_sigma_m")) from None
        r, _, rinfo = refine_and_cover(obs, np.asarray(T0, float), residual, **ropts)
        warnings = info.get("warnings", []) + rinfo.pop("warnings", [])
        return r.T_lidar_cam, cands, {**info, **rinfo, "base_T_lidar_cam": np.asarray(T0, float),
                                      **({"warnings": warnings} if warnings else {})}

    what = "maximum-likelihood refinement on the range residuals" if residual == "range" else \
        "refinement on the point-to-plane distances"
    return derived(base, suffix, func, f"{base.name}, then {what}, with covariance")


JOINT_OPTIONS = ("loss", "f_scale", "range_sigma_m", "corner_sigma_px", "max_iter")
"""Options of an ``X+joint`` method that go to the joint refinement; all others go to ``X``."""


def joint_method(base: Method) -> Method:
    """The method ``base.name + "+joint"``: run ``base``, then the joint maximum likelihood over the image corners
    and the ranges from its answer (``refine.joint.joint_step``; options ``JOINT_OPTIONS``, ``f_scale`` in noise
    stds), with the extrinsic's covariance, board poses marginalised. Without corners on every board it is
    ``X+ml`` and says so in ``info["warnings"]`` (its covariance ignores the camera's noise)."""
    def func(obs: Observations, **options):
        jopts = {k: options.pop(k) for k in JOINT_OPTIONS if k in options}
        T0, cands, info = base.func(obs, **options)
        T0 = np.asarray(T0, float)
        why = "no image corners" if not obs.has_corners else None
        if why is None:
            try:
                T, cov, jinfo = joint_step(obs, T0, **jopts)
            except (JointError, UncertaintyError) as err:
                why = f"joint refinement failed ({err})"
            else:
                jinfo["conditioning"] = conditioning(obs, T)
                return T, cands, {**info, **jinfo, "covariance": cov, "base_T_lidar_cam": T0}
        ropts = {k: jopts[k] for k in ("loss", "range_sigma_m") if k in jopts}
        r, _, rinfo = refine_and_cover(obs, T0, "range", **ropts)
        warn = f"{why}: range-only maximum likelihood; its covariance ignores the camera's noise"
        return r.T_lidar_cam, cands, {**info, **rinfo, "base_T_lidar_cam": T0,
                                      "warnings": [*info.get("warnings", []), warn]}

    return derived(base, "joint", func, f"{base.name}, then joint maximum likelihood over image corners and "
                   "lidar ranges (board poses estimated), with covariance")


SUFFIX_FACTORIES = {
    "ml": lambda base: refined_method(base, "range", "ml"),
    "plane": lambda base: refined_method(base, "plane", "plane"),
    "joint": joint_method,
}
