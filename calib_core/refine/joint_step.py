"""A method's final step when the boards carry image corners: the joint model (``refine.joint``) from the method's
answer, its covariance corrected for the likelihood's bend (``refine.bend``) and through the boards' dispersion test
(``refine.dispersion``), and what the result reports of them. Frames and units as in ``refine.joint``."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..data.lines import range_sigma
from ..data.observations import Observations
from ..data.outcome import CovariancePart, JointFitPart
from ..errors import JointError, UncertaintyError
from ..geometry.mounting import MountingPrior
from ..model.board_error import BoardErrorScale
from ..model.corners import board_poses
from ..model.intrinsics import ESTIMATED_INTRINSICS, EXACT_INTRINSICS, IntrinsicsPrior
from ..model.residuals import perturb
from .bend import HOLD_STD_FRACTION, REFIT_COST_RTOL, HeldDirection, bend_summary, bent_covariance, weakest_direction
from .dispersion import widened_covariance
from .joint import (
    JOINT_INTRINSICS_MODEL,
    JOINT_MODEL,
    JointOptions,
    board_scores,
    estimate_sigmas,
    intrinsics_marginal_covariance,
    joint_refine,
)


@dataclass(frozen=True, eq=False)
class JointStep:
    """``joint_step``'s answer: the extrinsic ``T_lidar_cam`` (4x4), its covariance with the model it comes from
    (``data.outcome.CovariancePart``), the joint model's fit (``data.outcome.JointFitPart``) and the warnings."""

    T_lidar_cam: np.ndarray
    covariance: CovariancePart
    fit: JointFitPart
    warnings: list[str]


def joint_step(obs: Observations, T0: np.ndarray, options: JointOptions | None = None, *,
               range_sigma_m: float | None = None, loss: str = "linear", names=None,
               mounting: MountingPrior | None = None, board_error: BoardErrorScale | None = None,
               spread_held: bool = False) -> JointStep:
    """A method's final step when the boards carry image corners: ``joint_refine`` from ``T0`` under the joint
    ``options`` (``refine.joint.JointOptions``: the corner noise, the robust scale, the iterations, the outline
    terms, ``widen``, ``bend``; default the defaults; its ``use_corners`` and ``board_error`` are the caller's, who
    decides whether to take this step and passes the per-board term's scale as ``board_error``); returns a
    ``JointStep`` whose covariance's model is ``JOINT_MODEL`` (or ``JOINT_INTRINSICS_MODEL`` when the camera's
    ``std_intrinsics`` made the intrinsics unknowns), its intrinsics ``EXACT_INTRINSICS`` or
    ``ESTIMATED_INTRINSICS``, with the noise figures in its fit. With ``options.widen``, the covariance's
    ``dispersion`` holds the boards' dispersion test (``refine.dispersion``; boards named by ``names``, default
    their index) and where it fails the covariance is widened to the boards' spread, with a warning that says so.
    With ``options.bend`` (and no mounting prior, whose rows cut the ridge to the prior's width) the covariance
    first takes the likelihood's bend along its weakest direction (``refine.bend``: two re-fits), reported as the
    covariance's ``bend``. ``board_error``: the per-board systematic error the model holds (``model.board_error``,
    ``refine.systematic``); the dispersion test is then of the model with it, and with ``spread_held`` (its scale
    estimated from these boards) the test is reported without widening. The range noise is then the scan lines'
    (``data.lines``) unless ``range_sigma_m``, not re-estimated from residuals that hold the boards' own errors.
    ``loss``: the robust loss (``refine.Loss``), its scale ``options.f_scale_sigmas`` noise stds.

    Raises JointError (no corners, a board behind the camera) and UncertaintyError (singular information).
    """
    o = options or JointOptions()
    if board_error is not None and board_error.active:  # the beams' noise: the scatter within each board's line
        range_sigma_m = range_sigma(obs, range_sigma_m)
    j = joint_refine(obs, T0, corner_sigma_px=o.corner_sigma_px, range_sigma_m=range_sigma_m, loss=loss,
                     f_scale_sigmas=o.f_scale_sigmas, max_iter=o.max_iter, outline=o.outline, mounting=mounting,
                     board_error=board_error)
    exact, cov, warnings = j.camera is None, j.covariance, []
    bent = {}
    if o.bend and mounting is None:
        term = 0.0  # the bend is the per-beam likelihood's; the per-board term's part is added to it unchanged
        if board_error is not None and board_error.active:
            prior = None if j.intrinsics is None else IntrinsicsPrior.of(obs.camera)
            per_beam = intrinsics_marginal_covariance(obs, j.T_lidar_cam, j.T_cam_board, j.corner_sigma_px,
                                                      j.range_sigma_m, prior, j.intrinsics, o.outline)[:6, :6]
            term, j = cov - per_beam, replace(j, covariance=per_beam)
        cov, bent, why = bent_joint_covariance(obs, j, loss, o)
        cov = cov + term
        warnings += [why] if why else []
    widen = o.widen and obs.n_boards > 3  # three boards fit exactly; units: the noise each sensor shows alone
    if widen:
        sc = o.corner_sigma_px if o.corner_sigma_px is not None else \
            estimate_sigmas(obs, j.T_lidar_cam, board_poses(obs), 6 * obs.n_boards, j.camera)[0]
        sr = range_sigma(obs, range_sigma_m)
        cov, disp = widened_covariance(cov, *board_scores(obs, j.T_lidar_cam, j.T_cam_board, sc, sr, j.camera),
                                       extra_params=intrinsics_parameters(obs, j, o.outline), held=spread_held)
        warnings += [disp.warning(names)] if disp.widened else []
    if not j.converged:
        warnings.insert(0, f"joint refinement stopped after {o.max_iter} iterations without converging")
    part = CovariancePart(cov, JOINT_MODEL if exact else JOINT_INTRINSICS_MODEL,
                          EXACT_INTRINSICS if exact else ESTIMATED_INTRINSICS,
                          dispersion=disp.to_dict(names) if widen else None, bend=bent or None)
    fit = JointFitPart(j.corner_sigma_px, j.range_sigma_m, j.corner_rms_px, j.range_rms_m, j.cost, j.iterations,
                       j.converged)
    return JointStep(j.T_lidar_cam, part, fit, warnings)


def bent_joint_covariance(obs: Observations, j, loss: str,
                          options: JointOptions) -> tuple[np.ndarray, dict, str | None]:
    """The joint answer ``j``'s (``refine.joint.JointResult``) covariance with the bend of the likelihood along its
    weakest direction (``refine.bend``; rotation scaled by the scan points' median range): each re-fit is the joint
    model at ``j``'s noise stds with that direction held, under ``loss`` and ``options``' robust scale, iterations
    and outline terms. Returns (covariance, ``bend_summary``, None), or ``j``'s covariance, {} and a warning when a
    re-fit fails."""
    length = float(np.median(np.linalg.norm(obs.scan_data.points, axis=1)))
    v, s = weakest_direction(j.covariance, length)

    def refit(u: float, x0: np.ndarray) -> np.ndarray:
        hold = HeldDirection(j.T_lidar_cam, v, u, HOLD_STD_FRACTION * s)
        r = joint_refine(obs, perturb(j.T_lidar_cam, x0), corner_sigma_px=j.corner_sigma_px,
                         range_sigma_m=j.range_sigma_m, loss=loss, f_scale_sigmas=options.f_scale_sigmas,
                         max_iter=options.max_iter, sigma_iters=1, intrinsics=j.camera is not None,
                         outline=options.outline, hold=hold, covariance=False, start=j, tol=REFIT_COST_RTOL)
        return hold.offset(r.T_lidar_cam)

    try:
        cov, dep = bent_covariance(j.covariance, v, refit)
        why = None if np.all(np.isfinite(cov)) else "a re-fit gave no finite answer"
    except (JointError, UncertaintyError, np.linalg.LinAlgError) as err:
        why = str(err)
    if why is not None:
        return j.covariance, {}, f"the covariance's bend along its weakest direction was not computed ({why}): " \
            "it is the Gaussian approximation at the answer"
    return cov, bend_summary(j.covariance, cov, v, dep), None


def intrinsics_parameters(obs: Observations, j, outline: bool) -> int:
    """How many parameters the free intrinsics of the joint answer ``j`` fit to the boards (0 with none): their
    effective number under the prior, ``m - tr(C_kk Lambda)`` (``C_kk`` their posterior covariance, ``Lambda`` the
    prior's information), rounded; each takes a degree of freedom from the boards' dispersion test."""
    prior = None if j.intrinsics is None else IntrinsicsPrior.of(obs.camera)
    if prior is None:
        return 0
    C = intrinsics_marginal_covariance(obs, j.T_lidar_cam, j.T_cam_board, j.corner_sigma_px, j.range_sigma_m, prior,
                                       j.intrinsics, outline)[6:, 6:]
    return int(round(prior.size - float(np.sum(np.diag(C) / prior.std**2))))
