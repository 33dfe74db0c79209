"""Choose and refine: the candidates scored on all the evidence (``score.evidence_cost``), the best few distinct ones
refined by maximum likelihood on the range residuals and, where the refined pose disagrees with the board outlines,
polished on the whole cost; the best is kept. Lidar frame, metres, radians.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np

from ..data.observations import Observations
from ..errors import SolveFailure
from ..model.linearised import lidarcam_linearised_many
from ..model.residuals import perturb
from ..model.score import ScoreOptions, evidence_cost, outline_term
from ..refine.refine import F_SCALE_SIGMAS, MAX_NFEV, Loss, RefineResult, refine, so3_left_jacobian
from ..refine.trust_region import least_squares_many
from .starts import DISTINCT_ROT_DEG, DISTINCT_TRANS_M, distinct_order, gauss_newton_steps, near_any

POLISH_THRESHOLD = 10.0
"""The refined pose is polished on the whole cost when its endpoint and outline terms exceed this (in the
cost's units, half a squared number of scale-lengths): the range optimum disagrees with the board outlines."""
GIVE_UP_ITERATIONS = 20
"""A polish from a later start is stopped after this many iterations ..."""
GIVE_UP_FACTOR = 100.0
"""... when its cost is still above this times the best cost found so far (a start that far off, after that many
steps, has not found a better minimum: on the paper's three-board cell, where polishes travel farthest, no stopped
polish would have won)."""
TIE_LOG_LIKELIHOOD = 0.1
"""Distinct refined answers (the distinct-start rule) whose costs, negative log-likelihoods, differ by less than this
are a tie: their likelihoods are equal within a factor e^0.1 (10%), which the data do not decide (``with_ties``);
the method then refuses, naming them, rather than follow rounding, unless a mounting prior separates them. Larger
values refuse more: on the paper's three-board cell (exact outlines) the better of two answers within 3.0 is the
right one 20 times in 24, and a threshold of 3.0 would refuse those 20 answers too."""
WEAK_LOG_LIKELIHOOD = 3.0
"""A distinct refined answer whose cost is within this of the chosen one's (but not a tie) is named in a warning:
the data prefer the answer by less than e^3 (about 20) to 1 (``Choice.runners_up``)."""
POLISH_METHOD = "trf"
"""The ``least_squares`` method of ``polish``."""


@dataclass(frozen=True)
class ChooseOptions:
    """Choosing and refining: ``n_refine`` best distinct starts (``distinct_rot_deg``, ``distinct_trans_m``),
    maximum likelihood on the range residuals with ``loss`` at scale ``f_scale_m`` metres (default
    ``f_scale_sigmas`` range-noise stds), at most ``max_nfev`` evaluations; ``polish`` on the whole cost above
    ``polish_threshold``; distinct answers within ``tie_log_likelihood`` of the best are ties."""

    n_refine: int = 3
    loss: Loss = Loss.LINEAR
    f_scale_m: float | None = None
    f_scale_sigmas: float = F_SCALE_SIGMAS
    max_nfev: int = MAX_NFEV
    polish: bool = True
    polish_threshold: float = POLISH_THRESHOLD
    distinct_rot_deg: float = DISTINCT_ROT_DEG
    distinct_trans_m: float = DISTINCT_TRANS_M
    tie_log_likelihood: float = TIE_LOG_LIKELIHOOD

    def __post_init__(self) -> None:
        object.__setattr__(self, "loss", Loss(self.loss))

    def scale_m(self, sigma_m: float) -> float:
        """The robust loss's scale in metres at range noise ``sigma_m``."""
        return float(self.f_scale_m) if self.f_scale_m is not None else self.f_scale_sigmas * sigma_m


def polish(obs: Observations, T0: np.ndarray, max_nfev: int, score: ScoreOptions, range_sigma_m: float,
           give_up_above: float = np.inf) -> np.ndarray:
    """Minimise the whole ``lidarcam`` selection cost from ``T0`` (``polish_many`` of one start). A polish whose
    cost is still above ``give_up_above`` after ``GIVE_UP_ITERATIONS`` iterations is stopped there."""
    def halt(_, nit, cost):
        return bool(np.isfinite(give_up_above) and nit >= GIVE_UP_ITERATIONS and cost > give_up_above)

    return polish_many(obs, np.asarray(T0, float)[None], max_nfev, score, range_sigma_m, halt)[0]


def polish_many(obs: Observations, T0: np.ndarray, max_nfev: int, score: ScoreOptions, range_sigma_m: float,
                halt=None, done=None) -> np.ndarray:
    """Minimise the whole ``lidarcam`` selection cost from each of the (B,4,4) ``T0`` at once (B,4,4):
    ``least_squares(method=POLISH_METHOD)`` of each in ``x = (w, dt)`` around its start (``data.residuals``' left
    perturbation), as ``refine.trust_region.least_squares_many`` runs it, with the analytic Jacobian
    (``linearised.lidarcam_linearised_many``, times the left Jacobian of SO(3) at the rotation step), the starts of
    a round linearised in one call. ``halt`` and ``done``: ``least_squares_many``'s (``done`` is told the start's
    index and its polished pose)."""
    T0 = np.asarray(T0, float).reshape(-1, 4, 4)
    kw = {"range_sigma_m": range_sigma_m, **score.kwargs()}

    def fun(idx, X):
        F, jac = lidarcam_linearised_many(obs, perturb(T0[idx], X), **kw)
        return F, functools.partial(_polish_jacobians, jac, X)

    told = None if done is None else (lambda i, x: done(i, perturb(T0[i], x)))
    X = least_squares_many(fun, np.zeros((len(T0), 6)), max_nfev, halt, told)
    return perturb(T0, X)


def _polish_jacobians(jac, X: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(k',n,6) the polish's Jacobians in ``x = (w, dt)`` at rows ``rows`` of the points ``X`` (k,6) of one residual
    call: ``lidarcam_linearised_many``'s (``jac(rows)``) times the left Jacobian of SO(3) at the rotation step."""
    J = jac(rows)
    for i, r in enumerate(rows):
        J[i, :, :3] = J[i, :, :3] @ so3_left_jacobian(X[r, :3])
    return J


PRUNE_FIRST = 4
"""``best_starts`` scores the outline term of this many candidates (at least ``n + 1``) first, doubling as needed."""


def best_starts(obs: Observations, C: np.ndarray, sigma_m: float, score: ScoreOptions, n: int,
                rot_deg: float = DISTINCT_ROT_DEG, trans_m: float = DISTINCT_TRANS_M) -> list[int]:
    """``distinct_order(C, score.evidence_cost(obs, C), n, ...)``, with the outline term (the dearest) scored only
    where it can matter: the cost without it is a lower bound, so once the ``n`` starts chosen among the candidates
    scored in full all cost less than the bound of every candidate not scored, those are the starts the full
    scoring would choose (ties broken by index as there). The full cost is the bound plus the outline term
    (``score.outline_term``)."""
    kw = {"range_sigma_m": sigma_m, **score.kwargs()}
    bound = evidence_cost(obs, C, **kw, with_outline=False)
    bound = np.where(np.isnan(bound), np.inf, bound)
    order = np.argsort(bound, kind="stable")
    k = min(len(C), max(PRUNE_FIRST, n + 1))
    while True:
        idx = np.sort(order[:k])
        full = bound[idx] + outline_term(obs, C[idx], score.outline_sigma_m)
        full = np.where(np.isnan(full), np.inf, full)
        picks = distinct_order(C[idx], full, n, rot_deg, trans_m)
        if k == len(C) or (len(picks) == n and full[picks[-1]] < bound[order[k]]):
            return [int(idx[j]) for j in picks]
        k = min(len(C), 2 * k)


@dataclass(frozen=True, eq=False)
class Choice:
    """The chosen, refined extrinsic: ``cost`` its all-evidence score, ``refined`` the range refinement,
    ``T`` the answer (polished or not), ``start`` the candidate it was refined from; ``ties``: the other refined
    answers, distinct from ``T``, whose cost is within ``TIE_LOG_LIKELIHOOD`` of it, as (T, cost) pairs, best
    first (empty when the data decide); ``runners_up``: likewise those within ``WEAK_LOG_LIKELIHOOD`` but not
    tied."""

    cost: float
    refined: RefineResult
    T: np.ndarray
    polished: bool
    start: np.ndarray
    ties: tuple = ()
    runners_up: tuple = ()


def refine_start(obs: Observations, T0: np.ndarray, sigma_m: float, score: ScoreOptions,
                 opts: ChooseOptions, refined: RefineResult | None = None) -> tuple[Choice, bool]:
    """Refine one start on the range likelihood (``refined``: its refinement, already run on ``obs``): its
    ``Choice`` (unpolished) and whether the refined pose disagrees with the board outlines (endpoint and outline
    terms above ``opts.polish_threshold``)."""
    r = refined if refined is not None and score.prior is None else \
        refine(obs.scan_data, T0, residual="range", loss=opts.loss, f_scale_m=opts.scale_m(sigma_m),
               max_nfev=opts.max_nfev, prior=score.prior, prior_scale_m=sigma_m)
    T1 = r.T_lidar_cam
    final, parts = evidence_cost(obs, T1[None], range_sigma_m=sigma_m, **score.kwargs(), return_details=True)
    off = parts["edge"][0] + parts["outline"][0] + parts["lower_bound"][0]
    return Choice(float(final[0]), r, T1, False, T0), bool(off > opts.polish_threshold)


def polish_choice(obs: Observations, c: Choice, sigma_m: float, score: ScoreOptions, opts: ChooseOptions,
                  give_up_above: float = np.inf) -> Choice:
    """``c`` polished on the whole evidence (``polish``) when that lowers its cost, else ``c``."""
    T2 = polish(obs, c.T, opts.max_nfev, score, sigma_m, give_up_above)
    f2 = float(evidence_cost(obs, T2[None], range_sigma_m=sigma_m, **score.kwargs())[0])
    return Choice(f2, c.refined, T2, True, c.start) if f2 < c.cost else c


def with_ties(out: list[Choice], opts: ChooseOptions, tie: float = TIE_LOG_LIKELIHOOD,
              weak: float = WEAK_LOG_LIKELIHOOD) -> Choice:
    """The best of ``out`` with ``ties`` (the others distinct from it, by the distinct-start rule, whose cost is
    within ``tie`` of its own) and ``runners_up`` (within ``weak``, not tied), each best first."""
    out = sorted(out, key=lambda c: c.cost)
    best = out[0]
    ties, near = [], []
    for c in out[1:]:
        if not np.isfinite(c.cost) or c.cost - best.cost >= max(tie, weak):
            break
        if not near_any(c.T, np.array([best.T, *(T for T, _ in ties + near)]), opts.distinct_rot_deg,
                        opts.distinct_trans_m):
            (ties if c.cost - best.cost < tie else near).append((c.T, c.cost))
    return replace(best, ties=tuple(ties), runners_up=tuple(near))


def choose_and_refine(obs: Observations, C: np.ndarray, sigma_m: float, score: ScoreOptions, opts: ChooseOptions,
                      n_refine: int | None = None, refined: tuple = ()) -> Choice:
    """Score candidates ``C`` with ``score.evidence_cost`` on ``obs`` at range noise ``sigma_m``, refine the
    ``n_refine`` (default ``opts.n_refine``) best distinct ones on the range likelihood (``refine_start``; a start
    in the basin of one already refined is not refined again, nor a start that is the optimum of one of
    ``refined``, plain least-squares refinements already run on ``obs``), polish those whose pose disagrees with
    the outlines (``polish_choice``; a hopeless polish of a later start is stopped: ``GIVE_UP_FACTOR``) and
    return the best."""
    C = np.asarray(C, float).reshape(-1, 4, 4)
    n = opts.n_refine if n_refine is None else n_refine
    starts = best_starts(obs, C, sigma_m, score, n, opts.distinct_rot_deg, opts.distinct_trans_m)
    if not starts:
        raise SolveFailure("lidarcam: no candidate has a finite score (under every one some board is implausible: "
                           "behind a sensor, or the sensors on opposite sides of its plane)", C)
    known = refined if opts.loss == Loss.LINEAR else ()
    out = _refine_starts(obs, C[starts], sigma_m, score, opts, known)
    return with_ties(polish_choices(obs, out, sigma_m, score, opts), opts, opts.tie_log_likelihood)


def polish_choices(obs: Observations, refined: list[tuple[Choice, bool]], sigma_m: float, score: ScoreOptions,
                   opts: ChooseOptions) -> list[Choice]:
    """Each refined choice (best first), polished (``polish_choice``) when it disagrees with the outlines, all
    polishes at once (``polish_many``); the polish of a later start is stopped as hopeless after
    ``GIVE_UP_ITERATIONS`` iterations while its cost is above ``GIVE_UP_FACTOR`` times the best final cost of the
    choices before it (as when the polishes run one after another)."""
    out: dict[int, Choice] = {k: c for k, (c, off) in enumerate(refined) if not (opts.polish and off)}
    todo = [k for k in range(len(refined)) if k not in out]
    if not todo:
        return [out[k] for k in range(len(refined))]

    def halt(i, nit, cost):
        if any(k not in out for k in range(todo[i])):
            return None
        bound = GIVE_UP_FACTOR * min((out[k].cost for k in range(todo[i])), default=np.inf)
        return bool(np.isfinite(bound) and nit >= GIVE_UP_ITERATIONS and cost > bound)

    def done(i, T2):
        c = refined[todo[i]][0]
        f2 = float(evidence_cost(obs, T2[None], range_sigma_m=sigma_m, **score.kwargs())[0])
        out[todo[i]] = Choice(f2, c.refined, T2, True, c.start) if f2 < c.cost else c

    polish_many(obs, np.array([refined[k][0].T for k in todo]), opts.max_nfev, score, sigma_m, halt, done)
    return [out[k] for k in range(len(refined))]


def _refine_starts(obs: Observations, starts: np.ndarray, sigma_m: float, score: ScoreOptions,
                   opts: ChooseOptions, known: tuple = ()) -> list[tuple[Choice, bool]]:
    """``refine_start`` of each start (best first), except a start whose Gauss-Newton steps land within
    the distinct-start rule of a start already refined: it is in that start's basin (``BASIN_STEPS``). A start
    that is the optimum of a ``known`` refinement keeps it."""
    out: list[tuple[Choice, bool]] = []
    refs = [next((r for r in known if np.array_equal(r.T_lidar_cam, T0)), None) for T0 in starts]
    # where every later start heads, all at once; an optimum already (a known refinement) stays where it is
    heads = np.array(starts)
    later = [i for i in range(1, len(starts)) if refs[i] is None]
    if later:
        heads[later] = gauss_newton_steps(obs.scan_data, heads[later])
    for T0, r, T1 in zip(starts, refs, heads, strict=True):
        if out and near_any(T1, np.array([c.T for c, _ in out]), opts.distinct_rot_deg, opts.distinct_trans_m):
            continue
        out.append(refine_start(obs, T0, sigma_m, score, opts, r))
    return out


def carried_runners_up(obs: Observations, best: Choice, runners: tuple, sigma_m: float, score: ScoreOptions,
                       opts: ChooseOptions, weak: float = WEAK_LOG_LIKELIHOOD) -> Choice:
    """``best`` (chosen on ``obs``) with ``runners_up``: earlier runners-up ``runners`` ((T, cost) pairs, found on
    other boards or points) refined again on ``obs`` (``refine_start``, polished where the outlines disagree), those
    distinct from ``best`` and from each other (the distinct-start rule) whose cost is below ``best.cost + weak``,
    best first. ``best`` itself and its ``ties`` are unchanged (one carried below it is a runner-up too: the answer
    is the one chosen on ``obs``)."""
    out: list[tuple] = []
    for T0, _ in runners:
        c, off = refine_start(obs, np.asarray(T0, float), sigma_m, score, opts)
        c = polish_choice(obs, c, sigma_m, score, opts) if opts.polish and off else c
        if np.isfinite(c.cost) and c.cost - best.cost < weak and not near_any(
                c.T, np.array([best.T, *(T for T, _ in out)]), opts.distinct_rot_deg, opts.distinct_trans_m):
            out.append((c.T, c.cost))
    return replace(best, runners_up=tuple(sorted(out, key=lambda tc: tc[1])))
