"""Choose and refine: the candidates scored on all the evidence (``scorers.lidarcam``), the best few distinct ones
refined by maximum likelihood on the range residuals and, where the refined pose disagrees with the board outlines,
polished on the whole cost; the best is kept. Lidar frame, metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..data.observations import Observations
from ..data.residuals import perturb
from ..errors import SolveFailure
from ..refine.refine import F_SCALE_SIGMAS, Loss, RefineResult, refine
from .scorers import ScoreOptions, lidarcam_residuals
from .scorers import lidarcam as lidarcam_score

DISTINCT_ROT_DEG = 1.0
"""Two extrinsics are distinct starts when they differ by at least this rotation (degrees) ..."""
DISTINCT_TRANS_M = 0.05
"""... or this translation (metres); the one rule for every choice of starts (consensus and refinement)."""
POLISH_THRESHOLD = 10.0
"""The refined pose is polished on the whole cost when its endpoint and outline terms exceed this (in the
cost's units, half a squared number of scale-lengths): the range optimum disagrees with the board outlines."""
POLISH_DIFF_STEP = 1e-7
"""Relative finite-difference step of ``polish`` (parameters in radians and metres)."""


@dataclass(frozen=True)
class RefineOptions:
    """Choosing and refining: ``n_refine`` best distinct starts (``distinct_rot_deg``, ``distinct_trans_m``),
    maximum likelihood on the range residuals with ``loss`` at scale ``f_scale_m`` metres (default
    ``f_scale_sigmas`` range-noise stds), at most ``max_nfev`` evaluations; ``polish`` on the whole cost above
    ``polish_threshold``."""

    n_refine: int = 3
    loss: Loss = Loss.LINEAR
    f_scale_m: float | None = None
    f_scale_sigmas: float = F_SCALE_SIGMAS
    max_nfev: int = 100
    polish: bool = True
    polish_threshold: float = POLISH_THRESHOLD
    distinct_rot_deg: float = DISTINCT_ROT_DEG
    distinct_trans_m: float = DISTINCT_TRANS_M

    def __post_init__(self) -> None:
        object.__setattr__(self, "loss", Loss(self.loss))

    def scale_m(self, sigma_m: float) -> float:
        """The robust loss's scale in metres at range noise ``sigma_m``."""
        return float(self.f_scale_m) if self.f_scale_m is not None else self.f_scale_sigmas * sigma_m


def distinct_order(T: np.ndarray, cost: np.ndarray, n: int, rot_deg: float = DISTINCT_ROT_DEG,
                   trans_m: float = DISTINCT_TRANS_M) -> list[int]:
    """Indices of the ``n`` lowest finite ``cost`` among (M,4,4) ``T`` that differ pairwise by at least
    ``rot_deg`` of rotation or ``trans_m`` of translation, best first."""
    out: list[int] = []
    cos_min = np.cos(np.radians(rot_deg))
    for j in np.argsort(cost, kind="stable"):
        if not np.isfinite(cost[j]) or len(out) >= n:
            break
        if out:
            K = T[out]
            cos = (np.einsum("ab,kab->k", T[j, :3, :3], K[:, :3, :3]) - 1.0) / 2.0   # cos of the relative angle
            near = (cos > cos_min) & (np.linalg.norm(K[:, :3, 3] - T[j, :3, 3], axis=1) < trans_m)
            if near.any():
                continue
        out.append(int(j))
    return out


def forward_difference_step(x: np.ndarray, rel_step: float) -> np.ndarray:
    """The forward-difference steps ``scipy.optimize.least_squares`` takes for ``diff_step=rel_step``: ``rel_step
    |x|`` signed as ``x`` (``+`` at 0), and ``sqrt(eps) max(1, |x|)`` where that step vanishes."""
    sign = np.where(x >= 0, 1.0, -1.0)
    h = rel_step * sign * np.abs(x)
    return np.where((x + h) - x == 0, np.sqrt(np.finfo(float).eps) * sign * np.maximum(1.0, np.abs(x)), h)


def polish(obs: Observations, T0: np.ndarray, max_nfev: int, score: ScoreOptions, range_sigma_m: float) -> np.ndarray:
    """Minimise the whole ``lidarcam`` selection cost from ``T0``; its Jacobian by forward differences with the
    steps of ``forward_difference_step``, the six perturbed extrinsics evaluated as one batch."""
    last: dict = {}

    def fun(x):
        last["x"] = x.copy()
        last["f"] = lidarcam_residuals(obs, perturb(T0, x), range_sigma_m=range_sigma_m, **score.kwargs())
        return last["f"]

    def jac(x):
        f0 = last["f"] if np.array_equal(last.get("x"), x) else fun(x)
        h = forward_difference_step(x, POLISH_DIFF_STEP)
        X = x + np.diag(h)
        F = lidarcam_residuals(obs, np.array([perturb(T0, xi) for xi in X]), range_sigma_m=range_sigma_m,
                               **score.kwargs())
        return ((F - f0) / (np.diag(X) - x)[:, None]).T

    sol = least_squares(fun, np.zeros(6), jac=jac, method="trf", max_nfev=max_nfev)
    return perturb(T0, sol.x)


PRUNE_FIRST = 8
"""``best_starts`` scores the outline term of this many candidates (at least ``2 n``) first, doubling as needed."""


def best_starts(obs: Observations, C: np.ndarray, sigma_m: float, score: ScoreOptions, n: int,
                rot_deg: float = DISTINCT_ROT_DEG, trans_m: float = DISTINCT_TRANS_M) -> list[int]:
    """``distinct_order(C, scorers.lidarcam(obs, C), n, ...)``, with the outline term (the dearest) scored only
    where it can matter: the cost without it is a lower bound, so once the ``n`` starts chosen among the candidates
    scored in full all cost less than the bound of every candidate not scored, those are the starts the full
    scoring would choose (ties broken by index as there)."""
    kw = {"range_sigma_m": sigma_m, **score.kwargs()}
    bound = lidarcam_score(obs, C, **kw, with_outline=False)
    bound = np.where(np.isnan(bound), np.inf, bound)
    order = np.argsort(bound, kind="stable")
    k = min(len(C), max(PRUNE_FIRST, 2 * n))
    while True:
        idx = np.sort(order[:k])
        full = lidarcam_score(obs, C[idx], **kw)
        picks = distinct_order(C[idx], full, n, rot_deg, trans_m)
        if k == len(C) or (len(picks) == n and full[picks[-1]] < bound[order[k]]):
            return [int(idx[j]) for j in picks]
        k = min(len(C), 2 * k)


@dataclass(frozen=True, eq=False)
class Choice:
    """The chosen, refined extrinsic: ``cost`` its all-evidence score, ``refined`` the range refinement,
    ``T`` the answer (polished or not), ``start`` the candidate it was refined from."""

    cost: float
    refined: RefineResult
    T: np.ndarray
    polished: bool
    start: np.ndarray


def refine_start(obs: Observations, T0: np.ndarray, sigma_m: float, score: ScoreOptions,
                 opts: RefineOptions) -> Choice:
    """Refine one start on the range likelihood, and polish on all evidence when the outlines disagree."""
    r = refine(obs.scan_data, T0, residual="range", loss=opts.loss, f_scale_m=opts.scale_m(sigma_m),
               max_nfev=opts.max_nfev)
    T1 = r.T_lidar_cam
    final, parts = lidarcam_score(obs, T1[None], range_sigma_m=sigma_m, **score.kwargs(), return_details=True)
    final = float(final[0])
    if opts.polish and parts["edge"][0] + parts["outline"][0] > opts.polish_threshold:
        # the range optimum disagrees with the board outlines: minimise the whole evidence from there
        T2 = polish(obs, T1, opts.max_nfev, score, sigma_m)
        f2 = float(lidarcam_score(obs, T2[None], range_sigma_m=sigma_m, **score.kwargs())[0])
        if f2 < final:
            return Choice(f2, r, T2, True, T0)
    return Choice(final, r, T1, False, T0)


def choose_and_refine(obs: Observations, C: np.ndarray, sigma_m: float, score: ScoreOptions, opts: RefineOptions,
                      n_refine: int | None = None) -> Choice:
    """Score candidates ``C`` with ``scorers.lidarcam`` on ``obs`` at range noise ``sigma_m``, refine the
    ``n_refine`` (default ``opts.n_refine``) best distinct ones (``refine_start``) and return the best."""
    C = np.asarray(C, float).reshape(-1, 4, 4)
    n = opts.n_refine if n_refine is None else n_refine
    starts = best_starts(obs, C, sigma_m, score, n, opts.distinct_rot_deg, opts.distinct_trans_m)
    if not starts:
        raise SolveFailure("lidarcam: no candidate has a finite score (every one puts a board behind the camera)", C)
    return min((refine_start(obs, C[j], sigma_m, score, opts) for j in starts), key=lambda c: c.cost)
