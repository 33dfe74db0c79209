"""The last steps every method of ours shares (``lidarcam`` and the suffix methods ``X+ml``, ``X+plane``,
``X+joint``), each written once: the refusal of directions the board geometry does not determine, the joint step
over image corners and ranges (or why it does not apply), the range model's covariance, and the calibration with
fixed mounting parameters."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.stats import chi2

from ..checks.degeneracy import Degeneracy, DegeneracyOptions, board_set_warnings, fixed_key, undetermined_directions
from ..data.lines import range_sigma
from ..data.observations import Observations
from ..data.outcome import InfoParts
from ..errors import JointError, SolveFailure, UncertaintyError
from ..geometry.mounting import MountingPrior, params_from_T, parse_fixed, with_units
from ..geometry.transforms import skew
from ..model.board_error import BoardErrorScale
from ..model.residuals import range_linearised
from ..refine.dispersion import widened_covariance
from ..refine.joint import JointOptions
from ..refine.joint_step import JointStep, joint_step
from ..refine.partial import fixed_starts, refine_free
from ..refine.systematic import fold_noise_ratio
from ..refine.uncertainty import (
    inverse_information,
    range_board_scores,
    refinement_covariance,
    systematic_sandwich,
)
from ..robust.choose import ChooseOptions


def refuse_undetermined(obs: Observations, T: np.ndarray, candidates: np.ndarray, who: str,
                        range_sigma_m: float | None, options: DegeneracyOptions | None = None,
                        refuse: bool = True) -> Degeneracy:
    """The degeneracy analysis at ``T`` (``checks.degeneracy.undetermined_directions``); a SolveFailure naming
    the directions the board geometry leaves free, with the analysis and the board-set warnings in its info
    (``refuse=False``: the analysis alone, for a caller whose prior determines those directions; ``T`` is then
    the posterior's mode, not the range optimum, and vertical boards' roll, pitch and z are left to the prior
    without a profile: ``profile_vertical``)."""
    options = options or DegeneracyOptions()
    deg = undetermined_directions(obs, T, range_sigma_m, max_scaled_sigma=options.max_scaled_sigma,
                                  null_conditioning=options.null_conditioning, profile_vertical=refuse)
    if refuse and not deg.determined:
        raise undetermined_failure(obs, deg, candidates, who)
    return deg


def undetermined_failure(obs: Observations, deg: Degeneracy, candidates: np.ndarray, who: str) -> SolveFailure:
    """The refusal naming the directions ``deg`` finds free, with the analysis and the board-set warnings."""
    return SolveFailure(f"{who}: {deg.message()}", candidates,
                        {"degeneracy": deg.to_dict(), "warnings": board_set_warnings(obs)})


def fold_covariance(obs: Observations, T: np.ndarray, deg: Degeneracy,
                    board_error: BoardErrorScale | None = None) -> np.ndarray:
    """The range model's covariance at ``T`` (6x6 in the parameters of ``data.residuals``) where the degeneracy
    analysis found folds (``Degeneracy.profile``): the first-order information with, along each fold direction
    (an eigen-direction of it), the information of its profile 1-sigma in place of the linear one (``1 / sigma^2``
    in the scaled lidar-origin axes), since the linearisation holds none or next to none there. Noise std:
    ``deg.range_sigma_m`` (the beams'). ``board_error``: the per-board systematic error held
    (``model.board_error``): each fold's profile 1-sigma grown by the fourth root of
    ``refine.systematic.fold_noise_ratio`` and the whole the sandwich of ``refine.uncertainty.systematic_sandwich``
    (the per-beam estimator under the term); without one, or with a zero one, the per-beam model exactly."""
    T = np.asarray(T, float)
    data = obs.scan_data
    e, J = range_linearised(T, data)
    A = _origin_axes(T, deg.scale_m)                # scaled lidar-origin axes -> the parameters of data.residuals
    term = board_error is not None and board_error.active
    grow = fold_noise_ratio(data, T, board_error, deg.range_sigma_m) ** 0.25 if term else 1.0
    Fs = (J @ A).T @ (J @ A) / deg.range_sigma_m**2
    for v, s in zip(deg.directions[deg.profile], deg.sigmas[deg.profile], strict=True):
        Fs = Fs + (1.0 / (grow * s) ** 2 - v @ Fs @ v) * np.outer(v, v)
    Cs = inverse_information(Fs, 1e-12)
    if term:
        Cs = systematic_sandwich(Cs, data, T, J @ A, board_error, deg.range_sigma_m)
    return A @ Cs @ A.T


def _origin_axes(T: np.ndarray, scale_m: float) -> np.ndarray:
    """(6,6) from the scaled lidar-origin axes of ``checks.degeneracy`` to the parameters of ``data.residuals``."""
    A = np.eye(6)
    A[3:, :3] = -skew(np.asarray(T, float)[:3, 3])
    A[:, 3:] *= scale_m
    return A


def profile_floor(T: np.ndarray, cov: np.ndarray, deg: Degeneracy) -> np.ndarray:
    """``cov`` (6x6 in the parameters of ``data.residuals``) at ``T`` widened so that along each direction whose
    sigma the profile likelihood raised above the linear one (``Degeneracy.floors``, unit ``v_i`` in the scaled
    lidar-origin axes) its 1-sigma is that sigma ``s_i`` exactly: with ``W`` the stacked directions, ``B = W C W^T``
    their block and ``G = C W^T B^-1`` the regression of every parameter on them, ``C + G diag(d) G^T`` with
    ``d_i = max(0, s_i^2 - B_ii)`` (independent extra error along each, carried to the others as the data
    correlate them; never a smaller covariance). ``cov`` itself where there is none, or the set is refused."""
    floors = deg.floors if len(deg.floors) == len(deg.sigmas) else np.zeros(len(deg.sigmas), bool)
    if not floors.any() or deg.geometric:
        return cov
    A = _origin_axes(T, deg.scale_m)
    Ai = np.linalg.inv(A)
    C = Ai @ np.asarray(cov, float) @ Ai.T
    W, s = deg.directions[floors], deg.sigmas[floors]
    B = W @ C @ W.T
    d = np.maximum(0.0, np.where(np.isfinite(s), s, 0.0) ** 2 - np.diag(B))
    if not d.any():
        return cov
    G = C @ W.T @ np.linalg.pinv(B)
    out = A @ (C + G @ np.diag(d) @ G.T) @ A.T
    return 0.5 * (out + out.T)


NO_CORNERS = "no image corners"
"""``try_joint``'s reason when a board carries no image corners."""


def try_joint(obs: Observations, T: np.ndarray, *, range_sigma_m: float | None, loss: str,
              options: JointOptions | None = None, names=None,
              mounting: MountingPrior | None = None,
              board_error: BoardErrorScale | None = None,
              spread_held: bool = False) -> tuple[JointStep | None, str | None]:
    """The joint step (``refine.joint_step.joint_step``) from ``T``: (its ``JointStep``, None) when it applies and
    succeeds; (None, why) otherwise (``why`` None when the corners are switched off). ``names``: the boards' names
    in its warnings (default their index in ``obs``); ``mounting``: a mounting prior in its cost (the covariance
    stays the data's: ``with_prior`` adds the prior's information); ``board_error``: the per-board systematic error
    the joint model holds (``model.board_error``), ``spread_held``: its scale estimated from these boards (the
    dispersion test reported, the covariance not widened)."""
    options = options or JointOptions()
    if not options.use_corners:
        return None, None
    if not obs.has_corners:
        return None, NO_CORNERS
    try:
        return joint_step(obs, T, options, range_sigma_m=range_sigma_m, loss=loss, names=names, mounting=mounting,
                          board_error=board_error, spread_held=spread_held), None
    except (JointError, UncertaintyError) as err:
        return None, f"joint refinement failed ({err})"


def range_covariance(obs: Observations, T: np.ndarray, candidates: np.ndarray, who: str, residual: str = "range",
                     range_sigma_m: float | None = None, board_error: BoardErrorScale | None = None) -> np.ndarray:
    """The range model's covariance at ``T`` (``refine.uncertainty.refinement_covariance``; board poses taken as
    exact), holding the per-board systematic error ``board_error`` where given (the beams' noise then the scan
    lines' unless ``range_sigma_m``); a SolveFailure with the reason when it cannot be computed."""
    if board_error is not None and board_error.active:
        range_sigma_m = range_sigma(obs, range_sigma_m)
    try:
        return refinement_covariance(obs.scan_data, T, residual, range_sigma_m, board_error=board_error)
    except UncertaintyError as err:
        raise SolveFailure(f"{who}: {err}", candidates) from None


def widened_range_covariance(obs: Observations, T: np.ndarray, cov: np.ndarray, range_sigma_m: float | None,
                             names=None, board_error: BoardErrorScale | None = None,
                             spread_held: bool = False) -> tuple[np.ndarray, dict | None, list[str]]:
    """The range model's covariance ``cov`` at ``T`` through the boards' dispersion test (``refine.dispersion``,
    ranges in units of the scan lines' scatter): (covariance, the test as the result reports it, and the warning
    where it was widened); ``board_error``: the per-board systematic error the model holds, ``spread_held``: its
    scale estimated from these boards (reported, not widened). Three boards or fewer leave nothing to test: ``cov``,
    None and no warning."""
    if obs.n_boards <= 3:
        return cov, None, []
    try:
        cov, disp = widened_covariance(cov, *range_board_scores(obs, T, range_sigma(obs, range_sigma_m)),
                                       held=spread_held)
    except np.linalg.LinAlgError:
        return cov, None, []
    return cov, disp.to_dict(names), [disp.warning(names)] if disp.widened else []


def fixed_calibration(obs: Observations, fixed: dict, full_start: Callable[[], np.ndarray],
                      choose: ChooseOptions, *, residual: str = "range",
                      range_sigma_m: float | None = None, fixed_sigma: np.ndarray | None = None,
                      board_error: BoardErrorScale | None = None) -> tuple[np.ndarray, np.ndarray, InfoParts]:
    """Calibrate the free mounting parameters with ``fixed`` ones held (``refine.partial``): from the closed-form
    planar start when roll, pitch and z are given, else from ``full_start()`` (a full calibration's answer);
    refined on ``residual`` with ``choose``'s loss, robust scale (``ChooseOptions.scale_m`` of the range noise,
    metres) and evaluation limit; ``fixed_sigma`` (6,): the given values' 1-sigma (radians, metres) where they are
    uncertain; ``board_error``: the per-board systematic error the covariance holds
    (``refine.partial.refine_free``). Returns (T_lidar_cam, starts, the info's parts: the refinement's report,
    covariance included, and the board set's warnings)."""
    mask, values = parse_fixed(fixed)
    sigma = range_sigma(obs, range_sigma_m)
    starts = fixed_starts(obs, mask, values, full_start)
    T, info = refine_free(obs, mask, values, starts, residual=residual, loss=choose.loss,
                          f_scale_m=choose.scale_m(sigma), range_sigma_m=range_sigma_m, max_nfev=choose.max_nfev,
                          fixed_sigma=fixed_sigma, board_error=board_error)
    report = dict(info, sigma_m_selection=sigma, refine_residual=residual, refine_loss=str(choose.loss))
    return T, np.asarray(starts), InfoParts(refinement=report, warnings=board_set_warnings(obs))


def with_prior(T: np.ndarray, cov: np.ndarray, prior: MountingPrior) -> np.ndarray:
    """The posterior covariance of the answer ``T`` (the posterior's mode) whose data alone give ``cov`` (6x6 in
    ``(w, dt)``, ``data.residuals``' left perturbation): the mounting ``prior``'s information ``J^T J`` added
    (``J = prior.jacobian(T)``)."""
    J = prior.jacobian(T)
    post = np.linalg.inv(np.linalg.inv(cov) + J.T @ J)
    return 0.5 * (post + post.T)


PRIOR_CONTRADICTS = "the mounting prior contradicts the boards"
"""How a warning of ``prior_contradiction`` begins (``calibrate`` names it as the likely cause of a refusal)."""
PRIOR_ALPHA = 1e-3
"""False-alarm rate of the test of a mounting prior against the boards (``prior_contradiction``)."""


def prior_contradiction(T: np.ndarray, cov: np.ndarray, prior: MountingPrior) -> str | None:
    """A warning when the mounting ``prior`` and the boards disagree beyond both their uncertainties, else None.

    At the posterior's mode ``T``, with ``cov`` the data's covariance alone, the prior's normalised residual ``r``
    and its Jacobian ``J`` (``MountingPrior.jacobian``) give, to first order, the prior's residual at the answer
    of the data alone: ``nu = S r`` with ``S = I + J cov J^T``; when prior and boards agree,
    ``nu^T S^-1 nu = r^T S r`` is chi-square with 6 degrees of freedom. The warning names how far the boards alone
    put the camera from the prior's pose (degrees, millimetres)."""
    r, J = prior.residuals(T), prior.jacobian(T)
    S = np.eye(6) + J @ cov @ J.T
    stat = float(r @ S @ r)
    p = float(chi2.sf(stat, 6))
    if not (np.isfinite(stat) and p < PRIOR_ALPHA):
        return None
    nu = S @ r
    rot_deg, trans_mm = np.degrees(np.linalg.norm(nu[:3]) * prior.sigma_rot_rad), \
        1000 * np.linalg.norm(nu[3:]) * prior.sigma_trans_m
    return (f"{PRIOR_CONTRADICTS} (chi-square {stat:.1f} on 6 degrees of freedom, p = "
            f"{p:.1e}): the boards alone put the camera about {rot_deg:.2f} deg and {trans_mm:.0f} mm from the "
            f"prior's pose, beyond the prior's 1-sigma ({np.degrees(prior.sigma_rot_rad):.2f} deg, "
            f"{1000 * prior.sigma_trans_m:.0f} mm) and the boards' own; the answer is pulled toward the prior: "
            "check its values or widen its sigmas")


def prior_fixed(prior: MountingPrior, deg: Degeneracy) -> tuple[dict, np.ndarray]:
    """The mounting ``prior``'s values of the axes the boards leave free (``deg.axes``; ``fixed`` keys, degrees
    and metres) and their 1-sigma (6,) in ``geometry.mounting.PARAMS`` order (radians, metres): the prior's
    rotation sigma for the angles (its rotation error is isotropic), its translation sigma for x, y, z."""
    units = with_units(params_from_T(prior.T_lidar_cam))
    fixed = {fixed_key(a): units[fixed_key(a)] for a in deg.axes}
    return fixed, np.r_[[prior.sigma_rot_rad] * 3, [prior.sigma_trans_m] * 3]


def prior_info(prior: MountingPrior) -> dict:
    """The mounting prior as the result reports it: its pose (``with_units``) and sigmas (degrees, metres)."""
    return {"mounting": with_units(params_from_T(prior.T_lidar_cam)),
            "sigma_rot_deg": float(np.degrees(prior.sigma_rot_rad)), "sigma_trans_m": prior.sigma_trans_m}
