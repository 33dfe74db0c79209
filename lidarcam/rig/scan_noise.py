"""The lidar's range noise and the straightness test of a board segment, estimated from the boards' own segments.

A board is flat, so the scatter of its segment about a straight line is the lidar's range noise as extraction meets
it: white noise, and what a range bias that depends on the surface does to a flat board (a Hokuyo reads the black
and white squares centimetres apart). Per segment (K,2 points, lidar frame, metres) the range noise is the total
least-squares line's residual RMS (K - 2 degrees of freedom) over the RMS of ``|nu . beam|`` (nu the line's normal,
beam the unit bearing: a range error ``e`` moves a point ``e |nu . beam|`` off the line); the estimate is the median
over the boards' segments, so one wrong segment does not move it.

The straightness test (``lidarcam.rig.segment.curvature_statistic``) reads about chi-square(1) on a straight segment
with white noise. A surface-dependent bias bends the boards' segments (by a few centimetres on a Hokuyo, 20-60
chi-square units at the noise above), so the threshold is taken from the boards' own statistics: Tukey's far-out fence
``Q3 + 3 IQR`` of them, never below ``CURVATURE_CHI2`` (on white noise the fence is about 5, so the chi-square
quantile stands). A segment is then refused as an arc when it bends far more than the boards themselves do: a
pillar, or a board run together with what stands beside it. Metres throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calib_core.data.lines import tls_line

from .extract_options import CURVATURE_CHI2, DEFAULT_RANGE_SIGMA

FENCE = 3.0
"""Tukey's far-out fence: ``Q3 + FENCE * IQR`` of the boards' curvature statistics."""
MIN_SEGMENTS = 3
"""Fewest board segments to estimate from; with fewer the defaults stand."""
MIN_RANGE_SIGMA = 1e-3
"""Floor of the estimate (metres): below any 2D lidar's noise; a noise-free simulation would otherwise give 0."""
MIN_POINTS = 6
"""Fewest points of a segment that enters the estimate."""


def segment_range_sigma(P: np.ndarray) -> float:
    """Range noise (1 sigma, metres) that the (K,2) points of one flat segment show about their straight line."""
    P = np.asarray(P, float)
    if len(P) < 3:
        return math.nan
    _, u, res, _ = tls_line(P)
    nu = np.array([-u[1], u[0]])
    beams = P / np.linalg.norm(P, axis=1, keepdims=True)
    incidence = max(float(np.sqrt(np.mean((beams @ nu) ** 2))), 0.05)
    return float(np.sqrt(res @ res / (len(P) - 2))) / incidence


@dataclass(frozen=True)
class NoiseEstimate:
    """The range noise and the arc threshold extraction used, and where each came from.

    Attributes:
        range_sigma_m: range noise, 1 sigma (m).
        range_source: ``"given"`` (an option), ``"estimated"`` (from the boards' segments) or ``"default"``.
        max_curvature_chi2: threshold of the straightness test (chi-square(1) units of ``range_sigma_m``).
        curvature_source: as ``range_source``.
        n_segments: board segments the estimate read (0 when nothing was estimated).
        quartiles: first and third quartile of those segments' curvature statistics (NaN when not read).
        why: why the default stands, when it does.
    """

    range_sigma_m: float
    range_source: str
    max_curvature_chi2: float
    curvature_source: str
    n_segments: int = 0
    quartiles: tuple[float, float] = (math.nan, math.nan)
    why: str = ""

    def to_dict(self) -> dict:
        """JSON-ready (NaN -> None), for ``Observations.meta["extraction_noise"]``."""
        return {"range_sigma_m": self.range_sigma_m, "range_source": self.range_source,
                "max_curvature_chi2": self.max_curvature_chi2, "curvature_source": self.curvature_source,
                "n_segments": self.n_segments,
                "curvature_quartiles": [q if math.isfinite(q) else None for q in self.quartiles],
                **({"why": self.why} if self.why else {})}

    def describe(self) -> str:
        """One line: ``range noise 25.8 mm (estimated from 27 board segments); arc test ...``."""
        def whence(source: str) -> str:
            if source == "estimated":
                return f"estimated from {self.n_segments} board segments"
            return "given" if source == "given" else "default" + (f": {self.why}" if self.why else "")

        disp = f": the fence Q3 + 3 IQR of their statistics, quartiles {self.quartiles[0]:.3g} / " \
            f"{self.quartiles[1]:.3g}" if self.curvature_source == "estimated" else ""
        return (f"range noise {1000 * self.range_sigma_m:.1f} mm ({whence(self.range_source)}); arc test: curvature "
                f"statistic above {self.max_curvature_chi2:.4g} ({whence(self.curvature_source)}{disp})")


def estimate_noise(segments, range_sigma_m: float | None = None,
                   max_curvature_chi2: float | None = None) -> NoiseEstimate:
    """The range noise and arc threshold from the boards' segments (each (K,2), lidar frame, metres); a value given
    (not None) is kept as given. Fewer than ``MIN_SEGMENTS`` usable segments: the defaults, with the reason."""
    from .segment import curvature_statistic

    segs = [np.asarray(P, float) for P in segments if len(P) >= MIN_POINTS]
    sig = np.array([segment_range_sigma(P) for P in segs])
    segs = [P for P, s in zip(segs, sig, strict=True) if math.isfinite(s)]
    sig = sig[np.isfinite(sig)]
    enough = len(segs) >= MIN_SEGMENTS
    why = "" if enough else f"{len(segs)} board segments (fewer than {MIN_SEGMENTS}) to estimate from"
    if range_sigma_m is not None:
        sigma, s_src = float(range_sigma_m), "given"
    elif enough:
        sigma, s_src = max(float(np.median(sig)), MIN_RANGE_SIGMA), "estimated"
    else:
        sigma, s_src = DEFAULT_RANGE_SIGMA, "default"
    quartiles = (math.nan, math.nan)
    if max_curvature_chi2 is not None:
        chi2, c_src = float(max_curvature_chi2), "given"
    elif enough:
        q1, q3 = np.percentile([curvature_statistic(P, sigma) for P in segs], [25, 75])
        quartiles = (float(q1), float(q3))
        chi2, c_src = max(CURVATURE_CHI2, float(q3 + FENCE * (q3 - q1))), "estimated"
    else:
        chi2, c_src = CURVATURE_CHI2, "default"
    return NoiseEstimate(sigma, s_src, chi2, c_src, len(segs) if enough else 0, quartiles,
                         why if "default" in (s_src, c_src) else "")
