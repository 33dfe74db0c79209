"""Scan lines and the range noise they show: one total-least-squares 2D line per board, fitted to its scan points
(lidar frame, metres), and the one home of the range-noise estimates built on them.

``scan_lines(obs)`` fits every board's line once per ``Observations`` (cached in ``Observations.derived``, and
carried to ``obs.subset``); every stage reads it: the consensus test, the hypotheses, the search, the
covariance's start values, the verdict and the fixed-parameter starts. Two noise estimates, both from the lines
alone (no extrinsic), both named for what they are:

- ``ScanLines.sigma_m`` (RMS): ``sigma^2 = sum d^2 / sum (b . nu)^2`` over the boards, a range error ``n`` along
  beam ``b`` moving a point by ``n |b . nu|`` off its line (normal ``nu``), two degrees of freedom per line taken
  out. The likelihood's scale (selection, refinement, joint start values).
- ``ScanLines.robust_sigma_m`` (median absolute deviation): each line refitted without the points beyond
  ``REFIT_MADS`` MADs, then ``MAD_TO_SIGMA`` times the median of ``|d / (b . nu)|``. The verdict's scale: a few
  stray points must not widen the test that is to find them.

``residual_sigma`` is the third kind, at an extrinsic: the RMS of residuals with the fitted parameters' degrees of
freedom taken out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SolveFailure, UncertaintyError
from .observations import Observations

MIN_LINE_POINTS = 3
"""Fewest scan points a board's line is fitted to."""
MIN_ASPECT = 3.0
"""A scan is line-like when its spread along the line is at least this many times its spread across it."""
MAD_TO_SIGMA = 1.4826
"""Median absolute deviation of a Gaussian sample to its standard deviation."""
ROBUST_MIN_POINTS = 4
"""Boards with fewer points do not enter the robust noise estimate (the median needs more than the line's two
degrees of freedom)."""
REFIT_MADS = 3.0
"""The robust estimate refits each line without its points beyond this many MADs of the first fit."""
ROBUST_MIN_INCIDENCE = 0.2
"""The robust estimate divides by ``max(|b . nu|, this)``: beams grazing their board do not blow a point's
share up."""
NOISE_FLOOR_M = 1e-6
"""The RMS estimate is at least this (metres): noise-free simulations stay well defined."""
MIN_SPREAD_M = 1e-6
"""Scan points whose RMS spread about their centroid is below this (metres) are one point repeated: no line."""


def tls_line(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Total-least-squares 2D line of (K,2) points: centroid (2,), unit direction (2,), signed orthogonal
    residuals (K,) (metres, along the left normal of the direction) and the two singular values (2,)."""
    P = np.asarray(points, float)
    c = P.mean(axis=0)
    _, s, Vt = np.linalg.svd(P - c, full_matrices=False)
    u = Vt[0]
    return c, u, (P - c) @ np.array([-u[1], u[0]]), s


def mad_sigma(residuals: np.ndarray) -> float:
    """Robust std of zero-centred residuals: ``MAD_TO_SIGMA`` times the median of their absolute values."""
    return MAD_TO_SIGMA * float(np.median(np.abs(residuals)))


def residual_sigma(residuals: np.ndarray, n_params: int) -> float:
    """RMS noise std of least-squares residuals at an optimum over ``n_params`` parameters:
    ``sqrt(|e|^2 / max(K - n_params, 1))``."""
    e = np.asarray(residuals, float).ravel()
    return float(np.sqrt(e @ e / max(len(e) - n_params, 1)))


def line_problem(P: np.ndarray, min_points: int = MIN_LINE_POINTS, min_aspect: float = MIN_ASPECT) -> str | None:
    """Why (K,2) scan points do not make a line (too few, one point repeated, not line-like), or None."""
    P = np.asarray(P, float)
    if len(P) < min_points:
        return f"{len(P)} scan points, at least {min_points} are needed to fit a line"
    s = np.linalg.svd(P - P.mean(axis=0), compute_uv=False)
    if s[0] < MIN_SPREAD_M * np.sqrt(len(P)):
        return f"its {len(P)} scan points are one point repeated (spread {s[0] / np.sqrt(len(P)):.1e} m): no line"
    if s[0] <= 0 or (s[1] > 0 and s[0] < min_aspect * s[1]):
        return "scan points are not line-like (collinear-degenerate or scattered)"
    return None


def _robust_ratios(P: np.ndarray) -> np.ndarray:
    """A board's shares of the robust noise estimate (module doc); empty below ``ROBUST_MIN_POINTS``."""
    if len(P) < ROBUST_MIN_POINTS:
        return np.zeros(0)
    c, u, d, _ = tls_line(P)
    mad = mad_sigma(d)
    keep = np.abs(d) <= REFIT_MADS * mad
    if keep.sum() >= ROBUST_MIN_POINTS and mad > 0:
        c, u, _, _ = tls_line(P[keep])
    nu = np.array([-u[1], u[0]])
    cos = np.abs((P / np.linalg.norm(P, axis=1, keepdims=True)) @ nu)
    return np.abs((P - c) @ nu) / np.maximum(cos, ROBUST_MIN_INCIDENCE) * np.sqrt(len(P) / (len(P) - 2))


@dataclass(frozen=True, eq=False)
class ScanLines:
    """Every board's scan line and its share of the noise estimates (one ``Observations``; see the module doc).

    Attributes, per board (N boards):
        centroid (N,2), direction (N,2) unit, oriented from the first to the last scan point, normal (N,2) its left
        normal; n_points (N,); sweep (N,) ``sum s_k^2`` of the points' positions along the line (m^2);
        incidence (N,) ``|nu . b|`` of the beam through the centroid; ends (N,2,3) first and last scan point
        (z = 0); line_like (N,) bool and problem (N,) the reason where not (``MIN_LINE_POINTS``, ``MIN_ASPECT``).
        NaN where a board has fewer than ``MIN_LINE_POINTS`` points.
        rms_num, rms_den (N,): the RMS estimate's sums; robust_ratios: per board, its values whose median is the
        robust estimate.
    """

    centroid: np.ndarray
    direction: np.ndarray
    normal: np.ndarray
    n_points: np.ndarray
    sweep: np.ndarray
    incidence: np.ndarray
    ends: np.ndarray
    line_like: np.ndarray
    problem: tuple
    rms_num: np.ndarray
    rms_den: np.ndarray
    robust_ratios: tuple

    @classmethod
    def fit(cls, obs: Observations) -> ScanLines:
        """Fit every board of ``obs`` (use ``scan_lines(obs)``: once per Observations)."""
        N = obs.n_boards
        c, u = np.full((N, 2), np.nan), np.full((N, 2), np.nan)
        sweep, inc, num, den = (np.zeros(N) for _ in range(4))
        problems, ratios = [], []
        for i, b in enumerate(obs.boards):
            P = b.scan
            problems.append(line_problem(P))
            ratios.append(_robust_ratios(P))
            if len(P) < MIN_LINE_POINTS:
                continue
            c[i], u[i], _, _ = tls_line(P)
            if (P[-1] - P[0]) @ u[i] < 0:
                u[i] = -u[i]
            nu = np.array([-u[i, 1], u[i, 0]])
            s = (P - c[i]) @ u[i]
            d = (P - c[i]) @ nu
            cos = (P / np.linalg.norm(P, axis=1, keepdims=True)) @ nu
            sweep[i], inc[i] = float(s @ s), abs(float(nu @ c[i])) / np.linalg.norm(c[i])
            num[i], den[i] = float(d @ d), float(cos @ cos) * (len(P) - 2) / len(P)
        ends = np.array([b.scan_3d[[0, -1]] for b in obs.boards]).reshape(N, 2, 3)
        return cls(c, u, np.column_stack([-u[:, 1], u[:, 0]]), np.array([len(b.scan) for b in obs.boards]),
                   sweep, inc, ends, np.array([p is None for p in problems], bool), tuple(problems), num, den,
                   tuple(ratios))

    def subset_boards(self, indices) -> ScanLines:
        """The lines of the boards at ``indices`` (as ``Observations.subset``)."""
        idx = np.asarray(indices, int)
        return ScanLines(self.centroid[idx], self.direction[idx], self.normal[idx], self.n_points[idx],
                         self.sweep[idx], self.incidence[idx], self.ends[idx], self.line_like[idx],
                         tuple(self.problem[i] for i in idx), self.rms_num[idx], self.rms_den[idx],
                         tuple(self.robust_ratios[i] for i in idx))

    @property
    def sigma_m(self) -> float:
        """RMS range-noise std (metres) over every board with ``MIN_LINE_POINTS`` points, at least
        ``NOISE_FLOOR_M``; ``UncertaintyError`` when there is none."""
        den = float(np.sum(self.rms_den))
        if den <= 0:
            raise UncertaintyError("no board has 3 or more scan points to estimate the noise from")
        return max(float(np.sqrt(np.sum(self.rms_num) / den)), NOISE_FLOOR_M)

    @property
    def robust_sigma_m(self) -> float:
        """Robust range-noise std (metres, the verdict's); NaN when no board has ``ROBUST_MIN_POINTS`` points."""
        r = [x for x in self.robust_ratios if len(x)]
        return mad_sigma(np.concatenate(r)) if r else float("nan")

    def require_line_like(self) -> None:
        """SolveFailure naming the first board whose scan is not line-like (``MIN_LINE_POINTS``, ``MIN_ASPECT``)."""
        bad = np.flatnonzero(~self.line_like)
        if len(bad):
            raise SolveFailure(f"board {bad[0]}: {self.problem[bad[0]]}")


def scan_lines(obs: Observations) -> ScanLines:
    """The ``ScanLines`` of ``obs``, fitted once per ``Observations``."""
    return obs.derived(SCAN_LINES_KEY, ScanLines.fit)


SCAN_LINES_KEY = "lines.scan_lines"
"""The ``Observations.derived`` key of the scan lines."""


def range_sigma(obs: Observations, given: float | None = None, *, robust: bool = False) -> float:
    """The range-noise std (metres) a stage works with: ``given`` when the caller knows it, else estimated from the
    scan lines alone, their RMS (``ScanLines.sigma_m``) or with ``robust`` their median absolute deviation
    (``ScanLines.robust_sigma_m``)."""
    if given is not None:
        return float(given)
    lines = scan_lines(obs)
    return lines.robust_sigma_m if robust else lines.sigma_m


def triple_inputs(obs: Observations, tri: np.ndarray, scans: np.ndarray | None = None):
    """The minimal solver's inputs (``solvers.vasconcelos.solve_triples``) for board triples ``tri`` (B,3): the
    planes' normals (B,3,3) and offsets (B,3) in the camera frame and the scan lines' points (B,3,2) and unit
    directions (B,3,2) in the lidar frame; the lines of the scan triples ``scans`` instead, when scans are paired
    with other boards than their own."""
    lines = scan_lines(obs)
    n, d = obs.planes_cam()
    s = np.asarray(tri if scans is None else scans, int)
    return n[tri], d[tri], lines.centroid[s], lines.direction[s]
