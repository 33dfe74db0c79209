"""Scan lines: a total-least-squares 2D line per board, fitted to its scan points (lidar frame, metres)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .observations import Observations
from .result import SolveFailure

MIN_LINE_POINTS = 3
MIN_SPREAD_M = 1e-6
"""Scan points whose RMS spread about their centroid is below this (metres) are one point repeated: no line."""


@dataclass(frozen=True, eq=False)
class ScanLine:
    """A 2D line in the lidar scan plane (z = 0), fitted by total least squares.

    Attributes:
        point: (2,) centroid of the points (metres).
        direction: (2,) unit direction, oriented from the first to the last scan point.
        rms: RMS orthogonal distance of the points to the line (metres).
        length: distance between the projections of the first and last points (metres).
        n_points: number of points fitted.
    """

    point: np.ndarray
    direction: np.ndarray
    rms: float
    length: float
    n_points: int


def tls_line(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Total-least-squares 2D line of (K,2) points: centroid (2,), unit direction (2,), signed orthogonal
    residuals (K,) (metres, along the left normal of the direction) and the two singular values (2,)."""
    P = np.asarray(points, float)
    c = P.mean(axis=0)
    _, s, Vt = np.linalg.svd(P - c, full_matrices=False)
    u = Vt[0]
    return c, u, (P - c) @ np.array([-u[1], u[0]]), s


def fit_line(points: np.ndarray, *, min_points: int = MIN_LINE_POINTS, min_aspect: float = 3.0) -> ScanLine:
    """Fit a line to (K,2) ordered points by SVD; refuses fewer than ``min_points`` points, points that are one
    point repeated (RMS spread under ``MIN_SPREAD_M``) or a point cloud that is not line-like (spread along the
    line less than ``min_aspect`` times the spread across it).

    Raises:
        SolveFailure: with the reason, for too few or degenerate points.
    """
    P = np.asarray(points, float)
    if len(P) < min_points:
        raise SolveFailure(f"{len(P)} scan points, at least {min_points} are needed to fit a line")
    c, u, _, s = tls_line(P)
    if s[0] < MIN_SPREAD_M * np.sqrt(len(P)):
        raise SolveFailure(f"its {len(P)} scan points are one point repeated (spread {s[0] / np.sqrt(len(P)):.1e} m):"
                           " no line")
    if s[0] <= 0 or (s[1] > 0 and s[0] < min_aspect * s[1]):
        raise SolveFailure("scan points are not line-like (collinear-degenerate or scattered)")
    if (P[-1] - P[0]) @ u < 0:
        u = -u
    along = (P - c) @ u
    return ScanLine(point=c, direction=u, rms=float(s[1] / np.sqrt(len(P))),
                    length=float(along[-1] - along[0]), n_points=len(P))


def fit_lines(obs: Observations, **kwargs) -> list[ScanLine]:
    """One ``ScanLine`` per board; a SolveFailure names the board that could not be fitted."""
    lines = []
    for i, b in enumerate(obs.boards):
        try:
            lines.append(fit_line(b.scan, **kwargs))
        except SolveFailure as err:
            raise SolveFailure(f"board {i}: {err.reason}") from None
    return lines
