"""Step 4 of ``lidarcam``, the final tests of a refined answer: the per-board test at the refined extrinsic (boards
that fail are left out, boards that pass are taken back) and the point test on the boards kept, with the warnings
and ``info`` entries they give."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..data.observations import Observations
from ..errors import SolveFailure
from ..model.plausible import implausible_reason
from ..model.residuals import range_residuals
from ..solvers._common import MIN_BOARDS
from .consensus import TEST_CHI2, board_statistics, inflation
from .inliers import TRIM_SIGMAS
from .search import MIN_TESTABLE, Search, board_reason, rejection

FINAL_MIN_POINTS = 3
"""The final point test leaves a board at least this many points (else it keeps them all)."""


@dataclass(frozen=True, eq=False)
class FinalTests:
    """The final tests of a refined answer: the boards used (as Observations, points failing the point test left
    out), whether that changed anything (then the method refines again on them), the warnings and the ``info``
    entries (``boards_used``, ``boards_rejected``, ``points_trimmed``, ``consensus``)."""

    obs_used: Observations
    changed: bool
    warnings: list
    info: dict


def point_test(obs: Observations, T: np.ndarray, sigma_m: float) -> tuple[Observations, int]:
    """Boards of ``obs`` without the scan points whose range residual at ``T``, less their board's median residual,
    exceeds ``TRIM_SIGMAS`` stds (a board keeps at least ``FINAL_MIN_POINTS`` points); and how many were left out.

    A point is tested against the rest of its board: an offset common to the whole board (its plane from the
    camera a few mm off, a range bias) is the per-board test's evidence, not a reason to drop its points."""
    e = range_residuals(T, obs.scan_data)
    boards, n = [], 0
    for i, b in enumerate(obs.boards):
        ei = e[obs.scan_data.board == i]
        keep = np.abs(ei - np.median(ei)) <= TRIM_SIGMAS * sigma_m
        if keep.all() or keep.sum() < FINAL_MIN_POINTS:
            boards.append(b)
            continue
        n += int((~keep).sum())
        boards.append(replace(b, scan=b.scan[keep]))
    if n == 0:
        return obs, 0
    return replace(obs, boards=tuple(boards), meta=dict(obs.meta)), n


def final_tests(s: Search, T: np.ndarray, *, reject: bool) -> FinalTests:
    """The final per-board test at the refined ``T`` (boards that fail are left out, boards that pass are taken
    back) and the point test on the boards kept."""
    q = board_statistics(s.obs_good, T, s.sigma_m, s.outline_sigma_m)[0]
    s2 = inflation(q[s.used])
    used = q <= TEST_CHI2 * s2 if reject and len(q) >= MIN_TESTABLE else s.used
    if used.sum() < MIN_BOARDS:
        raise SolveFailure(f"lidarcam: only {int(used.sum())} of {len(q)} boards pass the per-board test at the "
                           "refined extrinsic (at least 3 are needed): the boards do not agree on one extrinsic",
                           s.hyps.T)
    rejected = [r for r in s.rejected if r["index"] not in set(s.good.tolist())]
    rejected += [rejection(s.good[k], board_reason(q[k], TEST_CHI2 * s2, implausible_reason(s.obs_good, T, k)), q[k])
                 for k in np.flatnonzero(~used)]
    obs_u, n_pts = point_test(s.obs.subset(s.good[used]), T, s.sigma_m)
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
    return FinalTests(obs_u, bool(n_pts or not np.array_equal(used, s.used)), warnings, info)
