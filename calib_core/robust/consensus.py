"""Consensus over boards: which boards agree with an extrinsic, tested with the noise model, and hypotheses for
the search (minimal-solver triples, all of them while few and sampled with an adaptive MSAC stopping rule beyond
that, and Zhang & Pless on sampled subsets).

The per-board test compares what an extrinsic predicts with what the lidar measured, on sufficient statistics of
each scan, so scoring M hypotheses on N boards costs O(M N) (not O(M x points)):

* line: board i's plane, mapped into the lidar frame by ``T_lidar_cam``, meets the scan plane in a predicted line.
  The scan's total-least-squares line differs from it by an offset at the scan centroid and an angle; under the
  range noise (std ``sigma`` along the beam, ``sigma |nu . b|`` across the line) these have variances
  ``sigma_p^2 / K`` and ``sigma_p^2 / sum s_k^2`` (``s_k`` the points' positions along the line), so
  ``q_line = d_off^2 / var_off + sin^2(angle) / var_ang`` is chi-square with 2 degrees of freedom at the truth.
* outline: the two scan ends, mapped into the board frame, lie inside the board outline; their distances outside
  it over ``outline_sigma`` squared (boards with an exact outline only: a ``lower_bound`` or no outline is no
  evidence against the scan ends).
* a board whose scan centroid falls behind the camera gets ``inf``.

Lidar frame ``{L}``, camera ``{C}``, board ``{W}_i`` as in ``calib_core.data.observations``; metres, radians.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass

import numpy as np

from ..data.lines import fit_line
from ..data.observations import Observations
from ..data.residuals import outside_outline

EXHAUSTIVE_TRIPLES = 220
"""All board triples are solved while there are at most this many (12 boards); beyond, triples are sampled."""
SAMPLE_BATCH = 48
"""Triples sampled per round of the adaptive search."""
MAX_SAMPLED_TRIPLES = 960
"""Upper bound of sampled triples."""
SEARCH_CONFIDENCE = 0.999
"""Stop sampling once an all-inlier triple has been drawn with this probability (MSAC / RANSAC rule)."""
SCORE_TAU = 400.0
"""MSAC truncation of the per-board statistic while scoring hypotheses (minimal hypotheses are noisy: a good board
under a good triple's solution can be far beyond the final test's threshold)."""
TEST_CHI2 = 18.42
"""Final per-board test: the chi-square(2) quantile at 1 - 1e-4 (times the fitted inflation, ``inflation``)."""
ZP_SUBSETS = 8
"""Zhang & Pless solutions on this many sampled board subsets (from 5 boards on)."""
CHUNK_ELEMENTS = 400_000
"""Hypotheses are scored in chunks of at most this many (hypothesis, board) pairs: memory stays bounded."""


@dataclass(frozen=True, eq=False)
class BoardLines:
    """Sufficient statistics of every board's scan for the per-board test.

    Attributes: centroid (N,2), normal (N,2) unit normal of the TLS line, var_off (N,) and var_ang (N,) the
    variances of the line's offset (m^2) and angle (rad^2) under the range noise, ends (N,2,3) first and last scan
    point (lidar frame, z = 0), n_points (N,).
    """

    centroid: np.ndarray
    normal: np.ndarray
    var_off: np.ndarray
    var_ang: np.ndarray
    ends: np.ndarray
    n_points: np.ndarray


def board_lines(obs: Observations, sigma_m: float) -> BoardLines:
    """``BoardLines`` of every board (each must have a line-like scan) for range noise ``sigma_m`` (metres)."""
    c, nrm, voff, vang, ends, K = [], [], [], [], [], []
    for b in obs.boards:
        ln = fit_line(b.scan)
        nu = np.array([-ln.direction[1], ln.direction[0]])
        beam = ln.point / np.linalg.norm(ln.point)
        sp2 = (sigma_m * max(abs(float(nu @ beam)), 0.05)) ** 2
        s = (b.scan - ln.point) @ ln.direction
        c.append(ln.point), nrm.append(nu), voff.append(sp2 / len(b.scan)), vang.append(sp2 / max(float(s @ s), 1e-12))
        ends.append(b.scan_3d[[0, -1]]), K.append(len(b.scan))
    return BoardLines(np.array(c), np.array(nrm), np.array(voff), np.array(vang), np.array(ends), np.array(K))


def board_statistics(obs: Observations, lines: BoardLines, T: np.ndarray, outline_sigma_m: float) -> np.ndarray:
    """(M,N) per-board test statistic of every hypothesis ``T`` (M,4,4) ``T_lidar_cam`` (see the module doc);
    computed in chunks of ``CHUNK_ELEMENTS``."""
    T = np.asarray(T, float).reshape(-1, 4, 4)
    N = obs.n_boards
    step = max(1, CHUNK_ELEMENTS // max(N, 1))
    return np.concatenate([_statistics(obs, lines, T[i:i + step], outline_sigma_m) for i in range(0, len(T), step)]
                          or [np.zeros((0, N))])


def _statistics(obs: Observations, L: BoardLines, T: np.ndarray, outline_sigma_m: float) -> np.ndarray:
    n, d = obs.planes_cam()
    R, t = T[:, :3, :3], T[:, :3, 3]
    m = np.einsum("mab,nb->mna", R, n)                                       # board normals in {L}
    c = d[None] + np.einsum("mna,ma->mn", m, t)
    s = np.linalg.norm(m[..., :2], axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        nu = m[..., :2] / s[..., None]
        off = np.einsum("mnc,nc->mn", nu, L.centroid) - c / s
        sin = nu[..., 0] * L.normal[None, :, 1] - nu[..., 1] * L.normal[None, :, 0]
        q = off**2 / L.var_off + sin**2 / L.var_ang
    # scan ends in each board's frame: p_W = Phi^T (R^T (p_L - t) - Delta)
    p_C = np.einsum("mba,mnkb->mnka", R, L.ends[None] - t[:, None, None, :])
    depth = p_C[..., 2].mean(axis=-1)                                         # scan centre's depth in {C}
    T_cb = np.array([b.T_cam_board for b in obs.boards])
    p_W = np.einsum("mnkb,nba->mnka", p_C - T_cb[None, :, None, :3, 3], T_cb[:, :3, :3])
    for idx, outline in _outline_groups(obs):          # boards sharing one outline at once
        q[:, idx] += np.sum((outside_outline(p_W[:, idx, :, :2], outline) / outline_sigma_m) ** 2, axis=-1)
    q = np.where((depth > 0) & np.isfinite(q), q, np.inf)
    return q


def _outline_groups(obs: Observations) -> list[tuple[np.ndarray, np.ndarray]]:
    """(board indices, outline) of each distinct exact outline among the boards."""
    groups: dict[bytes, list[int]] = {}
    for i, b in enumerate(obs.boards):
        if b.outline_exact:
            groups.setdefault(np.ascontiguousarray(b.outline).tobytes() + bytes([len(b.outline)]), []).append(i)
    return [(np.array(idx), obs.boards[idx[0]].outline) for idx in groups.values()]


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


def msac_cost(q: np.ndarray, tau: float = SCORE_TAU) -> np.ndarray:
    """(M,) MSAC cost of (M,N) per-board statistics: each board counts ``min(q, tau)``."""
    return np.sum(np.minimum(q, tau), axis=1)


MAX_INFLATION = 25.0
"""The inflation is capped here (the boards' lines scatter 5 times more than the range noise explains): beyond,
the boards do not agree on one extrinsic and the tests reject them rather than widen."""


def inflation(q_used: np.ndarray, dof: int = 2) -> float:
    """Variance inflation (1 .. ``MAX_INFLATION``) of the per-board statistics of the boards in use: their median
    over the chi-square median, so that unmodelled noise (e.g. camera-pose errors) does not reject good boards."""
    if len(q_used) == 0:
        return 1.0
    chi2_median = {1: 0.455, 2: 1.386, 3: 2.366}.get(dof, dof * (1 - 2 / (9 * dof)) ** 3)
    return min(MAX_INFLATION, max(1.0, float(np.median(q_used)) / chi2_median))
