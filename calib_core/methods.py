"""The calibration methods (registered in ``calib_core.registry``) and the one entry, ``calibrate``."""

from __future__ import annotations

import time

import numpy as np

from .candidates import minimal_candidates
from .errors import CalibrationError
from .lines import fit_line
from .observations import Observations
from .refine import refine
from .registry import SUFFIXES, Method, get_method, register
from .residuals import ScanData
from .result import CalibrationResult, SolveFailure
from .selection import SCORERS
from .transforms import matrix_to_rotvec
from .uncertainty import UncertaintyError, conditioning, degeneracy_warnings, refinement_covariance, scan_noise_estimate
from .zhang_pless import MIN_BOARDS as ZP_MIN_BOARDS
from .zhang_pless import zhang_pless_linear as _zp_linear

ZHANG_CITE = "Zhang & Pless, IROS 2004"
VASC_CITE = "Vasconcelos, Barreto & Nunes, IEEE TPAMI 34(11) 2012"
PENG_CITE = "Peng, Wu, Li & Wang, J. Hunan Univ. Sci. Tech. 37(4) 2022"


def select_candidate(obs: Observations, cands, scorer: str, **scorer_options):
    """Pick the candidate of least cost under ``scorer``; returns (T, info)."""
    if len(cands.T_lidar_cam) == 0:
        raise SolveFailure(cands.summary())
    cost = SCORERS[scorer](obs, cands.T_lidar_cam, **scorer_options)
    j = int(np.argmin(cost))
    if not np.isfinite(cost[j]):
        raise SolveFailure(f"{scorer}: no candidate has a finite score", cands.T_lidar_cam)
    return cands.T_lidar_cam[j], {"chosen": j, "cost": float(cost[j]), "scorer": scorer,
                                  "n_triples": len(cands.triples),
                                  "n_degenerate_triples": int(sum(r is not None for r in cands.reasons))}


@register("zhang_pless_linear", min_boards=ZP_MIN_BOARDS, citation=ZHANG_CITE,
          summary="linear solution of N_i^T H q = |N_i|^2, Phi projected onto SO(3); no refinement")
def zhang_pless_linear(obs: Observations, *, weighting: str = "paper"):
    T = _zp_linear(obs, weighting=weighting)
    return T, T[None], {}


@register("zhang_pless", min_boards=ZP_MIN_BOARDS, citation=ZHANG_CITE,
          summary="the linear solution refined on point-to-plane distances (least squares, analytic Jacobian)")
def zhang_pless(obs: Observations, *, weighting: str = "paper", residual: str = "plane", loss: str = "linear"):
    T0 = _zp_linear(obs, weighting=weighting)
    r = refine(ScanData.from_observations(obs), T0, residual=residual, loss=loss)
    return r.T_lidar_cam, T0[None], {"cost": r.cost, "initial_cost": r.initial_cost, "nfev": r.nfev}


@register("vasconcelos", min_boards=3, citation=VASC_CITE,
          summary="minimal P3P solver on all board triples; least point-to-plane error of all scan points")
def vasconcelos(obs: Observations, **solver_options):
    cands = minimal_candidates(obs, **solver_options)
    T, info = select_candidate(obs, cands, "point_to_plane")
    return T, cands.T_lidar_cam, info


@register("peng2022", min_boards=3, citation=PENG_CITE,
          summary="Vasconcelos candidates; uncertainty-weighted joint likelihood of the point-line error")
def peng2022(obs: Observations, *, delta_m: float = 0.030, normalise_candidates: bool = True,
             beta_norm: str = "sum", beta_eps: float = 1e-12, error: str = "point_line",
             weighting: str = "uncertainty", **solver_options):
    cands = minimal_candidates(obs, **solver_options)
    T, info = select_candidate(obs, cands, "peng2022", delta_m=delta_m, normalise_candidates=normalise_candidates,
                               beta_norm=beta_norm, beta_eps=beta_eps, error=error, weighting=weighting)
    return T, cands.T_lidar_cam, info


REFINE_OPTIONS = ("loss", "f_scale", "sigma_m", "max_nfev")
"""Options of an ``X+ml`` / ``X+plane`` method that go to the refinement; all others go to ``X``."""


def _refine_and_cover(obs: Observations, T0: np.ndarray, residual: str, *, loss: str = "linear",
                      f_scale: float | None = None, sigma_m: float | None = None, max_nfev: int = 100,
                      f_scale_sigmas: float = 2.5):
    """Refine ``T0`` on ``residual`` and compute the covariance; returns (RefineResult, covariance, info)."""
    data = ScanData.from_observations(obs)
    if f_scale is None:
        f_scale = f_scale_sigmas * (sigma_m if sigma_m is not None else scan_noise_estimate(obs))
    r = refine(data, T0, residual=residual, loss=loss, f_scale=f_scale, max_nfev=max_nfev)
    try:
        cov = refinement_covariance(data, r.T_lidar_cam, residual, sigma_m)
    except UncertaintyError as err:
        raise SolveFailure(f"refinement: {err}", T0[None]) from None
    info = {"refine_cost": r.cost, "refine_initial_cost": r.initial_cost, "refine_nfev": r.nfev,
            "refine_residual": residual, "refine_loss": loss, "covariance": cov,
            "conditioning": conditioning(obs, r.T_lidar_cam)}
    return r, cov, info


def refined_method(base: Method, residual: str, suffix: str) -> Method:
    """The method ``base.name + "+" + suffix``: run ``base``, then refine its answer on ``residual``
    (``"range"``: maximum likelihood under range noise; ``"plane"``: point-to-plane distances), with the
    covariance of the refined extrinsic. Options ``loss``, ``f_scale`` (default 2.5 x the noise std),
    ``sigma_m`` (default: estimated) and ``max_nfev`` go to the refinement, the rest to ``base``."""
    def func(obs: Observations, **options):
        ropts = {k: options.pop(k) for k in REFINE_OPTIONS if k in options}
        T0, cands, info = base.func(obs, **options)
        r, _, rinfo = _refine_and_cover(obs, np.asarray(T0, float), residual, **ropts)
        return r.T_lidar_cam, cands, {**info, **rinfo, "base_T_lidar_cam": np.asarray(T0, float)}

    what = "maximum-likelihood refinement on the range residuals" if residual == "range" else \
        "refinement on the point-to-plane distances"
    return Method(f"{base.name}+{suffix}", func, base.min_boards, base.citation,
                  f"{base.name}, then {what}, with covariance")


SUFFIXES["ml"] = lambda base: refined_method(base, "range", "ml")
SUFFIXES["plane"] = lambda base: refined_method(base, "plane", "plane")
for _base in ("zhang_pless_linear", "vasconcelos", "peng2022"):
    for _suffix in SUFFIXES:
        get_method(f"{_base}+{_suffix}")


def _polish(obs: Observations, T0: np.ndarray, sigma: float, edge_sigma: float, outline_sigma: float,
            max_nfev: int) -> np.ndarray:
    """Minimise the ``lidarcam`` selection cost (all evidence) from ``T0``; finite-difference Jacobian."""
    from scipy.optimize import least_squares

    from .residuals import perturb
    from .selection import lidarcam_residuals

    def fun(x):
        return lidarcam_residuals(obs, perturb(T0, x), sigma_m=sigma, edge_sigma_m=edge_sigma,
                                  outline_sigma_m=outline_sigma)

    sol = least_squares(fun, np.zeros(6), method="trf", diff_step=1e-7, max_nfev=max_nfev)
    return perturb(T0, sol.x)


def _distinct(T: np.ndarray, chosen: list[np.ndarray], rot_deg: float, trans_m: float) -> bool:
    for C in chosen:
        dr = np.degrees(np.linalg.norm(matrix_to_rotvec(T[:3, :3] @ C[:3, :3].T)))
        if dr < rot_deg and np.linalg.norm(T[:3, 3] - C[:3, 3]) < trans_m:
            return False
    return True


@register("lidarcam", min_boards=3, citation="this project (lidarcam)",
          summary="minimal-solver (+ Zhang & Pless) candidates; all-evidence likelihood selection; ML refinement "
                  "of the best few; covariance and degeneracy warnings")
def lidarcam(obs: Observations, *, sigma_m: float | None = None, n_refine: int = 3, loss: str = "linear",
             f_scale: float | None = None, edge_sigma_m: float = 0.03, outline_sigma_m: float = 0.03,
             behind_penalty: float = np.inf, use_zhang_pless: bool = True, distinct_rot_deg: float = 1.0,
             distinct_trans_m: float = 0.05, min_conditioning: float = 1e-6, warn_min_boards: int = 4,
             warn_min_normal_spread_deg: float = 5.0, warn_min_conditioning: float = 1e-3, max_nfev: int = 100,
             polish: bool = True, polish_threshold: float = 10.0, **solver_options):
    """Our method.

    1. Candidates: the minimal solver on all board triples (``solver_options`` go to it), plus the linear
       Zhang & Pless solution when there are >= 5 boards (``use_zhang_pless``).
    2. Score every candidate with ``selection.lidarcam`` (range residuals in units of the noise std
       ``sigma_m``, default estimated from the scan lines; endpoint and outline terms; boards behind the camera).
    3. Refine the ``n_refine`` best distinct candidates (differing by ``distinct_rot_deg`` or
       ``distinct_trans_m``) by maximum likelihood on the range residuals (``loss``, ``f_scale``); keep the one
       whose refined pose scores least. With ``polish``, a refined pose whose endpoint and outline terms exceed
       ``polish_threshold`` (the range optimum puts scan points off the boards) is refined further on the whole
       ``selection.lidarcam`` cost (numerical Jacobian) and kept when that scores less.
    4. Covariance ``sigma^2 (J^T J)^-1`` (``sigma_m`` or estimated from the final residuals), conditioning and
       ``info["warnings"]``; after a polish the covariance is still that of the range model at the answer
       (it ignores the outline information: conservative). Fails with a reason when no candidate
       exists, none scores finite, or the refined pose's conditioning is below ``min_conditioning``.
    """
    reasons, pools = [], []
    # boards whose scan is not line-like take no part in the minimal solver, but count in the score and refinement
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
            pools.append(_zp_linear(obs)[None])
        except SolveFailure as fail:
            reasons.append(f"zhang_pless_linear: {fail.reason}")
    C = np.concatenate(pools) if pools else np.zeros((0, 4, 4))
    if len(C) == 0:
        raise SolveFailure("no candidate: " + "; ".join(reasons))
    sigma = sigma_m if sigma_m is not None else scan_noise_estimate(obs)
    sopts = {"sigma_m": sigma, "edge_sigma_m": edge_sigma_m, "outline_sigma_m": outline_sigma_m,
             "behind_penalty": behind_penalty}
    score = SCORERS["lidarcam"](obs, C, **sopts)
    starts: list[np.ndarray] = []
    for j in np.argsort(score, kind="stable"):
        if not np.isfinite(score[j]) or len(starts) >= n_refine:
            break
        if _distinct(C[j], starts, distinct_rot_deg, distinct_trans_m):
            starts.append(C[j])
    if not starts:
        raise SolveFailure("lidarcam: no candidate has a finite score (every one puts a board behind the camera)", C)
    best = None
    data = ScanData.from_observations(obs)
    for T0 in starts:
        r = refine(data, T0, residual="range", loss=loss, f_scale=f_scale if f_scale is not None else 2.5 * sigma,
                   max_nfev=max_nfev)
        T1 = r.T_lidar_cam
        final, parts = SCORERS["lidarcam"](obs, T1[None], **sopts, return_details=True)
        final = float(final[0])
        polished = False
        if polish and parts["edge"][0] + parts["outline"][0] > polish_threshold:
            # the range optimum disagrees with the board outlines: minimise the whole evidence from there
            T2 = _polish(obs, T1, sigma, edge_sigma_m, outline_sigma_m, max_nfev)
            f2 = float(SCORERS["lidarcam"](obs, T2[None], **sopts)[0])
            if f2 < final:
                T1, final, polished = T2, f2, True
        if best is None or final < best[0]:
            best = (final, r, T0, T1, polished)
    final, r, T0, T_best, polished = best
    cond = conditioning(obs, T_best)
    if not cond >= min_conditioning:
        raise SolveFailure(f"lidarcam: degenerate board set, the extrinsic is not determined (inverse condition "
                           f"number {cond:.1e} < {min_conditioning:g})", C)
    try:
        cov = refinement_covariance(data, T_best, "range", sigma_m)
    except UncertaintyError as err:
        raise SolveFailure(f"lidarcam: {err}", C) from None
    warnings = degeneracy_warnings(obs, T_best, min_boards=warn_min_boards,
                                   min_normal_spread_deg=warn_min_normal_spread_deg,
                                   min_conditioning=warn_min_conditioning)
    start = float(SCORERS["lidarcam"](obs, T0[None], **sopts)[0])
    return T_best, C, {"cost": final, "polished": polished, "score_start": start,
                              "n_refined": len(starts), "sigma_m_selection": sigma, "refine_cost": r.cost,
                              "refine_nfev": r.nfev, "covariance": cov, "conditioning": cond,
                              "warnings": warnings}


def calibrate(observations: Observations, method: str = "lidarcam", **options) -> CalibrationResult:
    """Calibrate ``T_lidar_cam`` from ``observations`` with the registered ``method``.

    Returns a ``CalibrationResult``; a method that cannot solve (too few boards, degenerate data) gives
    ``ok=False`` and a reason, never a guess. Unknown methods or options raise ``CalibrationError``.
    """
    m = get_method(method)
    t0 = time.perf_counter()
    if observations.n_boards < m.min_boards:
        return CalibrationResult(method, False, reason=f"{method} needs at least {m.min_boards} boards, "
                                 f"got {observations.n_boards}", seconds=time.perf_counter() - t0)
    try:
        T, cands, info = m.func(observations, **options)
    except SolveFailure as fail:
        return CalibrationResult(method, False, reason=fail.reason, candidates=fail.candidates,
                                 seconds=time.perf_counter() - t0)
    except TypeError as exc:
        if "unexpected keyword" in str(exc):
            raise CalibrationError(f"{method}: {exc}") from None
        raise
    cov = info.pop("covariance", None)
    return CalibrationResult(method, True, np.asarray(T, float), None, np.asarray(cands, float),
                             time.perf_counter() - t0, None if cov is None else np.asarray(cov, float), info=info)


from .ablations import register_ablations  # noqa: E402

register_ablations()
