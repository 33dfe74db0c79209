"""Our method, ``lidarcam``: minimal-solver (+ Zhang & Pless) candidates, an all-evidence likelihood to choose
among them, maximum-likelihood refinement of the best few, covariance and degeneracy warnings."""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ..joint import RANGE_ONLY_MODEL, JointError, joint_step
from ..lines import fit_line
from ..observations import Observations, ScanData
from ..refine import refine
from ..registry import Method
from ..residuals import perturb
from ..result import SolveFailure
from ..selection import EDGE_SIGMA_M, OUTLINE_SIGMA_M, lidarcam_residuals
from ..selection import lidarcam as lidarcam_score
from ..solvers.candidates import minimal_candidates
from ..solvers.zhang_pless import MIN_BOARDS as ZP_MIN_BOARDS
from ..solvers.zhang_pless import zhang_pless_linear
from ..transforms import matrix_to_rotvec
from ..uncertainty import (
    UncertaintyError,
    conditioning,
    degeneracy_warnings,
    refinement_covariance,
    scan_noise_estimate,
)
from .suffixes import F_SCALE_SIGMAS


def candidate_pool(obs: Observations, use_zhang_pless: bool = True, **solver_options) -> tuple[np.ndarray, list[str]]:
    """Candidates (M,4,4): the minimal solver on all triples of the boards whose scan is line-like, plus the
    linear Zhang & Pless solution from 5 boards on; and the reasons for what was left out."""
    reasons, pools = [], []
    good = []
    for i, b in enumerate(obs.boards):
        try:
            fit_line(b.scan)
            good.append(i)
        except SolveFailure as fail:
            reasons.append(f"board {i}: {fail.reason}")
    try:
        cands = minimal_candidates(obs.subset(good), **solver_options)
        pools.append(cands.T_lidar_cam)
        if len(cands.T_lidar_cam) == 0:
            reasons.append(f"minimal solver: {cands.summary()}")
    except SolveFailure as fail:
        reasons.append(f"minimal solver: {fail.reason}")
    if use_zhang_pless and obs.n_boards >= ZP_MIN_BOARDS:
        try:
            pools.append(zhang_pless_linear(obs)[None])
        except SolveFailure as fail:
            reasons.append(f"zhang_pless_linear: {fail.reason}")
    return (np.concatenate(pools) if pools else np.zeros((0, 4, 4))), reasons


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


def lidarcam(obs: Observations, *, range_sigma_m: float | None = None, n_refine: int = 3, loss: str = "linear",
             f_scale: float | None = None, edge_sigma_m: float = EDGE_SIGMA_M, outline_sigma_m: float = OUTLINE_SIGMA_M,
             behind_penalty: float = np.inf, use_zhang_pless: bool = True, distinct_rot_deg: float = 1.0,
             distinct_trans_m: float = 0.05, min_conditioning: float = 1e-6, warn_min_boards: int = 4,
             warn_min_normal_spread_deg: float = 5.0, warn_min_conditioning: float = 1e-3, max_nfev: int = 100,
             polish: bool = True, polish_threshold: float = 10.0, use_corners: bool = True,
             corner_sigma_px: float | None = None, **solver_options):
    """Our method.

    1. Candidates (``candidate_pool``): the minimal solver on all board triples (``solver_options`` go to it),
       plus the linear Zhang & Pless solution when there are >= 5 boards (``use_zhang_pless``).
    2. Score every candidate with ``selection.lidarcam`` (range residuals in units of the noise std
       ``range_sigma_m``, default estimated from the scan lines; endpoint and outline terms; boards behind the camera).
    3. Refine the ``n_refine`` best distinct candidates (differing by ``distinct_rot_deg`` or
       ``distinct_trans_m``) by maximum likelihood on the range residuals (``loss``, ``f_scale``); keep the one
       whose refined pose scores least. With ``polish``, a refined pose whose endpoint and outline terms exceed
       ``polish_threshold`` (the range optimum puts scan points off the boards) is refined further on the whole
       ``selection.lidarcam`` cost (numerical Jacobian) and kept when that scores less.
    4. When every board carries image corners (and ``use_corners``): the joint maximum likelihood over corners and
       ranges from that answer (``calib_core.joint``; noise stds ``corner_sigma_px``, ``range_sigma_m`` or
       estimated), with the extrinsic's covariance, board poses marginalised (``info["covariance_model"]`` "joint").
       Otherwise the range model's covariance ``sigma^2 (J^T J)^-1`` (``range_sigma_m`` or estimated from the final
       residuals; "range-only, ignores camera noise"); after a polish it is still that of the range model at the
       answer (it ignores the outline information: conservative). Conditioning and ``info["warnings"]``.
       Fails with a reason when no candidate exists, none scores finite, or the refined pose's conditioning is
       below ``min_conditioning``.
    """
    C, reasons = candidate_pool(obs, use_zhang_pless, **solver_options)
    if len(C) == 0:
        raise SolveFailure("no candidate: " + "; ".join(reasons))
    sigma = range_sigma_m if range_sigma_m is not None else scan_noise_estimate(obs)
    sopts = {"range_sigma_m": sigma, "edge_sigma_m": edge_sigma_m, "outline_sigma_m": outline_sigma_m,
             "behind_penalty": behind_penalty}
    starts = best_distinct(C, lidarcam_score(obs, C, **sopts), n_refine, distinct_rot_deg, distinct_trans_m)
    if not starts:
        raise SolveFailure("lidarcam: no candidate has a finite score (every one puts a board behind the camera)", C)
    data = obs.scan_data
    fs = f_scale if f_scale is not None else F_SCALE_SIGMAS * sigma
    tries = [(*refine_start(obs, data, T0, sopts, loss=loss, f_scale=fs, max_nfev=max_nfev, do_polish=polish,
                            polish_threshold=polish_threshold), T0) for T0 in starts]
    final, r, T_best, polished, T0 = min(tries, key=lambda x: x[0])
    cond = conditioning(obs, T_best)
    if not cond >= min_conditioning:
        raise SolveFailure(f"lidarcam: degenerate board set, the extrinsic is not determined (inverse condition "
                           f"number {cond:.1e} < {min_conditioning:g})", C)
    T_best, cov, jinfo = final_step(obs, T_best, C, use_corners, range_sigma_m=range_sigma_m,
                                    corner_sigma_px=corner_sigma_px, loss=loss)
    warnings = jinfo.pop("warnings", []) + degeneracy_warnings(obs, T_best, min_boards=warn_min_boards,
                                                               min_normal_spread_deg=warn_min_normal_spread_deg,
                                                               min_conditioning=warn_min_conditioning)
    start = float(lidarcam_score(obs, T0[None], **sopts)[0])
    return T_best, C, {"cost": final, "polished": polished, "score_start": start, "n_refined": len(starts),
                       "sigma_m_selection": sigma, "refine_cost": r.cost, "refine_nfev": r.nfev, "covariance": cov,
                       "conditioning": cond, "warnings": warnings, **jinfo}


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
                  "minimal-solver (+ Zhang & Pless) candidates; all-evidence likelihood selection; ML refinement "
                  "of the best few; covariance and degeneracy warnings", cost="O(N^4) candidate scoring")
