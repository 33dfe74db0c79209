"""Point-level robustness: which scan points of a board lie on its scan line, before any extrinsic is known.

A board's scan is a straight segment in the lidar scan plane plus, in real data, points that are not on the
board: gross outliers (spurious returns anywhere along a beam) and mixed pixels at the ends (a beam that
straddles the board edge returns a range between the board and the background). Both are off the board's line
along their beam. Per board: a least-median line over point pairs (robust to up to half the points being
off), then a total-least-squares refit on the points near it; the range residual of every point against that
line (the noise is along the beam) is tested against the pooled noise scale of all boards (``clipped_sigma``: a
real lidar's heavy-tailed noise is not read as outliers). Lidar frame, metres.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np

from ..data.lines import MAD_TO_SIGMA, MIN_LINE_POINTS, mad_sigma, tls_line
from ..data.observations import Observations
from ..model.residuals import MIN_BEAM_INCIDENCE

TRIM_SIGMAS = 4.0
"""A scan point whose range residual against its board's robust line exceeds this many pooled noise stds is
left out (about 6e-5 of clean Gaussian points)."""

MAX_TRIM_SHARE = 0.5
"""A board that would lose more than this share of its points is not a single straight segment: it is kept
whole and left to the board-level consensus, which then rejects it as a whole."""

NEAR_SIGMAS = 3.0
"""The robust line is refitted by total least squares on the points within this many robust stds of it."""
MIN_SIGMA_M = 1e-6
"""Floor (metres) of the robust scales: exact (noise-free) scans keep a finite test."""

CLIP_MAX_ITER = 50
"""At most this many rounds of ``clipped_sigma``'s fixed-point iteration ..."""
CLIP_RTOL = 1e-6
"""... which stops when the std changes by less than this share."""

_PAIR_GAPS = (2, 3)
_MAX_PAIRS = 24


@dataclass(frozen=True)
class TrimReport:
    """What point-level trimming left out.

    Attributes:
        keep: per board, (K_i,) bool mask of the points kept.
        off_line: per board, the number of points left out inside the scan (gross outliers).
        at_ends: per board, the number left out in the leading or trailing run (mixed pixels at the ends).
        sigma_m: pooled clipped range-noise std (metres, ``clipped_sigma``) the test used.
        untrimmed: boards that were not trimmed (too few points, or more than ``MAX_TRIM_SHARE`` off).
    """

    keep: tuple[np.ndarray, ...]
    off_line: tuple[int, ...]
    at_ends: tuple[int, ...]
    sigma_m: float
    untrimmed: tuple[int, ...]

    @property
    def n_trimmed(self) -> int:
        return int(sum(self.off_line) + sum(self.at_ends))

    def summary(self) -> dict:
        """JSON-able counts: total, off-line, at the ends, and per board (only boards that lost points)."""
        per = {i: a + b for i, (a, b) in enumerate(zip(self.off_line, self.at_ends, strict=True)) if a + b}
        return {"total": self.n_trimmed, "off_line": int(sum(self.off_line)), "at_ends": int(sum(self.at_ends)),
                "per_board": {str(i): int(n) for i, n in per.items()}, "sigma_m": float(self.sigma_m)}


def line_range_residuals(points: np.ndarray, normal: np.ndarray, offset, beams: tuple | None = None) -> np.ndarray:
    """Range residuals (metres) of (K,2) points against lines ``normal . x = offset``: measured range minus the
    range at which each point's beam meets the line. ``normal`` (L,2) unit, ``offset`` (L,) -> (L,K); beams
    parallel to a line get a residual of a kilometre or more. ``beams``: ``_beams(points)``, when the caller has
    it."""
    r, b = _beams(points) if beams is None else beams
    nb = np.atleast_2d(normal) @ b.T                                          # (L,K)
    nb = np.where(np.abs(nb) < MIN_BEAM_INCIDENCE, np.copysign(MIN_BEAM_INCIDENCE, nb), nb)
    return r[None] - np.asarray(offset, float).reshape(-1, 1) / nb


def _beams(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ranges (K,) of (K,2) points and their unit beams (K,2) (a zero range keeps its zero point)."""
    r = _row_norms(points)
    return r, points / np.where(r > 0, r, 1.0)[:, None]


def _row_norms(v: np.ndarray) -> np.ndarray:
    """``numpy.linalg.norm(v, axis=1)`` of (K,2) rows, the same numbers (the root of x^2 + y^2) with less
    overhead."""
    return np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1])


def _row_medians(a: np.ndarray) -> np.ndarray:
    """``numpy.median(a, axis=1)`` of an (L,K) array, the same numbers from one partition (the mean of the two
    middle values for even K, as numpy takes it); numpy's own where a row holds a NaN."""
    K = a.shape[1]
    if K == 0 or np.isnan(a).any():
        return np.median(a, axis=1)
    h = K // 2
    if K % 2:
        return np.partition(a, h, axis=1)[:, h]
    part = np.partition(a, [h - 1, h], axis=1)
    return (part[:, h - 1] + part[:, h]) / 2


@functools.lru_cache(maxsize=1024)
def _pairs(K: int) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic point pairs spread along a scan of K points (gaps K/2 and K/3); read-only, kept per K."""
    ii, jj = [], []
    for g in _PAIR_GAPS:
        gap = max(1, K // g)
        starts = np.unique(np.linspace(0, K - 1 - gap, min(_MAX_PAIRS // len(_PAIR_GAPS), K - gap)).astype(int))
        ii.append(starts)
        jj.append(starts + gap)
    out = np.concatenate(ii), np.concatenate(jj)
    for a in out:
        a.setflags(write=False)
    return out


def robust_line_residuals(points: np.ndarray) -> np.ndarray | None:
    """Range residuals (K,) of a board's points against its robust line: the least-median-of-|residual| line
    through point pairs, refitted by total least squares on the points within ``NEAR_SIGMAS`` robust stds of it;
    None when no pair of points spans a line (one point repeated: the line fit refuses the board)."""
    P = np.asarray(points, float)
    i, j = _pairs(len(P))
    d = P[j] - P[i]
    n = np.column_stack([-d[:, 1], d[:, 0]])
    ln = _row_norms(n)
    ok = ln > 0
    if not ok.any():
        return None
    n = n[ok] / ln[ok, None]
    beams = _beams(P)                                                         # both fits' beams, computed once
    e = line_range_residuals(P, n, np.einsum("lc,lc->l", n, P[i[ok]]), beams)
    med = _row_medians(np.abs(e))
    e = e[int(np.argmin(med))]
    scale = MAD_TO_SIGMA * max(float(np.min(med)), 1e-9)
    near = np.abs(e) <= NEAR_SIGMAS * scale
    if near.sum() >= MIN_LINE_POINTS:
        c, u, _, _ = tls_line(P[near])
        nrm = np.array([-u[1], u[0]])
        e = line_range_residuals(P, nrm, [nrm @ c], beams)[0]
    return e


def clipped_sigma(residuals: np.ndarray, n_sigmas: float = TRIM_SIGMAS, max_iter: int = CLIP_MAX_ITER) -> float:
    """Noise std of zero-centred residuals that may hold gross outliers: from the MAD estimate, the RMS of the
    residuals within ``n_sigmas`` stds, repeated to its fixed point (metres, floored by ``MIN_SIGMA_M``).

    On Gaussian noise with gross outliers it is the Gaussian std (the outliers stay beyond the cut; a 4-std cut
    shrinks the RMS by 0.1%); on heavy-tailed noise (a real lidar's occasional returns several MADs off) it grows
    to the std of the tail the test has to accept, where the MAD alone would read that tail as outliers."""
    e = np.abs(np.asarray(residuals, float).ravel())
    sigma = max(mad_sigma(e), MIN_SIGMA_M)
    for _ in range(max_iter):
        new = max(float(np.sqrt(np.mean(e[e <= n_sigmas * sigma] ** 2))), MIN_SIGMA_M)
        if abs(new - sigma) <= CLIP_RTOL * sigma:
            return new
        sigma = new
    return sigma


def trim_points(obs: Observations, *, n_sigmas: float = TRIM_SIGMAS, max_share: float = MAX_TRIM_SHARE,
                min_points: int = MIN_LINE_POINTS) -> TrimReport:
    """Which scan points of each board lie on its line (``TrimReport``); the test scale is the pooled clipped
    std of all boards' residuals (one noise model for the lidar)."""
    res = [robust_line_residuals(b.scan) if len(b.scan) > min_points else None for b in obs.boards]
    pooled = np.concatenate([e for e in res if e is not None] or [np.zeros(1)])
    sigma = clipped_sigma(pooled, n_sigmas)
    keep, off, ends, untrimmed = [], [], [], []
    for i, (b, e) in enumerate(zip(obs.boards, res, strict=True)):
        K = len(b.scan)
        good = np.ones(K, bool) if e is None else np.abs(e) <= n_sigmas * sigma
        if e is None or good.sum() < min_points or (K - good.sum()) > max_share * K:
            untrimmed.append(i)
            good = np.ones(K, bool)
        keep.append(good)
        first, last = (int(np.argmax(good)), K - int(np.argmax(good[::-1]))) if good.any() else (0, K)
        n_end = first + (K - last)
        ends.append(n_end)
        off.append(int(K - good.sum()) - n_end)
    return TrimReport(tuple(keep), tuple(off), tuple(ends), sigma, tuple(untrimmed))


@dataclass(frozen=True)
class TrimOptions:
    """Point trimming: ``enabled``; a point is left out beyond ``n_sigmas`` pooled robust stds of its board's line,
    unless its board would lose more than ``max_share`` of its points."""

    enabled: bool = True
    n_sigmas: float = TRIM_SIGMAS
    max_share: float = MAX_TRIM_SHARE


def trim(obs: Observations, options: TrimOptions | None = None) -> tuple[Observations, TrimReport | None]:
    """The observations with the points off their boards' lines left out, and the report (None when disabled)."""
    options = options or TrimOptions()
    if not options.enabled:
        return obs, None
    rep = trim_points(obs, n_sigmas=options.n_sigmas, max_share=options.max_share)
    return apply_trim(obs, rep), rep


def apply_trim(obs: Observations, report: TrimReport) -> Observations:
    """``obs`` with every board's scan reduced to its kept points (the same object when nothing was left out)."""
    if report.n_trimmed == 0:
        return obs
    boards = tuple(b if k.all() else replace(b, scan=b.scan[k])
                   for b, k in zip(obs.boards, report.keep, strict=True))
    return replace(obs, boards=boards, meta=dict(obs.meta))
