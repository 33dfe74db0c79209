"""Consensus over boards: which boards agree with an extrinsic, tested with the noise model (the hypotheses that
are tested come from ``calib_core.robust.hypotheses``).

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
* lower bound: on a board whose outline is a lower bound (``refine.lower_bound``), the squared chord and margin
  residuals of its two scan ends (at their default scales; the chord's capped, so a partial segment costs at most
  ``2 CHORD_CAP``).
* an implausible board (``robust.plausible``: its scan behind the camera or the lidar, or the two sensors on
  opposite sides of its plane) gets ``inf``.

This test (chi-square with an inflation for unmodelled noise) decides which boards the consensus keeps, at every
hypothesis; the verdict (``calib_core.checks.verdict``) is a second, independent test of the final answer on every
scan point (a clipped chi-square robust to stray points): the one chooses boards, the other judges the answer.

Lidar frame ``{L}``, camera ``{C}``, board ``{W}_i`` as in ``calib_core.data.observations``; metres, radians.
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.stats import chi2

from ..data.lines import ScanLines, scan_lines
from ..data.observations import Observations
from ..model.chords import lower_bound_boards
from ..model.lower_bound import chord_residuals, margin_residuals
from ..model.plausible import plausible_boards
from ..model.residuals import board_frames, outline_groups, outside_outline

SCORE_TAU = 400.0
"""MSAC truncation of the per-board statistic while scoring hypotheses (minimal hypotheses are noisy: a good board
under a good triple's solution can be far beyond the final test's threshold)."""
TEST_CHI2 = 18.42
"""Final per-board test: the chi-square(2) quantile at 1 - 1e-4 (times the fitted inflation, ``inflation``)."""
CHUNK_ELEMENTS = 400_000
"""Hypotheses are scored in chunks of at most this many (hypothesis, board) pairs: memory stays bounded."""


MIN_TEST_INCIDENCE = 0.05
"""The line's offset and angle variances use ``max(|nu . b|, this)``: a board seen nearly edge-on does not get a
vanishing variance (and an infinite statistic) from the geometry alone."""


def test_variances(lines: ScanLines, sigma_m: float) -> tuple[np.ndarray, np.ndarray]:
    """(N,) variances of each scan line's offset (m^2) and angle (rad^2) under range noise ``sigma_m`` (metres)."""
    sp2 = (sigma_m * np.maximum(lines.incidence, MIN_TEST_INCIDENCE)) ** 2
    return sp2 / lines.n_points, sp2 / np.maximum(lines.sweep, 1e-12)


def board_statistics(obs: Observations, T: np.ndarray, sigma_m: float, outline_sigma_m: float) -> np.ndarray:
    """(M,N) per-board test statistic of every hypothesis ``T`` (M,4,4) ``T_lidar_cam`` (see the module doc) for
    range noise ``sigma_m`` (metres; the scan lines are ``lines.scan_lines(obs)``, every board line-like);
    computed in chunks of ``CHUNK_ELEMENTS``."""
    T = np.asarray(T, float).reshape(-1, 4, 4)
    N = obs.n_boards
    L = scan_lines(obs)
    var = test_variances(L, sigma_m)
    step = max(1, CHUNK_ELEMENTS // max(N, 1))
    return np.concatenate([_statistics(obs, L, var, T[i:i + step], outline_sigma_m) for i in range(0, len(T), step)]
                          or [np.zeros((0, N))])


def _statistics(obs: Observations, L: ScanLines, var: tuple, T: np.ndarray, outline_sigma_m: float) -> np.ndarray:
    n, d = obs.planes_cam()
    R, t = T[:, :3, :3], T[:, :3, 3]
    m = n @ R.swapaxes(-1, -2)                                                # (M,N,3) board normals in {L}
    c = d[None] + (m @ t[..., None])[..., 0]
    s = np.sqrt(m[..., 0] ** 2 + m[..., 1] ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        nu = m[..., :2] / s[..., None]
        off = nu[..., 0] * L.centroid[:, 0] + nu[..., 1] * L.centroid[:, 1] - c / s
        sin = nu[..., 0] * L.normal[None, :, 1] - nu[..., 1] * L.normal[None, :, 0]
        q = off**2 / var[0] + sin**2 / var[1]
    # scan centre's depth in {C} (z of R^T (p_L - t)) and the scan ends in each board's frame (``board_frames``)
    depth = ((L.ends.mean(axis=1)[None] - t[:, None]) @ R[:, :, 2:3])[..., 0]
    A, c = board_frames(obs, T, rows=2)
    p_W = L.ends[None] @ A.swapaxes(-1, -2) + c[:, :, None, :]                 # (M,N,2,2)
    for idx, outline in outline_groups(obs):          # boards sharing one outline at once
        q[:, idx] += ((outside_outline(p_W[:, idx], outline) / outline_sigma_m) ** 2).sum(axis=-1)
    lb = lower_bound_boards(obs)
    if len(lb):                                       # lower-bound outlines: chord coverage and the margin prior
        low = chord_residuals(obs, T) ** 2 + margin_residuals(obs, T) ** 2
        q[:, lb] += low.reshape(len(T), len(lb), 2).sum(axis=-1)
    q = np.where((depth > 0) & plausible_boards(obs, T) & np.isfinite(q), q, np.inf)
    return q


def msac_cost(q: np.ndarray, tau: float = SCORE_TAU) -> np.ndarray:
    """(M,) MSAC cost of (M,N) per-board statistics: each board counts ``min(q, tau)``."""
    return np.sum(np.minimum(q, tau), axis=1)


MAX_INFLATION = 25.0
"""The inflation is capped here (the boards' lines scatter 5 times more than the range noise explains): beyond,
the boards do not agree on one extrinsic and the tests reject them rather than widen."""


@functools.lru_cache(maxsize=16)
def chi2_median(dof: int) -> float:
    """The median of the chi-square distribution with ``dof`` degrees of freedom (kept per ``dof``)."""
    return float(chi2.median(dof))


def inflation(q_used: np.ndarray, dof: int = 2) -> float:
    """Variance inflation (1 .. ``MAX_INFLATION``) of the per-board statistics of the boards in use: their median
    over the chi-square median, so that unmodelled noise (e.g. camera-pose errors) does not reject good boards."""
    if len(q_used) == 0:
        return 1.0
    return min(MAX_INFLATION, max(1.0, float(np.median(q_used)) / chi2_median(dof)))
