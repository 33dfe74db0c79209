"""The consensus search over boards of ``lidarcam`` (hypotheses, MSAC scores, local optimisation on consensus
sets) on the trimmed observations, and the final per-board and per-point tests of the refined answer (which say
whether the method must refine again; they do not refine).

Board indices in everything reported (``boards_used``, ``boards_rejected``) are those of the caller's
observations. Lidar frame, metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..data.lines import range_sigma, scan_lines
from ..data.observations import Observations
from ..errors import SolveFailure
from ..geometry.mounting import MountingPrior
from ..model.plausible import implausible_reason
from ..refine.refine import F_SCALE_SIGMAS, Loss, RefineResult, refine
from ..solvers._common import MIN_BOARDS
from .consensus import SCORE_TAU, TEST_CHI2, board_statistics, inflation, msac_cost
from .hypotheses import Hypotheses, hypotheses
from .inliers import TrimReport
from .starts import distinct_order, gauss_newton_steps, near_any

POOL_MAX = 64
"""The final selection scores at most this many hypotheses, the best by MSAC cost (the per-board statistics are
sufficient statistics of the same evidence, so the all-evidence score's best few are among them) ..."""
POOL_MAX_SAMPLED = 8
"""... and this many when triples were sampled (many boards: the local optimisation's results are in the pool
too, and the all-evidence score costs O(pool x points))."""
LO_STARTS = 3
"""Distinct best MSAC hypotheses that get a local optimisation on their consensus sets."""
LO_STARTS_ALL = 2
"""... and distinct best hypotheses by the untruncated sum of the statistics, optimised on all boards first (so a
consensus that leaves a good board out must beat the one that keeps every board)."""
LO_ROUNDS = 4
"""At most this many refine-and-retest rounds of one local optimisation."""
LO_LOSS = Loss.LINEAR
"""The local optimisation's loss (a robust one takes ``F_SCALE_SIGMAS`` range-noise stds as its scale): plain least
squares; a board in the consensus set but off is left out by the re-test rounds (``LO_ROUNDS``). On the robustness
suite (wrong boards, outlier points, mixed pixels) it names and leaves out the same boards as ``soft_l1`` did, and
it runs by Levenberg-Marquardt in less than half the time of ``soft_l1``'s trust-region solver."""
MIN_TESTABLE = 4
"""Boards are tested and rejected only from this many on: three boards fit every minimal solution exactly."""


@dataclass(frozen=True)
class ConsensusOptions:
    """The consensus search: ``reject_boards`` (test boards and leave out those that fail), ``use_zhang_pless``
    (Zhang & Pless hypotheses beside the minimal solver's), ``solver`` (options of the minimal solver,
    ``solvers.vasconcelos.solve_triples``, as (name, value) pairs)."""

    reject_boards: bool = True
    use_zhang_pless: bool = True
    solver: tuple = ()


@dataclass(frozen=True, eq=False)
class Search:
    """Outcome of the consensus search (see the module doc); ``good`` are the caller's indices of the boards with a
    line-like scan, ``used`` (len(good),) bool the consensus among them; ``refined`` the range refinements
    (``RefineResult``) of the local optimisations that ran on exactly the boards of ``used``: extrinsics of
    ``pool`` already refined on ``obs_used``."""

    obs: Observations
    trim: TrimReport | None
    good: np.ndarray
    hyps: Hypotheses
    used: np.ndarray
    pool: np.ndarray
    sigma_m: float
    outline_sigma_m: float
    rejected: list = field(default_factory=list)
    refined: tuple = ()

    @cached_property
    def obs_good(self) -> Observations:
        return self.obs.subset(self.good)

    @cached_property
    def obs_used(self) -> Observations:
        return self.obs.subset(self.good[self.used])

    @property
    def hypotheses_T(self) -> np.ndarray:
        return self.hyps.T


def rejection(index: int, reason: str, statistic: float | None = None) -> dict:
    return {"index": int(index), "reason": reason, "statistic": None if statistic is None else float(statistic)}


@dataclass(frozen=True, eq=False)
class LocalOptimum:
    """One local optimisation (``local_optimise``): the extrinsic ``T``, its consensus set ``used`` (N,) bool, the
    per-board statistics ``q`` (N,), their ``inflation``, the MSAC ``cost`` at the final threshold plus
    ``N log(inflation)``, and ``refined``: the range refinement that gave ``T`` when it ran on exactly the boards
    of ``used`` (else None)."""

    T: np.ndarray
    used: np.ndarray
    q: np.ndarray
    inflation: float
    cost: float
    refined: RefineResult | None


def local_optimise(obs: Observations, T0: np.ndarray, q0: np.ndarray, sigma_m: float, outline_sigma_m: float,
                   start_all: bool = False, prior: MountingPrior | None = None) -> LocalOptimum:
    """Refine ``T0`` on the boards it explains (``q0 < SCORE_TAU``; every board in front of the camera with
    ``start_all``), re-test every board, repeat until the consensus set is stable. With a mounting ``prior`` each
    refinement holds it (the posterior's mode): where the boards leave directions free (every board vertical), a
    refinement without it wanders along them off the boards."""
    used, T, q = (np.isfinite(q0) if start_all else q0 < SCORE_TAU), T0, q0
    s2, r = 1.0, None
    for _ in range(LO_ROUNDS):
        if used.sum() < MIN_BOARDS:
            break
        r = refine(obs.scan_data.of_boards(used), T, residual="range", loss=LO_LOSS,
                   f_scale_m=F_SCALE_SIGMAS * sigma_m, prior=prior, prior_scale_m=sigma_m)
        T = r.T_lidar_cam
        q = board_statistics(obs, T, sigma_m, outline_sigma_m)[0]
        s2 = inflation(q[used])
        new = q <= TEST_CHI2 * s2
        if np.array_equal(new, used):
            break
        used, r = new, None
    return LocalOptimum(T, used, q, s2, float(msac_cost(q[None], TEST_CHI2 * s2)[0]) + np.log(s2) * len(q), r)


def consensus_search(obs: Observations, trim: TrimReport | None, *, range_sigma_m: float | None,
                     outline_sigma_m: float, options: ConsensusOptions | None = None,
                     prior: MountingPrior | None = None) -> Search:
    """On ``obs`` (already trimmed, ``trim`` says how): keep the boards with a line-like scan, search hypotheses
    and the consensus set among them (noise ``range_sigma_m``, default the scan lines' RMS estimate); ``prior``: a
    mounting prior, its pose one hypothesis more (``hypotheses``) and held by every local optimisation."""
    options = options or ConsensusOptions()
    lines = scan_lines(obs)
    good = np.flatnonzero(lines.line_like)
    rejected = [rejection(i, f"no line fits its scan: {lines.problem[i]}") for i in np.flatnonzero(~lines.line_like)]
    if len(good) < MIN_BOARDS:
        raise SolveFailure(f"lidarcam: only {len(good)} boards with a line-like scan (at least 3 are needed): "
                           + "; ".join(f"board {r['index']}: {r['reason']}" for r in rejected))
    obs_g = obs.subset(good)
    sigma = range_sigma(obs_g, range_sigma_m)
    H = hypotheses(obs_g, sigma, outline_sigma_m, use_zhang_pless=options.use_zhang_pless,
                   guess=None if prior is None else prior.T_lidar_cam,
                   **dict(options.solver))
    if len(H.T) == 0:
        raise SolveFailure("no candidate: " + "; ".join(H.reasons))
    used = np.ones(len(good), bool)
    optima: list[LocalOptimum] = []
    if options.reject_boards and len(good) >= MIN_TESTABLE:
        used, optima, rejected = _consensus(obs_g, H, sigma, outline_sigma_m, good, rejected, prior)
    within = np.flatnonzero(H.within(used))
    cap = POOL_MAX if H.exhaustive else POOL_MAX_SAMPLED
    within = within[np.argsort(msac_cost(H.q[within][:, used]), kind="stable")[:cap]]
    pool = np.concatenate([H.T[within]] + ([np.array([o.T for o in optima])] if optima else []))
    refined = tuple(o.refined for o in optima if o.refined is not None and np.array_equal(o.used, used))
    return Search(obs, trim, good, H, used, pool, sigma, outline_sigma_m, rejected, refined)


def _consensus(obs_g: Observations, H: Hypotheses, sigma: float, outline_sigma_m: float, good: np.ndarray,
               rejected: list, prior: MountingPrior | None = None):
    """Local optimisation of the best starts and the consensus set of the best: (used (N,) bool, the local optima
    (``LocalOptimum``), the rejections so far plus the boards left out)."""
    cost = msac_cost(H.q)
    # starts: the best MSAC hypotheses, and the best by the untruncated sum (all boards, no rejection)
    starts = [(j, False) for j in distinct_order(H.T, cost, LO_STARTS)]
    starts += [(j, True) for j in distinct_order(H.T, np.sum(H.q, axis=1), LO_STARTS_ALL)]
    firsts = [np.isfinite(H.q[j]) if a else H.q[j] < SCORE_TAU for j, a in starts]
    keys = [(j, first.tobytes()) for (j, _), first in zip(starts, firsts, strict=True)]
    heads = _heads(obs_g, H.T[[j for j, _ in starts]], firsts, keys)
    done: dict = {}  # a start's result by (hypothesis, initial board set): the same start is optimised once
    for (j, a), first, key, T1 in zip(starts, firsts, keys, heads, strict=True):
        if key in done or _in_basin(T1, first, done):
            continue
        done[key] = local_optimise(obs_g, H.T[j], H.q[j], sigma, outline_sigma_m, a, prior)
    results = list(done.values())
    if not results:
        raise SolveFailure("lidarcam: no hypothesis puts the boards in front of the camera", H.T)
    # compare them at one truncation (the largest inflation among them): a solution must not win by
    # leaving out boards that inflate its own noise estimate
    tau = TEST_CHI2 * max(res.inflation for res in results)
    best = min(results, key=lambda res: float(msac_cost(res.q[None], tau)[0]))
    used = best.used
    rejected = rejected + [rejection(good[k], board_reason(best.q[k], TEST_CHI2 * best.inflation,
                                                            implausible_reason(obs_g, best.T, k)), best.q[k])
                           for k in np.flatnonzero(~used)]
    if used.sum() < 3:
        raise SolveFailure(f"lidarcam: only {int(used.sum())} of {len(good)} boards agree on one extrinsic "
                           f"(at least 3 are needed); the others fail the per-board test", H.T)
    return used, results, rejected


def _heads(obs: Observations, T0: np.ndarray, firsts: list, keys: list) -> list:
    """Where each start (``T0`` (S,4,4) on its initial board set ``firsts[s]``) heads: its Gauss-Newton steps on those
    boards (``choose.BASIN_STEPS``), all at once, for the starts a basin test may ask about (not the first, at least
    3 boards; a repeated start shares its first occurrence's); None for the others."""
    ask = [s for s in range(1, len(keys)) if keys[s] not in keys[:s] and firsts[s].sum() >= 3]
    heads = dict.fromkeys(keys)
    if ask:
        T1 = gauss_newton_steps(obs.scan_data, T0[ask], np.array([firsts[s] for s in ask]))
        heads.update({keys[s]: T for s, T in zip(ask, T1, strict=True)})
    return [None if s == 0 else heads[k] for s, k in enumerate(keys)]


def _in_basin(T1: np.ndarray | None, first: np.ndarray, done: dict) -> bool:
    """Whether a start on the initial board set ``first``, whose Gauss-Newton steps take it to ``T1`` (``_heads``),
    is in the basin of a local optimisation already run: ``T1`` lies within the distinct-start rule of a result
    whose consensus holds every board of ``first`` (it would be optimised to the same extrinsic and consensus)."""
    near = [res.T for res in done.values() if np.all(res.used[first])]
    if not near or T1 is None:
        return False
    return near_any(T1, np.array(near))


def board_reason(q: float, threshold: float, implausible: str | None = None) -> str:
    """Why a board failed the per-board test, for the report (``implausible``: ``plausible.implausible_reason``)."""
    if not np.isfinite(q):
        return f"{implausible or 'its scan falls behind the camera'} under the consensus extrinsic"
    return (f"scan inconsistent with the board plane and outline (chi-square statistic {q:.3g} > {threshold:.3g}): "
            "not this board's scan, or a moved board")
