"""Our method, ``lidarcam``, an orchestration: point trimming and the consensus search over boards
(``calib_core.search``), an all-evidence likelihood to choose among the consensus hypotheses, maximum-likelihood
refinement of the best few, the final per-board and per-point tests, covariance and warnings."""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ..joint import RANGE_ONLY_MODEL, JointError, joint_step
from ..observations import Observations, ScanData
from ..refine import refine
from ..registry import Method
from ..residuals import perturb
from ..result import SolveFailure
from ..search import consensus_search, finish_search
from ..selection import EDGE_SIGMA_M, OUTLINE_SIGMA_M, lidarcam_residuals
from ..selection import lidarcam as lidarcam_score
from ..transforms import matrix_to_rotvec
from ..uncertainty import (
    UncertaintyError,
    conditioning,
    degeneracy_warnings,
    refinement_covariance,
)
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


def polish(obs: Observations, T0: np.ndarray, max_nfev: int, **score_options) -> np.ndarray:
    """Minimise the whole ``lidarcam`` selection cost from ``T0`` (finite-difference Jacobian)."""
    def fun(x):
        return lidarcam_residuals(obs, perturb(T0, x), **score_options)

    sol = least_squares(fun, np.zeros(6), method="trf", diff_step=1e-7, max_nfev=max_nfev)
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


def lidarcam(obs: Observations, *, range_sigma_m: float | None = None, n_refine: int = 3, loss: str = "linear",
             f_scale: float | None = None, edge_sigma_m: float = EDGE_SIGMA_M, outline_sigma_m: float = OUTLINE_SIGMA_M,
             behind_penalty: float = np.inf, use_zhang_pless: bool = True, distinct_rot_deg: float = 1.0,
             distinct_trans_m: float = 0.05, min_conditioning: float = 1e-6, warn_min_boards: int = 4,
             warn_min_normal_spread_deg: float = 5.0, warn_min_conditioning: float = 1e-3, max_nfev: int = 100,
             polish: bool = True, polish_threshold: float = 10.0, trim_points: bool = True,
             reject_boards: bool = True, use_corners: bool = True, corner_sigma_px: float | None = None,
             **solver_options):
    """Our method.

    1. Point-level trimming (``trim_points``; ``calib_core.inliers``): scan points off their board's robust line
       (gross outliers, mixed pixels at the ends) are left out.
    2. Consensus over boards (``reject_boards``; ``calib_core.consensus``): hypotheses from the minimal solver on
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
    5. On the boards used: when every board carries image corners (and ``use_corners``), the joint maximum
       likelihood over corners and ranges from that answer (``calib_core.joint``; noise stds ``corner_sigma_px``,
       ``range_sigma_m`` or estimated), with the extrinsic's covariance, board poses marginalised
       (``info["covariance_model"]`` "joint"); otherwise the range model's covariance ``sigma^2 (J^T J)^-1``
       ("range-only, ignores camera noise"). Conditioning and ``info["warnings"]``. Fails with a reason when no
       candidate exists, fewer than 3 consistent boards remain, or the conditioning of the refined pose is below
       ``min_conditioning``.
    """
    sigma_opt = range_sigma_m
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
    obs_u, C = fin.obs_used, search.all_candidates
    cond = conditioning(obs_u, T_best)
    if not cond >= min_conditioning:
        raise SolveFailure(f"lidarcam: degenerate board set, the extrinsic is not determined (inverse condition "
                           f"number {cond:.1e} < {min_conditioning:g})", C)
    T_best, cov, jinfo = final_step(obs_u, T_best, C, use_corners, range_sigma_m=sigma_opt,
                                    corner_sigma_px=corner_sigma_px, loss=loss)
    warnings = fin.warnings + jinfo.pop("warnings", []) + degeneracy_warnings(
        obs_u, T_best, min_boards=warn_min_boards, min_normal_spread_deg=warn_min_normal_spread_deg,
        min_conditioning=warn_min_conditioning)
    start = float(lidarcam_score(search.obs_used, T0[None], **sopts)[0])
    return T_best, C, {"cost": final, "polished": polished, "score_start": start, "n_refined": n_refine,
                       "sigma_m_selection": sigma, "refine_cost": r.cost, "refine_nfev": r.nfev, "covariance": cov,
                       "conditioning": cond, "warnings": warnings, **fin.info, **jinfo}


def final_step(obs: Observations, T: np.ndarray, C: np.ndarray, use_corners: bool, *, range_sigma_m, corner_sigma_px,
               loss: str) -> tuple[np.ndarray, np.ndarray, dict]:
    """The answer and its covariance: the joint ML over corners and ranges (``calib_core.joint``) when every board
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
