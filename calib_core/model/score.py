"""The ``lidarcam`` selection cost (``evidence_cost``): a negative log-likelihood over all the evidence a candidate
extrinsic meets (every scan point's range residual, both endpoints against the board edges, scan points inside the
board outline, the lower-bound outline's chord and margin terms, the mounting prior, boards in front of both sensors),
composed from the terms of this stage; its residual vector (``lidarcam_residuals``) and the scales of its terms
(metres). Its analytic linearisation is ``model.linearised``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.observations import Observations
from ..geometry.mounting import MountingPrior
from .lower_bound import CHORD_CAP, CHORD_SIGMA_M, MARGIN_SIGMA_M, chord_residuals, margin_residuals
from .plausible import plausible_boards
from .residuals import (
    board_frames,
    candidate_chunk,
    in_chunks,
    outside_outlines,
    point_line_errors,
    range_residuals,
)

EDGE_SIGMA_M = 0.03
"""Scale (metres) of the endpoint-against-edge term of the ``lidarcam`` score: absorbs the range noise and the beam
spacing at the board edges (0.25 deg at 5 m is 22 mm)."""

OUTLINE_SIGMA_M = 0.03
"""Scale (metres) of the points-inside-the-outline term of the ``lidarcam`` score."""

DEFAULT_RANGE_SIGMA_M = 0.02
"""Range-noise std (metres) of the ``lidarcam`` scorer when its caller gives none (the simulator's default
noise; the method always passes its own estimate)."""


def exact_outline_boards(obs: Observations) -> np.ndarray:
    """Indices of the boards whose outline is exact: the only ones the endpoint and outline terms read (a
    ``lower_bound`` outline lets the scan run past it, ``none`` says nothing)."""
    return np.flatnonzero(obs.exact_outlines)


@dataclass(frozen=True)
class ScoreOptions:
    """Scales (metres) of the ``lidarcam`` score's endpoint and outline terms (exact outlines) and of its chord and
    margin terms (lower-bound outlines, ``refine.lower_bound``), its cost per implausible board (behind a sensor,
    or the sensors on opposite sides of its plane: ``robust.plausible``), and the mounting ``prior`` (None: no
    prior)."""

    edge_sigma_m: float = EDGE_SIGMA_M
    outline_sigma_m: float = OUTLINE_SIGMA_M
    behind_penalty: float = np.inf
    chord_sigma_m: float = CHORD_SIGMA_M
    chord_cap: float = CHORD_CAP
    margin_sigma_m: float = MARGIN_SIGMA_M
    prior: MountingPrior | None = None

    def kwargs(self) -> dict:
        return {"edge_sigma_m": self.edge_sigma_m, "outline_sigma_m": self.outline_sigma_m,
                "behind_penalty": self.behind_penalty, "chord_sigma_m": self.chord_sigma_m,
                "chord_cap": self.chord_cap, "margin_sigma_m": self.margin_sigma_m, "prior": self.prior}


LOWER_BOUND_KEYS = ("chord_sigma_m", "chord_cap", "margin_sigma_m", "prior")
"""The score's keywords beyond the exact-outline ones: the lower-bound terms and the mounting prior."""


def evidence_constants(obs: Observations):
    """The constants of the score's evidence: the indices of the boards whose outline is exact
    (``exact_outline_boards``), the mask (K,) of their scan points in ``obs.scan_data``, and every
    board's scan centroid (N,3; lidar frame, metres)."""
    exact = exact_outline_boards(obs)
    return exact, np.isin(obs.scan_data.board, exact), np.array([b.scan_3d.mean(axis=0) for b in obs.boards])


def _evidence(obs: Observations, C: np.ndarray, range_sigma_m: float, edge_sigma_m: float, outline_sigma_m: float,
              with_outline: bool = True, **lower):
    """The ``lidarcam`` score's normalised residuals of (M,4,4) candidates: range (M,K), endpoints and outline
    distances of the boards with an exact outline (scan-data order), the chord, margin and prior residuals
    (``lower``: ``LOWER_BOUND_KEYS``), and the number of implausible boards (M,)."""
    data = obs.scan_data
    exact, on_exact, _ = obs.derived("score.evidence_constants", evidence_constants)
    rng = range_residuals(C, data) / range_sigma_m
    frames = board_frames(obs, C)
    edge = point_line_errors(obs, C, frames=frames)[:, exact].reshape(len(C), -1) / edge_sigma_m
    out = outside_outlines(obs, C, frames=frames)[:, on_exact] / outline_sigma_m if with_outline else \
        np.zeros((len(C), 0))
    chord = chord_residuals(obs, C, lower.get("chord_sigma_m", CHORD_SIGMA_M), lower.get("chord_cap", CHORD_CAP),
                            frames)
    margin = margin_residuals(obs, C, lower.get("margin_sigma_m", MARGIN_SIGMA_M), frames)
    prior = lower.get("prior")
    pri = prior.residuals(C) if prior is not None else np.zeros((len(C), 0))
    bad = (~plausible_boards(obs, C)).sum(axis=1).astype(float)
    return rng, edge, out, np.concatenate([chord, margin], axis=1), pri, bad


def evidence_cost(obs: Observations, candidates: np.ndarray, *, range_sigma_m: float = DEFAULT_RANGE_SIGMA_M,
                  edge_sigma_m: float = EDGE_SIGMA_M, outline_sigma_m: float = OUTLINE_SIGMA_M,
                  behind_penalty: float = np.inf, return_details: bool = False, with_outline: bool = True, **lower):
    """Our selection cost: a negative log-likelihood over all the evidence, per candidate (lower is better).

    ``cost = 0.5 sum_k (e_k / sigma)^2 + 0.5 sum_{i,end} (d_{i,end} / edge_sigma)^2 + 0.5 sum_k (o_k / outline_sigma)^2
    + 0.5 |r_lower|^2 + 0.5 |r_prior|^2 + behind_penalty * (implausible boards)`` with ``e_k`` the range residual of
    every scan point against its board plane, ``d`` the point-line errors of the two endpoints of every board
    (docs/METHOD.md eq. 8-12), ``o_k`` the distance of every scan point, mapped into its board's frame, outside the
    board outline (``d`` and ``o`` on boards with an exact outline only, ``exact_outline_boards``), ``r_lower`` the
    chord and margin residuals of the boards with a lower-bound outline (``refine.lower_bound``), ``r_prior`` the
    mounting prior's (when given), and a board implausible when it is behind the camera or the lidar or the two
    sensors lie on opposite sides of its plane (``robust.plausible``).

    Args:
        range_sigma_m: range-noise std (metres).
        edge_sigma_m, outline_sigma_m: scales (metres) of the endpoint and outline terms; they absorb the
            range noise and the beam spacing at the board edges (0.25 deg at 5 m is 22 mm).
        behind_penalty: cost per implausible board (inf: such a candidate is never chosen).
        with_outline: False leaves the outline term out (the dearest): a lower bound of the cost, for pruning.
        lower: ``LOWER_BOUND_KEYS`` (the chord and margin scales, the cap, the mounting prior).
    Returns:
        (M,) cost; with ``return_details`` also a dict of the terms, each (M,).
    """
    candidates = np.asarray(candidates, float).reshape(-1, 4, 4)
    if len(candidates) > candidate_chunk(obs):  # bounded memory: score the candidates in chunks
        opts = {"range_sigma_m": range_sigma_m, "edge_sigma_m": edge_sigma_m, "outline_sigma_m": outline_sigma_m,
                "behind_penalty": behind_penalty, "with_outline": with_outline, **lower}
        out = in_chunks(lambda C: evidence_cost(obs, C, **opts, return_details=True), obs, candidates)
        return out if return_details else out[0]
    rng, edge, out, low, pri, behind = _evidence(obs, candidates, range_sigma_m, edge_sigma_m, outline_sigma_m,
                                                 with_outline, **lower)
    terms = {"range": rng, "edge": edge, "outline": out, "lower_bound": low, "prior": pri}
    terms = {k: 0.5 * (v**2).sum(axis=1) for k, v in terms.items()}
    with np.errstate(invalid="ignore"):
        pen = np.where(behind > 0, behind * behind_penalty, 0.0)
    cost = sum(terms.values()) + pen
    cost = np.where(np.isnan(cost), np.inf, cost)
    if return_details:
        return cost, {**terms, "behind": behind}
    return cost


def outline_term(obs: Observations, candidates: np.ndarray, outline_sigma_m: float = OUTLINE_SIGMA_M) -> np.ndarray:
    """(M,) the outline term of the ``lidarcam`` cost alone, ``0.5 sum_k (o_k / outline_sigma)^2``: what the cost
    adds to its ``with_outline=False`` lower bound."""
    _, on_exact, _ = obs.derived("score.evidence_constants", evidence_constants)
    out = in_chunks(lambda C: outside_outlines(obs, C)[:, on_exact], obs, candidates) / outline_sigma_m
    return 0.5 * np.sum(out**2, axis=1)


def lidarcam_residuals(obs: Observations, T_lidar_cam: np.ndarray, *, range_sigma_m: float = DEFAULT_RANGE_SIGMA_M,
                       edge_sigma_m: float = EDGE_SIGMA_M, outline_sigma_m: float = OUTLINE_SIGMA_M,
                       behind_penalty: float = np.inf, **lower) -> np.ndarray:
    """The residual vector of the ``lidarcam`` cost at one extrinsic (its squared norm / 2 is the cost without the
    implausible-board penalty, which is not a residual): range residuals / sigma, endpoint errors / edge sigma,
    outline distances / outline sigma, the chord and margin residuals, the prior's. A (M,4,4) batch of extrinsics
    gives (M, n), one row each."""
    T = np.asarray(T_lidar_cam, float)
    C = T.reshape(-1, 4, 4)
    rng, edge, out, low, pri, _ = _evidence(obs, C, range_sigma_m, edge_sigma_m, outline_sigma_m, **lower)
    res = np.concatenate([rng, edge, out, low, pri], axis=1)
    return res[0] if T.ndim == 2 else res
