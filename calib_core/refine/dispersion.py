"""Do the boards agree with each other as the noise model says? If not, a covariance that holds their spread.

A model's covariance holds only the noise it models (corner noise, range noise along the beam, a stated
intrinsics prior). On a real rig each board also carries errors the model does not hold and that do not average
out over its points: a board that is not flat, a printed pattern off its nominal size, a range bias that depends on
the surface and the incidence, residual lens distortion. They move each board's plane as a whole, so they show
in how the boards pull on the extrinsic, not in the scatter within a board.

Each board's pull is its score ``g_i`` (6,): the gradient of its own normalised cost with respect to the extrinsic
(rotation rad, translation m; ``calib_core.model.residuals``' left perturbation) at the answer, its own pose
profiled out. Under the model ``g_i`` has covariance ``S_i``, the board's profiled Fisher information
(``refine.joint.board_informations``), and the scores sum to zero at the optimum. So

    D = sum_i g_i^T S_i^+ g_i   ~   chi-square with  sum_i rank(S_i) - 6  degrees of freedom

(a board whose scan is a line on a plane has rank 2, so ``2N - 6``: none at three boards). When ``D`` exceeds its
upper ``DISPERSION_ALPHA`` quantile the boards disagree beyond the model, and the covariance is widened to the
larger, direction by direction, of

- the model's covariance times the dispersion ratio ``D / dof`` (every board's error as the model predicts it,
  only larger), and
- the boards' one-step jackknife (cluster-robust, boards as clusters): the spread of ``(S - S_i)^-1 g_i``, the
  Gauss-Newton step that leaving board ``i`` out makes, times ``(N - 1) / N``; it needs no model of the
  unmodelled error, but has rank below 6 with few boards, where the first term holds.

The scores are taken in units of the noise each sensor shows alone (the scatter of the scan lines, the corners'
scatter about their boards' own pose fits): a joint model that re-estimates its noise stds from its residuals
spreads the boards' error over every point, where it averages down. When the test passes (the model's own case:
a simulated rig), the covariance is the model's, unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.special import chdtrc

DISPERSION_ALPHA = 0.01
"""False-alarm rate of the boards' dispersion test: the covariance is widened when the dispersion statistic is
above its chi-square quantile at ``1 - DISPERSION_ALPHA`` (1 in 100 calibrations whose noise the model holds)."""
RANK_RTOL = 1e-9
"""A board's information eigenvalue below this fraction of its largest counts as a direction it does not see."""
NAMED_BOARDS = 3
"""The warning names the boards with the largest shares of the statistic, at most this many."""


@dataclass(frozen=True)
class Dispersion:
    """The boards' dispersion test at an answer.

    Attributes:
        statistic: ``D``; dof: its degrees of freedom (0: not testable); p_value: chi-square tail probability (1
        when not testable); ratio: ``D / dof`` (1 when not testable); widened: whether the covariance was widened;
        shares: (N,) each board's part of ``D``; held: the test failed but a per-board systematic term estimated
        from these boards holds their spread (not widened).
    """

    statistic: float
    dof: int
    p_value: float
    ratio: float
    widened: bool
    shares: np.ndarray
    held: bool = False

    def to_dict(self, names=None) -> dict:
        """JSON-able form for ``info["board_dispersion"]`` (``shares`` keyed by board name or index)."""
        names = [str(n) for n in names] if names is not None else [str(i) for i in range(len(self.shares))]
        return {"statistic": float(self.statistic), "dof": int(self.dof), "p_value": float(self.p_value),
                "ratio": float(self.ratio), "alpha": DISPERSION_ALPHA, "widened": bool(self.widened),
                **({"held": True} if self.held else {}),
                "shares": {n: float(s) for n, s in zip(names, self.shares, strict=True)}}

    def warning(self, names=None) -> str:
        """The result's warning when the covariance was widened: the statistic and the boards that drive it."""
        names = [str(n) for n in names] if names is not None else [str(i) for i in range(len(self.shares))]
        top = np.argsort(self.shares)[::-1][:NAMED_BOARDS]
        worst = ", ".join(f"board {names[i]} ({self.shares[i]:.1f})" for i in top)
        return (f"the boards disagree beyond the noise model (dispersion {self.statistic:.1f} on {self.dof} degrees of "
                f"freedom, p = {self.p_value:.1e}): error the model does not hold (board flatness or size, range "
                f"bias per surface, lens distortion) moves whole board planes; the covariance is widened to the "
                f"boards' spread (ratio {self.ratio:.2f}); largest shares: {worst}")


def dispersion(g: np.ndarray, S_i: np.ndarray, extra_params: int = 0) -> Dispersion:
    """The dispersion test of the board scores ``g`` (N,6) with their informations ``S_i`` (N,6,6); ``widened``
    is whether it fails at ``DISPERSION_ALPHA``. ``extra_params``: parameters besides the extrinsic fitted to the
    same boards (free intrinsics), each taking a degree of freedom from the test."""
    w, V = np.linalg.eigh(0.5 * (S_i + np.swapaxes(S_i, 1, 2)))                # (N,6), (N,6,6)
    keep = w > RANK_RTOL * w[:, -1:]
    proj = np.einsum("nab,na->nb", V, g)                                        # g in each board's eigenbasis
    shares = np.sum(np.where(keep, proj**2 / np.where(keep, w, 1.0), 0.0), axis=1)
    dof = int(keep.sum()) - 6 - int(extra_params)
    D = float(shares.sum())
    if dof <= 0:
        return Dispersion(D, 0, 1.0, 1.0, False, shares)
    p = float(chdtrc(dof, D))  # the chi-square upper tail (scipy.stats.chi2.sf without its per-call checks)
    return Dispersion(D, dof, p, D / dof, p < DISPERSION_ALPHA, shares)


def jackknife_covariance(g: np.ndarray, S_i: np.ndarray) -> np.ndarray:
    """The boards' one-step jackknife covariance (6,6): ``(N-1)/N sum (d_i - mean d)(d_i - mean d)^T`` with
    ``d_i = (S - S_i)^-1 g_i`` (pseudo-inverse where leaving a board out leaves a direction free)."""
    S = S_i.sum(axis=0)
    d = np.einsum("nab,nb->na", np.linalg.pinv(S[None] - S_i, hermitian=True), g)
    d -= d.mean(axis=0)
    n = len(g)
    return (n - 1) / n * d.T @ d


def loewner_max(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """The least covariance at least ``A`` (positive definite) and covering ``B`` (positive semi-definite) in every
    direction of ``A``'s whitened frame: ``L V max(1, m) V^T L^T`` with ``A = L L^T`` and ``L^-1 B L^-T = V m V^T``."""
    L = np.linalg.cholesky(0.5 * (A + A.T))
    Li = np.linalg.inv(L)
    m, V = np.linalg.eigh(Li @ (0.5 * (B + B.T)) @ Li.T)
    C = L @ (V * np.maximum(m, 1.0)) @ V.T @ L.T
    return 0.5 * (C + C.T)


def centred(g: np.ndarray, S_i: np.ndarray) -> np.ndarray:
    """The scores after one Gauss-Newton step of the extrinsic on their sum, ``g_i - S_i S^-1 sum_j g_j``: they sum
    to zero, as at the optimum of the weights they are computed with (exact for a linear model)."""
    return g - np.einsum("nab,b->na", S_i, np.linalg.solve(S_i.sum(axis=0), g.sum(axis=0)))


def widened_covariance(cov: np.ndarray, g: np.ndarray, S_i: np.ndarray, extra_params: int = 0,
                       held: bool = False) -> tuple[np.ndarray, Dispersion]:
    """``cov`` (6,6) and the dispersion test of the scores ``g`` (N,6) with informations ``S_i`` (N,6,6), in units
    of the noise each sensor shows alone; where the test fails, ``cov`` widened to cover the larger of the model's
    covariance in those units times the dispersion ratio, ``ratio S^-1``, and the boards' jackknife (module
    docstring); ``cov`` itself where it is larger still. ``extra_params``: as ``dispersion``'s. ``held``: the
    model holds the boards' spread already (a per-board systematic term whose scale was estimated from these
    boards, ``refine.systematic``): the test is reported, ``cov`` is not widened (no switch on top of an estimate).
    """
    g = centred(g, S_i)
    d = dispersion(g, S_i, extra_params)
    if held and d.widened:
        d = replace(d, widened=False, held=True)
    if not d.widened:
        return cov, d
    spread = loewner_max(d.ratio * np.linalg.inv(S_i.sum(axis=0)), jackknife_covariance(g, S_i))
    return loewner_max(np.asarray(cov, float), spread), d
