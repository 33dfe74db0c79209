"""Selection among candidate extrinsics: interchangeable scorers, each returning a cost (lower is better).

A scorer is ``f(obs, candidates (M,4,4) T_lidar_cam, **options) -> (M,) cost``. ``point_to_plane`` is
Vasconcelos' choice; ``peng2022`` is the paper's uncertainty-weighted joint likelihood of the point-line
error (docs/METHOD.md eq. 1-12), returned as minus its log; ``lidarcam`` is ours: a negative log-likelihood that
uses all the evidence (every scan point's range residual, both endpoints against the board edges, scan points
inside the board outline, boards in front of the camera).
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

from ..data.observations import Observations
from ..data.residuals import (
    candidate_chunk,
    in_chunks,
    outside_outline,
    plane_residuals,
    point_line_errors,
    points_in_boards,
    range_residuals,
)
from ..data.result import SolveFailure
from ..errors import CalibrationError

EDGE_SIGMA_M = 0.03
"""Scale (metres) of the endpoint-against-edge term of the ``lidarcam`` score: absorbs the range noise and the beam
spacing at the board edges (0.25 deg at 5 m is 22 mm)."""

OUTLINE_SIGMA_M = 0.03
"""Scale (metres) of the points-inside-the-outline term of the ``lidarcam`` score."""


def exact_outline_boards(obs: Observations) -> np.ndarray:
    """Indices of the boards whose outline is exact: the only ones the endpoint and outline terms read (a
    ``lower_bound`` outline lets the scan run past it, ``none`` says nothing)."""
    return np.flatnonzero(obs.exact_outlines)


def peng2022_outline_warnings(obs: Observations) -> list[str]:
    """The paper's point-line term needs every board's edges: ``SolveFailure`` naming the field when a board has
    none (``outline_kind`` ``none``); a warning when some outlines are only lower bounds (the paper's model is
    kept, and assumes they are the edges)."""
    kinds = [b.outline_kind for b in obs.boards]
    none = [i for i, k in enumerate(kinds) if k == "none"]
    if none:
        raise SolveFailure(f"peng2022: the point-line error needs the board edges, but boards {none} have "
                           "outline_kind 'none' (no outline)")
    low = [i for i, k in enumerate(kinds) if k == "lower_bound"]
    if not low:
        return []
    return [f"peng2022: boards {low} have outline_kind 'lower_bound' (the physical board may be larger); the "
            "paper's point-line error assumes the outline is the edge the lidar meets"]


def point_to_plane(obs: Observations, candidates: np.ndarray) -> np.ndarray:
    """Sum of squared point-to-plane distances (m^2) of all scan points over all boards, per candidate."""
    return in_chunks(lambda C: np.sum(plane_residuals(C, obs.scan_data) ** 2, axis=1), obs, candidates)


def peng2022(obs: Observations, candidates: np.ndarray, *, delta_m: float = 0.030,
             normalise_candidates: bool = True, beta_norm: str = "sum", beta_eps: float = 1e-12,
             error: str = "point_line", weighting: str = "uncertainty", return_details: bool = False):
    """Minus the log of the paper's uncertainty-weighted joint likelihood (docs/METHOD.md eq. 1-6), per candidate.

    Args:
        delta_m: ``delta`` of eq. 1 in metres (the paper's 30 mm).
        normalise_candidates: eq. 2, normalise ``pi_{j,i}`` over the candidates of each board.
        beta_norm: how ``beta_i = O_i U_i`` is normalised: ``"sum"`` (to one), ``"max"``, ``"none"``.
        beta_eps: zero guard; ``beta_i`` below it (relative to its normaliser) is raised to it.
        error: ``"point_line"`` (the paper: two endpoint errors per board) or ``"point_plane"`` (the
            distances of all that board's points to its plane; an ablation).
        weighting: ``"uncertainty"`` (exponent ``1/beta_i``) or ``"equal"`` (all exponents 1; an ablation).
    Returns:
        (M,) cost ``-log pi_j``; with ``return_details`` also a dict of ``log_pi`` (M,N), ``O``, ``U``,
        ``beta`` (N,).
    """
    M = len(candidates)
    if error == "point_line":
        peng2022_outline_warnings(obs)
        sq = in_chunks(lambda C: np.sum(point_line_errors(obs, C) ** 2, axis=-1), obs, candidates)  # (M,N)
    elif error == "point_plane":
        data = obs.scan_data
        sq = in_chunks(lambda C: np.stack([np.sum(plane_residuals(C, data)[:, data.board == i] ** 2, axis=1)
                                           for i in range(obs.n_boards)], axis=1), obs, candidates)
    else:
        raise CalibrationError(f"peng2022: error must be 'point_line' or 'point_plane', got {error!r}")
    log_pi = -sq / (2 * delta_m**2) - np.log(np.sqrt(2 * np.pi) * delta_m)               # eq. 1, (M,N)
    if normalise_candidates:
        log_pi = log_pi - logsumexp(log_pi, axis=0, keepdims=True)                      # eq. 2
    pi = np.exp(log_pi - (0 if normalise_candidates else logsumexp(log_pi, axis=0, keepdims=True)))
    with np.errstate(divide="ignore", invalid="ignore"):
        O = -np.sum(np.where(pi > 0, pi * np.log2(pi), 0.0), axis=0)                    # eq. 3, (N,)
    R = candidates[:, :3, :3]
    R_hat = R[np.argmax(log_pi, axis=0)]                                                 # (N,3,3)
    U = np.sum(pi * np.sum((R[:, None] - R_hat[None]) ** 2, axis=(-2, -1)), axis=0)      # eq. 4
    beta = O * U                                                                          # eq. 5
    if weighting == "equal":
        w = np.ones_like(beta)
    elif weighting == "uncertainty":
        if beta_norm == "sum":
            s = beta.sum()
            beta = beta / s if s > 0 else np.ones_like(beta) / len(beta)
        elif beta_norm == "max":
            s = beta.max(initial=0.0)
            beta = beta / s if s > 0 else np.ones_like(beta)
        elif beta_norm != "none":
            raise CalibrationError(f"peng2022: beta_norm must be 'sum', 'max' or 'none', got {beta_norm!r}")
        w = 1.0 / np.maximum(beta, beta_eps)
    else:
        raise CalibrationError(f"peng2022: weighting must be 'uncertainty' or 'equal', got {weighting!r}")
    cost = -(log_pi @ w)                                                                  # eq. 6, log space
    if M and not np.all(np.isfinite(cost)):
        cost = np.where(np.isfinite(cost), cost, np.inf)
    if return_details:
        return cost, {"log_pi": log_pi, "O": O, "U": U, "beta": beta}
    return cost


def lidarcam(obs: Observations, candidates: np.ndarray, *, range_sigma_m: float = 0.02,
             edge_sigma_m: float = EDGE_SIGMA_M, outline_sigma_m: float = OUTLINE_SIGMA_M,
             behind_penalty: float = np.inf, return_details: bool = False):
    """Our selection cost: a negative log-likelihood over all the evidence, per candidate (lower is better).

    ``cost = 0.5 sum_k (e_k / sigma)^2 + 0.5 sum_{i,end} (d_{i,end} / edge_sigma)^2 + 0.5 sum_k (o_k / outline_sigma)^2
    + behind_penalty * (boards behind the camera)`` with ``e_k`` the range residual of every scan point against
    its board plane, ``d`` the point-line errors of the two endpoints of every board (docs/METHOD.md eq. 8-12), ``o_k``
    the distance of every scan point, mapped into its board's frame, outside the board outline (``d`` and ``o`` on
    boards with an exact outline only, ``exact_outline_boards``), and a board
    "behind the camera" when the centroid of its scan points mapped into the camera frame has depth <= 0.

    Args:
        range_sigma_m: range-noise std (metres).
        edge_sigma_m, outline_sigma_m: scales (metres) of the endpoint and outline terms; they absorb the
            range noise and the beam spacing at the board edges (0.25 deg at 5 m is 22 mm).
        behind_penalty: cost per board behind the camera (inf: such a candidate is never chosen).
    Returns:
        (M,) cost; with ``return_details`` also a dict of the four terms, each (M,).
    """
    candidates = np.asarray(candidates, float).reshape(-1, 4, 4)
    if len(candidates) > candidate_chunk(obs):  # bounded memory: score the candidates in chunks
        opts = {"range_sigma_m": range_sigma_m, "edge_sigma_m": edge_sigma_m, "outline_sigma_m": outline_sigma_m,
                "behind_penalty": behind_penalty}
        out = in_chunks(lambda C: lidarcam(obs, C, **opts, return_details=True), obs, candidates)
        return out if return_details else out[0]
    rng_term = 0.5 * np.sum((range_residuals(candidates, obs.scan_data) / range_sigma_m) ** 2, axis=1)
    exact = exact_outline_boards(obs)
    edge_term = 0.5 * np.sum((point_line_errors(obs, candidates)[:, exact] / edge_sigma_m) ** 2, axis=(1, 2))
    out_term = np.zeros(len(candidates))
    behind = np.zeros(len(candidates))
    R, t = candidates[:, :3, :3], candidates[:, :3, 3]
    for b, P in zip(obs.boards, points_in_boards(obs, candidates), strict=True):
        if b.outline_exact:
            out_term += 0.5 * np.sum((outside_outline(P[..., :2], b.outline) / outline_sigma_m) ** 2, axis=1)
        depth = np.einsum("ma,ma->m", R[:, :, 2], b.scan_3d.mean(axis=0) - t)   # z of R^T (c - t)
        behind += depth <= 0
    with np.errstate(invalid="ignore"):
        pen = np.where(behind > 0, behind * behind_penalty, 0.0)
    cost = rng_term + edge_term + out_term + pen
    cost = np.where(np.isnan(cost), np.inf, cost)
    if return_details:
        return cost, {"range": rng_term, "edge": edge_term, "outline": out_term, "behind": behind}
    return cost


def lidarcam_residuals(obs: Observations, T_lidar_cam: np.ndarray, *, range_sigma_m: float = 0.02,
                       edge_sigma_m: float = EDGE_SIGMA_M, outline_sigma_m: float = OUTLINE_SIGMA_M) -> np.ndarray:
    """The residual vector of the ``lidarcam`` cost at one extrinsic (its squared norm / 2 is the cost without the
    behind-the-camera penalty): range residuals / sigma, endpoint errors / edge sigma, outline distances / outline
    sigma. A (M,4,4) batch of extrinsics gives (M, n), one row each."""
    T = np.asarray(T_lidar_cam, float)
    C = T.reshape(-1, 4, 4)
    parts = [range_residuals(C, obs.scan_data) / range_sigma_m,
             point_line_errors(obs, C)[:, exact_outline_boards(obs)].reshape(len(C), -1) / edge_sigma_m]
    parts += [outside_outline(P[..., :2], b.outline) / outline_sigma_m
              for b, P in zip(obs.boards, points_in_boards(obs, C), strict=True) if b.outline_exact]
    out = np.concatenate(parts, axis=1)
    return out[0] if T.ndim == 2 else out


PENG2022_OPTIONS = ("delta_m", "normalise_candidates", "beta_norm", "beta_eps", "error", "weighting")
"""The options of the ``peng2022`` scorer (the paper's readings); their defaults are in its signature."""

SCORERS = {"point_to_plane": point_to_plane, "peng2022": peng2022, "lidarcam": lidarcam}
