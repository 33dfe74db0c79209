"""Hypotheses of the extrinsic for the consensus search: the minimal solver on board triples (all of them while
there are at most ``EXHAUSTIVE_TRIPLES``, else sampled in rounds until the MSAC / RANSAC stopping rule is met)
and, from 5 boards on, Zhang & Pless on the whole set and on sampled subsets. Sampling is seeded from the data
(``consensus.data_seed``), so a rerun on the same data gives the same answer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..data.observations import Observations
from ..data.result import SolveFailure
from ..solvers.vasconcelos import board_triples, solve_triples
from ..solvers.zhang_pless import MIN_BOARDS as ZP_MIN_BOARDS
from ..solvers.zhang_pless import zhang_pless_linear
from .consensus import (
    EXHAUSTIVE_TRIPLES,
    MAX_SAMPLED_TRIPLES,
    SAMPLE_BATCH,
    SCORE_TAU,
    ZP_SUBSETS,
    BoardLines,
    board_statistics,
    data_seed,
    needed_samples,
    sample_triples,
)


@dataclass(frozen=True, eq=False)
class Hypotheses:
    """Hypotheses and their per-board statistics.

    Attributes:
        T: (M,4,4) ``T_lidar_cam``. source: (M,N) bool, the boards each was computed from. q: (M,N) per-board
        statistics (``consensus.board_statistics``). exhaustive: every triple was solved. n_triples: triples
        solved. reasons: why some source gave nothing.
    """

    T: np.ndarray
    source: np.ndarray
    q: np.ndarray
    exhaustive: bool
    n_triples: int
    reasons: tuple[str, ...]

    def within(self, boards: np.ndarray) -> np.ndarray:
        """(M,) bool: the hypotheses computed from the given boards only (``boards`` (N,) bool)."""
        return ~np.any(self.source & ~boards[None], axis=1)


def _solve(obs: Observations, lines: BoardLines, tri: np.ndarray, solver_options: dict):
    n, d = obs.planes_cam()
    u = np.stack([lines.normal[:, 1], -lines.normal[:, 0]], axis=1)
    sol = solve_triples(n[tri], d[tri], lines.centroid[tri], u[tri], **solver_options)
    src = np.zeros((len(sol.T_lidar_cam), obs.n_boards), bool)
    src[np.arange(len(src))[:, None], tri[sol.triple]] = True
    return sol.T_lidar_cam, src


def triple_hypotheses(obs: Observations, lines: BoardLines, outline_sigma_m: float, solver_options: dict):
    """(T, source, q, exhaustive, n_triples): all triples while few, else adaptive sampling."""
    N = obs.n_boards
    n_all = math.comb(N, 3)
    if n_all <= EXHAUSTIVE_TRIPLES:
        all_tri = board_triples(N)
        T, src = _solve(obs, lines, all_tri, solver_options)
        return T, src, board_statistics(obs, lines, T, outline_sigma_m), True, len(all_tri)
    rng = np.random.default_rng(data_seed(obs))
    seen: set = set()
    Ts, srcs, qs = [], [], []
    best_inliers = 0
    while len(seen) < min(MAX_SAMPLED_TRIPLES, n_all):
        tri = sample_triples(N, SAMPLE_BATCH, rng, seen)
        if len(tri) == 0:
            break
        T, src = _solve(obs, lines, tri, solver_options)
        q = board_statistics(obs, lines, T, outline_sigma_m)
        Ts.append(T), srcs.append(src), qs.append(q)
        if len(q):
            best_inliers = max(best_inliers, int(np.max(np.sum(q < SCORE_TAU, axis=1))))
        if len(seen) >= needed_samples(best_inliers / N):
            break
    def cat(a, shape):
        return np.concatenate(a) if a else np.zeros(shape)

    return (cat(Ts, (0, 4, 4)), cat(srcs, (0, N)).astype(bool), cat(qs, (0, N)), False, len(seen))


def zp_hypotheses(obs: Observations, rng: np.random.Generator, n_subsets: int = ZP_SUBSETS):
    """Zhang & Pless on all boards and on ``n_subsets`` random subsets of ``max(5, 0.6 N)`` boards:
    (T (M,4,4), source (M,N), reasons)."""
    N = obs.n_boards
    if N < ZP_MIN_BOARDS:
        return np.zeros((0, 4, 4)), np.zeros((0, N), bool), []
    subsets = [np.arange(N)]
    size = max(ZP_MIN_BOARDS, int(np.ceil(0.6 * N)))
    if size < N:
        subsets += [np.sort(rng.choice(N, size, replace=False)) for _ in range(n_subsets)]
    Ts, srcs, reasons = [], [], []
    for idx in subsets:
        try:
            Ts.append(zhang_pless_linear(obs.subset(idx)))
        except SolveFailure as fail:
            reasons.append(f"zhang_pless_linear on {len(idx)} boards: {fail.reason}")
            continue
        s = np.zeros(N, bool)
        s[idx] = True
        srcs.append(s)
    return (np.array(Ts).reshape(-1, 4, 4), np.array(srcs, bool).reshape(-1, N), reasons)


def hypotheses(obs: Observations, lines: BoardLines, outline_sigma_m: float, *, use_zhang_pless: bool = True,
               **solver_options) -> Hypotheses:
    """Every hypothesis of the consensus search with its per-board statistics."""
    T, src, q, exhaustive, n_tri = triple_hypotheses(obs, lines, outline_sigma_m, solver_options)
    reasons: list[str] = [] if len(T) else [f"minimal solver: {n_tri} triples, no real solution"]
    if use_zhang_pless:
        Tz, sz, rz = zp_hypotheses(obs, np.random.default_rng(data_seed(obs) + 1))
        reasons += rz
        if len(Tz):
            T = np.concatenate([T, Tz])
            src = np.concatenate([src, sz])
            q = np.concatenate([q, board_statistics(obs, lines, Tz, outline_sigma_m)])
    return Hypotheses(T, src, q, exhaustive, n_tri, tuple(reasons))
