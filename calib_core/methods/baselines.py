"""The seed methods as their papers describe them: Zhang & Pless (linear and refined), Vasconcelos (minimal
solver, point-to-plane selection) and Peng et al. 2022 (the same candidates, uncertainty-weighted selection)."""

from __future__ import annotations

import numpy as np

from ..data.observations import Observations
from ..data.outcome import InfoParts
from ..errors import SolveFailure
from ..refine.refine import refine
from ..registry import Method
from ..robust.scorers import PENG2022_OPTIONS, SCORERS, peng2022_outline_warnings
from ..solvers._common import MIN_BOARDS
from ..solvers.candidates import minimal_candidates, solver_keywords
from ..solvers.zhang_pless import MIN_BOARDS as ZP_MIN_BOARDS
from ..solvers.zhang_pless import zhang_pless_linear as _zp_linear

ZHANG_CITE = "Zhang & Pless, IROS 2004"
VASC_CITE = "Vasconcelos, Barreto & Nunes, IEEE TPAMI 34(11) 2012"
PENG_CITE = "Peng, Wu, Li & Wang, J. Hunan Univ. Sci. Tech. 37(4) 2022"
EXHAUSTIVE = "O(N^4): every candidate of all C(N,3) triples scored on all N boards"


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


def zhang_pless_linear(obs: Observations, *, weighting: str = "paper"):
    T = _zp_linear(obs, weighting=weighting)
    return T, T[None], {}


def zhang_pless(obs: Observations, *, weighting: str = "paper", residual: str = "plane", loss: str = "linear"):
    T0 = _zp_linear(obs, weighting=weighting)
    r = refine(obs.scan_data, T0, residual=residual, loss=loss)
    return r.T_lidar_cam, T0[None], {"cost": r.cost, "initial_cost": r.initial_cost, "nfev": r.nfev}


def vasconcelos(obs: Observations, **solver_options):
    cands = minimal_candidates(obs, **solver_options)
    T, info = select_candidate(obs, cands, "point_to_plane")
    return T, cands.T_lidar_cam, info


def peng2022(obs: Observations, **options):
    """Options: the ``selection.peng2022`` readings (``PENG2022_OPTIONS``, defaults there); the rest go to the
    minimal solver."""
    sel = {k: options.pop(k) for k in PENG2022_OPTIONS if k in options}
    warnings = peng2022_outline_warnings(obs) if sel.get("error", "point_line") == "point_line" else []
    cands = minimal_candidates(obs, **options)
    T, info = select_candidate(obs, cands, "peng2022", **sel)
    return T, cands.T_lidar_cam, InfoParts(base=info, warnings=warnings or None).to_info()


BASELINES = (
    Method("zhang_pless_linear", zhang_pless_linear, ZP_MIN_BOARDS, ZHANG_CITE,
           "linear solution of N_i^T H q = |N_i|^2, Phi projected onto SO(3); no refinement", cost="O(N)",
           paper=True),
    Method("zhang_pless", zhang_pless, ZP_MIN_BOARDS, ZHANG_CITE,
           "the linear solution refined on point-to-plane distances (least squares, analytic Jacobian)",
           cost="O(N)", paper=True),
    Method("vasconcelos", vasconcelos, MIN_BOARDS, VASC_CITE,
           "minimal P3P solver on all board triples; least point-to-plane error of all scan points", cost=EXHAUSTIVE,
           paper=True, options=solver_keywords("vasconcelos")),
    Method("peng2022", peng2022, MIN_BOARDS, PENG_CITE,
           "Vasconcelos candidates; uncertainty-weighted joint likelihood of the point-line error", cost=EXHAUSTIVE,
           paper=True, options=solver_keywords("vasconcelos") | set(PENG2022_OPTIONS)),
)
