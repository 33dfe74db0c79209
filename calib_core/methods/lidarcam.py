"""Our method, ``lidarcam``, an orchestration: point trimming and the consensus search over boards
(``calib_core.robust.search``), an all-evidence likelihood to choose among the consensus hypotheses, maximum-likelihood
refinement of the best few, the final per-board and per-point tests, the directions a degenerate board set does
not determine, covariance and warnings; and calibration of the rest with some mounting parameters fixed."""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ..checks.degeneracy import (
    MAX_SCALED_SIGMA,
    NULL_CONDITIONING,
    board_set_warnings,
    degeneracy_warnings,
    explain_failure,
    undetermined_directions,
)
from ..data.observations import Observations, ScanData
from ..data.residuals import perturb
from ..data.result import SolveFailure
from ..geometry.mounting import parse_fixed
from ..geometry.transforms import matrix_to_rotvec
from ..refine.joint import RANGE_ONLY_MODEL, JointError, joint_step
from ..refine.partial import calibrate_fixed, fixed_starts
from ..refine.refine import refine
from ..refine.uncertainty import UncertaintyError, conditioning, refinement_covariance, scan_noise_estimate
from ..registry import Method
from ..robust.scorers import EDGE_SIGMA_M, OUTLINE_SIGMA_M, lidarcam_residuals
from ..robust.scorers import lidarcam as lidarcam_score
from ..robust.search import consensus_search, finish_search
from .suffixes import F_SCALE_SIGMAS


def _distinct(T: np.ndarray, chosen: list[np.ndarray], rot_deg: float, trans_m: float) -> bool:
    for C in chosen:
        dr = np.degrees(np.linalg.norm(matrix_to_rotvec(T[:3, :3] @ C[:3, :3].T)))
        if dr < rot_deg and np.linalg.norm(T[:3, 3] - C[:3, 3]) < trans_m:
            return False
    return True


def best_distinct(C: np.ndarray, score: np.ndarray, n: int, rot_deg: float, trans_m: float) -> list[np.ndarray]:
    """The ``n`` best-scoring candidates that differ pairwise by ``rot_deg`` or ``trans_m`` (finite scores only)."""
    starts: list[np.ndarray] = []
    for j in np.argsort(score, kind="stable"):
        if not np.isfinite(score[j]) or len(starts) >= n:
            break
        if _distinct(C[j], starts, rot_deg, trans_m):
            starts.append(C[j])
    return starts


def forward_difference_step(x: np.ndarray, rel_step: float) -> np.ndarray:
    """The forward-difference steps ``scipy.optimize.least_squares`` takes for ``diff_step=rel_step``: ``rel_step
    |x|`` signed as ``x`` (``+`` at 0), and ``sqrt(eps) max(1, |x|)`` where that step vanishes."""
    sign = np.where(x >= 0, 1.0, -1.0)
    h = rel_step * sign * np.abs(x)
    return np.where((x + h) - x == 0, np.sqrt(np.finfo(float).eps) * sign * np.maximum(1.0, np.abs(x)), h)


POLISH_DIFF_STEP = 1e-7
"""Relative finite-difference step of ``polish`` (parameters in radians and metres)."""


def polish(obs: Observations, T0: np.ndarray, max_nfev: int, **score_options) -> np.ndarray:
    """Minimise the whole ``lidarcam`` selection cost from ``T0``; its Jacobian by forward differences with the
    steps of ``forward_difference_step``, the six perturbed extrinsics evaluated as one batch."""
    last: dict = {}

    def fun(x):
        last["x"], last["f"] = x.copy(), lidarcam_residuals(obs, perturb(T0, x), **score_options)
        return last["f"]

    def jac(x):
        f0 = last["f"] if np.array_equal(last.get("x"), x) else fun(x)
        h = forward_difference_step(x, POLISH_DIFF_STEP)
        X = x + np.diag(h)
        F = lidarcam_residuals(obs, np.array([perturb(T0, xi) for xi in X]), **score_options)
        return ((F - f0) / (np.diag(X) - x)[:, None]).T

    sol = least_squares(fun, np.zeros(6), jac=jac, method="trf", max_nfev=max_nfev)
    return perturb(T0, sol.x)


def refine_start(obs: Observations, data: ScanData, T0: np.ndarray, sopts: dict, *, loss: str, f_scale: float,
                 max_nfev: int, do_polish: bool, polish_threshold: float):
    """Refine one start on the range likelihood (and polish on all evidence when the outlines disagree);
    returns (score, RefineResult, T, polished)."""
    r = refine(data, T0, residual="range", loss=loss, f_scale=f_scale, max_nfev=max_nfev)
    T1 = r.T_lidar_cam
    final, parts = lidarcam_score(obs, T1[None], **sopts, return_details=True)
    final = float(final[0])
    if do_polish and parts["edge"][0] + parts["outline"][0] > polish_threshold:
        # the range optimum disagrees with the board outlines: minimise the whole evidence from there
        score_opts = {k: sopts[k] for k in ("range_sigma_m", "edge_sigma_m", "outline_sigma_m")}
        T2 = polish(obs, T1, max_nfev, **score_opts)
        f2 = float(lidarcam_score(obs, T2[None], **sopts)[0])
        if f2 < final:
            return f2, r, T2, True
    return final, r, T1, False


def select_and_refine(obs: Observations, C: np.ndarray, sopts: dict, *, n_refine: int, loss: str, f_scale: float,
                      max_nfev: int, do_polish: bool, polish_threshold: float, distinct_rot_deg: float,
                      distinct_trans_m: float):
    """Score candidates ``C`` with ``selection.lidarcam`` on ``obs``, refine the ``n_refine`` best distinct ones
    (``refine_start``) and return (score, RefineResult, T, polished, start T) of the best."""
    starts = best_distinct(C, lidarcam_score(obs, C, **sopts), n_refine, distinct_rot_deg, distinct_trans_m)
    if not starts:
        raise SolveFailure("lidarcam: no candidate has a finite score (every one puts a board behind the camera)", C)
    data = obs.scan_data
    tries = [(*refine_start(obs, data, T0, sopts, loss=loss, f_scale=f_scale, max_nfev=max_nfev,
                            do_polish=do_polish, polish_threshold=polish_threshold), T0) for T0 in starts]
    return min(tries, key=lambda x: x[0])


def lidarcam(obs: Observations, *, fixed: dict | None = None, range_sigma_m: float | None = None, n_refine: int = 3,
             loss: str = "linear", f_scale: float | None = None, edge_sigma_m: float = EDGE_SIGMA_M,
             outline_sigma_m: float = OUTLINE_SIGMA_M, behind_penalty: float = np.inf, use_zhang_pless: bool = True,
             distinct_rot_deg: float = 1.0, distinct_trans_m: float = 0.05, min_conditioning: float = NULL_CONDITIONING,
             max_scaled_sigma: float = MAX_SCALED_SIGMA, max_nfev: int = 100, polish: bool = True,
             polish_threshold: float = 10.0, trim_points: bool = True, reject_boards: bool = True,
             use_corners: bool = True, corner_sigma_px: float | None = None, **solver_options):
    """Our method.

    1. Point-level trimming (``trim_points``; ``calib_core.robust.inliers``): scan points off their board's robust line
       (gross outliers, mixed pixels at the ends) are left out.
    2. Consensus over boards (``reject_boards``; ``calib_core.robust.consensus``): hypotheses from the minimal solver on
       board triples (all while few, sampled adaptively beyond) and Zhang & Pless on sampled subsets, scored on
       every board by a per-board chi-square test of the noise model; local optimisation of the best few on their
       consensus sets. Boards that fail are left out (``info["boards_rejected"]``).
    3. On the consensus boards: every hypothesis computed from them is scored with ``selection.lidarcam`` (range
       residuals in units of the noise std ``range_sigma_m``, default estimated from the scan lines; endpoint and
       outline terms; boards behind the camera); the ``n_refine`` best distinct ones (differing by
       ``distinct_rot_deg`` or ``distinct_trans_m``) are refined by maximum likelihood on the range residuals
       (``loss``, ``f_scale``), polished on the whole cost when the outlines disagree (``polish``,
       ``polish_threshold``); the best is kept.
    4. A final per-board test at the refined pose (boards that fail are left out and the pose refined again) and
       a final point test (range residuals beyond ``inliers.TRIM_SIGMAS`` stds left out, refined again).
    5. Degeneracy (``calib_core.checks.degeneracy.undetermined_directions``, thresholds ``min_conditioning`` and
       ``max_scaled_sigma``): directions the board geometry leaves free (e.g. roll, pitch and height z when every
       board is vertical) are not presented as estimated: the result is ``ok=False``, its reason names them and
       how to calibrate the rest. Directions weak only for lack of data are named in ``info["warnings"]``.
    6. On the boards used: when every board carries image corners (and ``use_corners``), the joint maximum
       likelihood over corners and ranges from that answer (``calib_core.refine.joint``; noise stds ``corner_sigma_px``,
       ``range_sigma_m`` or estimated), with the extrinsic's covariance, board poses marginalised
       (``info["covariance_model"]`` "joint"); otherwise the range model's covariance ``sigma^2 (J^T J)^-1``
       ("range-only, ignores camera noise"). Fails with a reason when no candidate exists or fewer than 3
       consistent boards remain.

    ``fixed``: calibrate only the other mounting parameters (``calib_core.geometry.mounting``: the camera's pose in the
    lidar frame as roll, pitch, yaw and x, y, z), holding these at the given values, e.g.
    ``{"z_m": 0.12, "roll_deg": 0.0, "pitch_deg": 0.0}``; maximum likelihood on the range residuals from a
    closed-form start when roll, pitch and z are given (else from the full method's answer), with the covariance
    of the free parameters (``calib_core.refine.partial.calibrate_fixed``).
    """
    opts = {"range_sigma_m": range_sigma_m, "n_refine": n_refine, "loss": loss, "f_scale": f_scale,
            "edge_sigma_m": edge_sigma_m, "outline_sigma_m": outline_sigma_m, "behind_penalty": behind_penalty,
            "use_zhang_pless": use_zhang_pless, "distinct_rot_deg": distinct_rot_deg,
            "distinct_trans_m": distinct_trans_m, "max_nfev": max_nfev, "polish": polish,
            "polish_threshold": polish_threshold, "trim_points": trim_points, "reject_boards": reject_boards}
    if fixed is not None:
        mask, values = parse_fixed(fixed)
        sigma = range_sigma_m if range_sigma_m is not None else scan_noise_estimate(obs)
        starts = fixed_starts(obs, mask, values, lambda: _solve(obs, solver_options, **opts)[0])
        T, info = calibrate_fixed(obs, mask, values, starts, loss=loss,
                                  f_scale=f_scale if f_scale is not None else F_SCALE_SIGMAS * sigma,
                                  range_sigma_m=range_sigma_m, max_nfev=max_nfev)
        return T, np.asarray(starts), {**info, "sigma_m_selection": sigma, "warnings": board_set_warnings(obs)}
    try:
        T_best, C, obs_u, info = _solve(obs, solver_options, **opts)
    except SolveFailure as fail:
        raise explain_failure(obs, fail, range_sigma_m) from None
    deg = undetermined_directions(obs_u, T_best, range_sigma_m, max_scaled_sigma=max_scaled_sigma,
                                  null_conditioning=min_conditioning)
    if not deg.determined:
        raise SolveFailure(f"lidarcam: {deg.message()}", np.concatenate([T_best[None], C]),
                           {"degeneracy": deg.to_dict(), "warnings": board_set_warnings(obs_u)})
    T_best, cov, jinfo = final_step(obs_u, T_best, C, use_corners, range_sigma_m=range_sigma_m,
                                    corner_sigma_px=corner_sigma_px, loss=loss)
    warnings = info.pop("warnings") + jinfo.pop("warnings", []) + degeneracy_warnings(obs_u, T_best) + \
        ([deg.message()] if len(deg.directions) else [])
    return T_best, C, {**info, "covariance": cov, "conditioning": conditioning(obs_u, T_best), "warnings": warnings,
                       **jinfo}


def _solve(obs: Observations, solver_options: dict, *, range_sigma_m, n_refine, loss, f_scale, edge_sigma_m,
           outline_sigma_m, behind_penalty, use_zhang_pless, distinct_rot_deg, distinct_trans_m, max_nfev, polish,
           polish_threshold, trim_points, reject_boards):
    """Steps 1-4 of ``lidarcam``: (the best refined ``T_lidar_cam``, all candidates, the observations of the boards
    used, info)."""
    search = consensus_search(obs, range_sigma_m=range_sigma_m, outline_sigma_m=outline_sigma_m,
                              trim=trim_points, reject=reject_boards, use_zhang_pless=use_zhang_pless,
                              **solver_options)
    sigma = search.sigma_m
    sopts = {"range_sigma_m": sigma, "edge_sigma_m": edge_sigma_m, "outline_sigma_m": outline_sigma_m,
             "behind_penalty": behind_penalty}
    fs = f_scale if f_scale is not None else F_SCALE_SIGMAS * sigma
    ropts = {"n_refine": n_refine, "loss": loss, "f_scale": fs, "max_nfev": max_nfev, "do_polish": polish,
             "polish_threshold": polish_threshold, "distinct_rot_deg": distinct_rot_deg,
             "distinct_trans_m": distinct_trans_m}
    final, r, T_best, polished, T0 = select_and_refine(search.obs_used, search.pool, sopts, **ropts)
    fin = finish_search(search, T_best, reject=reject_boards, refit=lambda o, T: select_and_refine(
        o, T[None], sopts, **{**ropts, "n_refine": 1}))
    if fin.refit is not None:
        final, r, T_best, polished, _ = fin.refit
    start = float(lidarcam_score(search.obs_used, T0[None], **sopts)[0])
    return T_best, search.all_candidates, fin.obs_used, {
        "cost": final, "polished": polished, "score_start": start, "n_refined": n_refine, "sigma_m_selection": sigma,
        "refine_cost": r.cost, "refine_nfev": r.nfev, "warnings": list(fin.warnings), **fin.info}


def final_step(obs: Observations, T: np.ndarray, C: np.ndarray, use_corners: bool, *, range_sigma_m, corner_sigma_px,
               loss: str) -> tuple[np.ndarray, np.ndarray, dict]:
    """The answer and its covariance: the joint ML over corners and ranges (``refine.joint``) when every board
    carries image corners, else the range model's covariance at ``T`` (it ignores the camera's noise)."""
    why = None
    if use_corners and obs.has_corners:
        try:
            return joint_step(obs, T, corner_sigma_px=corner_sigma_px, range_sigma_m=range_sigma_m, loss=loss)
        except (JointError, UncertaintyError) as err:
            why = f"joint refinement failed ({err}); covariance of the range model only"
    try:
        cov = refinement_covariance(obs.scan_data, T, "range", range_sigma_m)
    except UncertaintyError as err:
        raise SolveFailure(f"lidarcam: {err}", C) from None
    return T, cov, {"covariance_model": RANGE_ONLY_MODEL, **({"warnings": [why]} if why else {})}


LIDARCAM = Method("lidarcam", lidarcam, 3, "this project (lidarcam)",
                  "point trimming; consensus over boards (minimal-solver triples + Zhang & Pless subsets, "
                  "per-board chi-square tests; inconsistent boards rejected and named); all-evidence likelihood "
                  "selection; ML refinement of the best few; covariance and degeneracy warnings",
                  cost="about linear in N: all C(N,3) triples up to 12 boards, then an "
                  "adaptively sampled, bounded set; per-board tests O(hypotheses x N)")
