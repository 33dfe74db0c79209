"""Hypotheses of the extrinsic for the consensus search: the minimal solver on board triples (all of them while
there are at most ``EXHAUSTIVE_TRIPLES``, else sampled in rounds until the MSAC / RANSAC stopping rule is met)
and, from 5 boards on, Zhang & Pless on the whole set and on sampled subsets. Sampling is seeded from the data
(``data_seed``), so a rerun on the same data gives the same answer.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

import numpy as np

from ..data.lines import triple_inputs
from ..data.observations import Observations
from ..solvers._common import board_triples
from ..solvers.vasconcelos import solve_triples
from ..solvers.zhang_pless import MIN_BOARDS as ZP_MIN_BOARDS
from ..solvers.zhang_pless import linear_subsets
from .consensus import SCORE_TAU, board_statistics

EXHAUSTIVE_TRIPLES = 220
"""All board triples are solved while there are at most this many (12 boards); beyond, triples are sampled."""
SAMPLE_BATCH = 48
"""Triples sampled per round of the adaptive search."""
MAX_SAMPLED_TRIPLES = 960
"""Upper bound of sampled triples."""
SEARCH_CONFIDENCE = 0.999
"""Stop sampling once an all-inlier triple has been drawn with this probability (MSAC / RANSAC rule)."""
ZP_SUBSETS = 8
"""Zhang & Pless solutions on this many sampled board subsets (from 5 boards on) ..."""
ZP_SUBSET_SHARE = 0.6
"""... each of ``max(5, ZP_SUBSET_SHARE N)`` boards."""


def data_seed(obs: Observations) -> int:
    """A seed drawn from the data themselves (CRC32 of the scans and board poses): reruns are reproducible."""
    crc = 0
    for b in obs.boards:
        crc = zlib.crc32(np.ascontiguousarray(b.scan).tobytes(), crc)
        crc = zlib.crc32(np.ascontiguousarray(b.T_cam_board).tobytes(), crc)
    return crc


def needed_samples(inlier_share: float, confidence: float = SEARCH_CONFIDENCE, size: int = 3) -> float:
    """Samples of ``size`` boards needed to draw one all-inlier sample with ``confidence`` (the RANSAC rule)."""
    w = inlier_share**size
    if w >= 1.0:
        return 1.0
    if w <= 0.0:
        return math.inf
    return math.log(1.0 - confidence) / math.log(1.0 - w)


def sample_triples(n_boards: int, count: int, rng: np.random.Generator, seen: set) -> np.ndarray:
    """Up to ``count`` distinct, not yet ``seen`` sorted triples of board indices (``seen`` is updated)."""
    out = []
    for _ in range(8 * count):
        if len(out) >= count:
            break
        tri = tuple(sorted(rng.choice(n_boards, 3, replace=False).tolist()))
        if tri not in seen:
            seen.add(tri)
            out.append(tri)
    return np.array(out, dtype=int).reshape(-1, 3)




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


def _solve(obs: Observations, tri: np.ndarray, solver_options: dict):
    sol = solve_triples(*triple_inputs(obs, tri), **solver_options)
    src = np.zeros((len(sol.T_lidar_cam), obs.n_boards), bool)
    src[np.arange(len(src))[:, None], tri[sol.triple]] = True
    return sol.T_lidar_cam, src


def triple_hypotheses(obs: Observations, sigma_m: float, outline_sigma_m: float, solver_options: dict):
    """(T, source, q, exhaustive, n_triples): all triples while few, else adaptive sampling."""
    N = obs.n_boards
    n_all = math.comb(N, 3)
    if n_all <= EXHAUSTIVE_TRIPLES:
        all_tri = board_triples(N)
        T, src = _solve(obs, all_tri, solver_options)
        return T, src, board_statistics(obs, T, sigma_m, outline_sigma_m), True, len(all_tri)
    rng = np.random.default_rng(data_seed(obs))
    seen: set = set()
    Ts, srcs, qs = [], [], []
    best_inliers = 0
    while len(seen) < min(MAX_SAMPLED_TRIPLES, n_all):
        tri = sample_triples(N, SAMPLE_BATCH, rng, seen)
        if len(tri) == 0:
            break
        T, src = _solve(obs, tri, solver_options)
        q = board_statistics(obs, T, sigma_m, outline_sigma_m)
        Ts.append(T), srcs.append(src), qs.append(q)
        if len(q):
            best_inliers = max(best_inliers, int(np.max(np.sum(q < SCORE_TAU, axis=1))))
        if len(seen) >= needed_samples(best_inliers / N):
            break
    def cat(a, shape):
        return np.concatenate(a) if a else np.zeros(shape)

    return (cat(Ts, (0, 4, 4)), cat(srcs, (0, N)).astype(bool), cat(qs, (0, N)), False, len(seen))


def zp_hypotheses(obs: Observations, rng: np.random.Generator, n_subsets: int = ZP_SUBSETS):
    """Zhang & Pless on all boards and on ``n_subsets`` random subsets of ``max(5, ZP_SUBSET_SHARE N)`` boards:
    (T (M,4,4), source (M,N), reasons)."""
    N = obs.n_boards
    if N < ZP_MIN_BOARDS:
        return np.zeros((0, 4, 4)), np.zeros((0, N), bool), []
    size = max(ZP_MIN_BOARDS, int(np.ceil(ZP_SUBSET_SHARE * N)))
    subsets = np.ones((1 + (n_subsets if size < N else 0), N), bool)
    for k in range(1, len(subsets)):
        subsets[k] = False
        subsets[k, rng.choice(N, size, replace=False)] = True
    T, full = linear_subsets(obs, subsets)
    reasons = [f"zhang_pless_linear on {int(s.sum())} boards: degenerate board set (the linear system is rank "
               "deficient)" for s in subsets[~full]]
    return T[full], subsets[full], reasons


def hypotheses(obs: Observations, sigma_m: float, outline_sigma_m: float, *, use_zhang_pless: bool = True,
               guess: np.ndarray | None = None, **solver_options) -> Hypotheses:
    """Every hypothesis of the consensus search with its per-board statistics (``consensus.board_statistics`` at
    range noise ``sigma_m``). ``guess``: a (4,4) pose known before the data (a mounting prior's), one hypothesis
    more, computed from no board."""
    T, src, q, exhaustive, n_tri = triple_hypotheses(obs, sigma_m, outline_sigma_m, solver_options)
    reasons: list[str] = [] if len(T) else [f"minimal solver: {n_tri} triples, no real solution"]
    if guess is not None:
        G = np.asarray(guess, float)[None]
        T, src = np.concatenate([T, G]), np.concatenate([src, np.zeros((1, obs.n_boards), bool)])
        q = np.concatenate([q, board_statistics(obs, G, sigma_m, outline_sigma_m)])
    if use_zhang_pless:
        Tz, sz, rz = zp_hypotheses(obs, np.random.default_rng(data_seed(obs) + 1))
        reasons += rz
        if len(Tz):
            T = np.concatenate([T, Tz])
            src = np.concatenate([src, sz])
            q = np.concatenate([q, board_statistics(obs, Tz, sigma_m, outline_sigma_m)])
    return Hypotheses(T, src, q, exhaustive, n_tri, tuple(reasons))
