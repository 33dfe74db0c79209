"""The calibration methods (registered in ``calib_core.registry``) and the one entry, ``calibrate``."""

from __future__ import annotations

import time

import numpy as np

from .candidates import minimal_candidates
from .errors import CalibrationError
from .observations import Observations
from .refine import refine
from .registry import get_method, register
from .residuals import ScanData
from .result import CalibrationResult, SolveFailure
from .selection import SCORERS
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


def calibrate(observations: Observations, method: str = "peng2022", **options) -> CalibrationResult:
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
    return CalibrationResult(method, True, np.asarray(T, float), None, np.asarray(cands, float),
                             time.perf_counter() - t0, info=info)
