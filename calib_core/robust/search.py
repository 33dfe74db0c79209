"""The robust front and back of ``lidarcam``: point trimming, the consensus search over boards (hypotheses, MSAC
scores, local optimisation on consensus sets) and the final per-board and per-point tests after refinement.

Board indices in everything reported (``boards_used``, ``boards_rejected``) are those of the caller's
observations. Lidar frame, metres, radians.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..data.lines import fit_line
from ..data.observations import Observations
from ..data.residuals import range_residuals
from ..data.result import SolveFailure
from ..geometry.transforms import matrix_to_rotvec
from ..refine.refine import refine
from ..refine.uncertainty import scan_noise_estimate
from .consensus import SCORE_TAU, TEST_CHI2, BoardLines, board_lines, board_statistics, inflation, msac_cost
from .hypotheses import Hypotheses, hypotheses
from .inliers import TRIM_SIGMAS, TrimReport, apply_trim, trim_points

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
MIN_TESTABLE = 4
"""Boards are tested and rejected only from this many on: three boards fit every minimal solution exactly."""


@dataclass(frozen=True, eq=False)
class Search:
    """Outcome of the consensus search (see the module doc); ``good`` are the caller's indices of the boards with a
    line-like scan, ``used`` (len(good),) bool the consensus among them."""

    obs: Observations
    trim: TrimReport | None
    good: np.ndarray
    lines: BoardLines
    hyps: Hypotheses
    used: np.ndarray
    pool: np.ndarray
    sigma_m: float
    outline_sigma_m: float
    rejected: list = field(default_factory=list)

    @property
    def obs_good(self) -> Observations:
        return self.obs.subset(self.good)

    @property
    def obs_used(self) -> Observations:
        return self.obs.subset(self.good[self.used])

    @property
    def all_candidates(self) -> np.ndarray:
        return self.hyps.T


def _rejection(index: int, reason: str, statistic: float | None = None) -> dict:
    return {"index": int(index), "reason": reason, "statistic": None if statistic is None else float(statistic)}


def _distinct_order(T: np.ndarray, cost: np.ndarray, n: int) -> list[int]:
    out: list[int] = []
    for j in np.argsort(cost, kind="stable"):
        if not np.isfinite(cost[j]) or len(out) >= n:
            break
        if all(np.linalg.norm(matrix_to_rotvec(T[j, :3, :3] @ T[k, :3, :3].T)) > 0.02
               or np.linalg.norm(T[j, :3, 3] - T[k, :3, 3]) > 0.05 for k in out):
            out.append(int(j))
    return out


def local_optimise(obs: Observations, lines: BoardLines, T0: np.ndarray, q0: np.ndarray, sigma_m: float,
                   outline_sigma_m: float, start_all: bool = False):
    """Refine ``T0`` on the boards it explains (``q0 < SCORE_TAU``; every board in front of the camera with
    ``start_all``), re-test every board, repeat until the consensus set is stable: (T, used (N,) bool, q (N,),
    inflation, MSAC cost at the final threshold plus ``N log(inflation)``)."""
    used, T, q = (np.isfinite(q0) if start_all else q0 < SCORE_TAU), T0, q0
    s2 = 1.0
    for _ in range(LO_ROUNDS):
        if used.sum() < 3:
            break
        T = refine(obs.subset(np.flatnonzero(used)).scan_data, T, residual="range", loss="soft_l1",
                   f_scale=2.5 * sigma_m).T_lidar_cam
        q = board_statistics(obs, lines, T, outline_sigma_m)[0]
        s2 = inflation(q[used])
        new = q <= TEST_CHI2 * s2
        if np.array_equal(new, used):
            break
        used = new
    return T, used, q, s2, float(msac_cost(q[None], TEST_CHI2 * s2)[0]) + np.log(s2) * len(q)


def consensus_search(obs: Observations, *, range_sigma_m: float | None, outline_sigma_m: float, trim: bool = True,
                     reject: bool = True, use_zhang_pless: bool = True, **solver_options) -> Search:
    """Trim points, keep boards with a line-like scan, search hypotheses and the consensus set among them."""
    rep = trim_points(obs) if trim else None
    obs_t = apply_trim(obs, rep) if rep is not None else obs
    good, rejected = [], []
    for i, b in enumerate(obs_t.boards):
        try:
            fit_line(b.scan)
            good.append(i)
        except SolveFailure as fail:
            rejected.append(_rejection(i, f"no line fits its scan: {fail.reason}"))
    good = np.array(good, dtype=int)
    if len(good) < 3:
        raise SolveFailure(f"lidarcam: only {len(good)} boards with a line-like scan (at least 3 are needed): "
                           + "; ".join(f"board {r['index']}: {r['reason']}" for r in rejected))
    obs_g = obs_t.subset(good)
    sigma = range_sigma_m if range_sigma_m is not None else scan_noise_estimate(obs_g)
    lines = board_lines(obs_g, sigma)
    H = hypotheses(obs_g, lines, outline_sigma_m, use_zhang_pless=use_zhang_pless, **solver_options)
    if len(H.T) == 0:
        raise SolveFailure("no candidate: " + "; ".join(H.reasons))
    cost = msac_cost(H.q)
    used = np.ones(len(good), bool)
    lo_T: list[np.ndarray] = []
    if reject and len(good) >= MIN_TESTABLE:
        # starts: the best MSAC hypotheses, and the best by the untruncated sum (all boards, no rejection)
        starts = [(j, False) for j in _distinct_order(H.T, cost, LO_STARTS)]
        starts += [(j, True) for j in _distinct_order(H.T, np.sum(H.q, axis=1), LO_STARTS_ALL)]
        done: dict = {}  # a start's result by (hypothesis, initial board set): the same start is optimised once
        for j, a in starts:
            key = (j, (np.isfinite(H.q[j]) if a else H.q[j] < SCORE_TAU).tobytes())
            if key not in done:
                done[key] = local_optimise(obs_g, lines, H.T[j], H.q[j], sigma, outline_sigma_m, a)
        results = list(done.values())
        lo_T = [res[0] for res in results]
        # compare them at one truncation (the largest inflation among them): a solution must not win by
        # leaving out boards that inflate its own noise estimate
        tau = TEST_CHI2 * max((res[3] for res in results), default=1.0)
        best = min(results, key=lambda res: float(msac_cost(res[2][None], tau)[0])) if results else None
        if best is None:
            raise SolveFailure("lidarcam: no hypothesis puts the boards in front of the camera", H.T)
        used = best[1]
        for k in np.flatnonzero(~used):
            rejected.append(_rejection(good[k], board_reason(best[2][k], TEST_CHI2 * best[3]), best[2][k]))
        if used.sum() < 3:
            raise SolveFailure(f"lidarcam: only {int(used.sum())} of {len(good)} boards agree on one extrinsic "
                               f"(at least 3 are needed); the others fail the per-board test", H.T)
    within = np.flatnonzero(H.within(used))
    cap = POOL_MAX if H.exhaustive else POOL_MAX_SAMPLED
    within = within[np.argsort(msac_cost(H.q[within][:, used]), kind="stable")[:cap]]
    pool = np.concatenate([H.T[within]] + ([np.array(lo_T)] if lo_T else []))
    return Search(obs_t, rep, good, lines, H, used, pool, sigma, outline_sigma_m, rejected)


def board_reason(q: float, threshold: float) -> str:
    """Why a board failed the per-board test, for the report."""
    if not np.isfinite(q):
        return "its scan falls behind the camera under the consensus extrinsic"
    return (f"scan inconsistent with the board plane and outline (chi-square statistic {q:.3g} > {threshold:.3g}): "
            "not this board's scan, or a moved board")


@dataclass(frozen=True, eq=False)
class Finish:
    """After the final tests: the boards used (as Observations), the refit (None when nothing changed), the
    warnings and the ``info`` entries (``boards_used``, ``boards_rejected``, ``points_trimmed``, ``consensus``)."""

    obs_used: Observations
    refit: tuple | None
    warnings: list
    info: dict


def _point_test(obs: Observations, T: np.ndarray, sigma_m: float) -> tuple[Observations, int]:
    """Boards of ``obs`` without the scan points whose range residual at ``T`` exceeds ``TRIM_SIGMAS`` stds
    (a board keeps at least 3 points); and how many were left out."""
    e = range_residuals(T, obs.scan_data)
    bad = np.abs(e) > TRIM_SIGMAS * sigma_m
    if not bad.any():
        return obs, 0
    boards, n = [], 0
    for i, b in enumerate(obs.boards):
        keep = ~bad[obs.scan_data.board == i]
        if keep.all() or keep.sum() < 3:
            boards.append(b)
            continue
        n += int((~keep).sum())
        boards.append(replace(b, scan=b.scan[keep]))
    return replace(obs, boards=tuple(boards), meta=dict(obs.meta)), n


def finish_search(s: Search, T: np.ndarray, *, reject: bool, refit: Callable) -> Finish:
    """The final per-board test at the refined ``T`` (boards that fail are left out, boards that pass are taken
    back) and the point test on the boards kept; ``refit(obs, T)`` refines again when either changed anything."""
    q = board_statistics(s.obs_good, s.lines, T, s.outline_sigma_m)[0]
    s2 = inflation(q[s.used])
    used = q <= TEST_CHI2 * s2 if reject and len(q) >= MIN_TESTABLE else s.used
    if used.sum() < 3:
        raise SolveFailure(f"lidarcam: only {int(used.sum())} of {len(q)} boards pass the per-board test at the "
                           "refined extrinsic (at least 3 are needed): the boards do not agree on one extrinsic",
                           s.hyps.T)
    rejected = [r for r in s.rejected if r["index"] not in set(s.good.tolist())]
    rejected += [_rejection(s.good[k], board_reason(q[k], TEST_CHI2 * s2), q[k]) for k in np.flatnonzero(~used)]
    obs_u, n_pts = _point_test(s.obs.subset(s.good[used]), T, s.sigma_m)
    out = refit(obs_u, T) if (n_pts or not np.array_equal(used, s.used)) else None
    warnings = [f"board {r['index']} left out: {r['reason']}" for r in sorted(rejected, key=lambda r: r["index"])]
    trimmed = s.trim.summary() if s.trim is not None else {"total": 0}
    trimmed["in_fit"] = n_pts
    if trimmed["total"] + n_pts:
        warnings.append(f"{trimmed['total'] + n_pts} scan points left out as outliers (off their board's line: "
                        f"{trimmed.get('off_line', 0)}, at the segment ends: {trimmed.get('at_ends', 0)}, "
                        f"in the final fit: {n_pts})")
    info = {"boards_used": [int(i) for i in s.good[used]],
            "boards_rejected": sorted(rejected, key=lambda r: r["index"]), "points_trimmed": trimmed,
            "consensus": {"n_hypotheses": int(len(s.hyps.T)), "n_triples": int(s.hyps.n_triples),
                          "exhaustive": bool(s.hyps.exhaustive), "inflation": float(s2),
                          "statistics": [float(v) for v in q]}}
    return Finish(obs_u, out, warnings, info)
