"""Selection among candidate extrinsics: interchangeable scorers, each returning a cost (lower is better).

A scorer is ``f(obs, candidates (M,4,4) T_lidar_cam, **options) -> (M,) cost``. ``point_to_plane`` is
Vasconcelos' choice; ``peng2022`` is the paper's uncertainty-weighted joint likelihood of the point-line
error (docs/METHOD.md eq. 1-12), returned as minus its log; ``lidarcam`` is ours: a negative log-likelihood that
uses all the evidence (every scan point's range residual, both endpoints against the board edges, scan points
inside the board outline, boards in front of the camera: ``model.score.evidence_cost``).
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

from ..data.observations import Observations
from ..errors import CalibrationError, SolveFailure
from ..model.residuals import in_chunks, plane_residuals, point_line_errors
from ..model.score import evidence_cost


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


PENG_BLOCK_ELEMENTS = 2_000_000
"""Budget (array elements) of one block of the ``peng2022`` scorer: its largest temporary is (B,N,3,3) over B
candidates and N boards, so memory stays bounded whatever the number of triples."""
PENG_KEEP_ELEMENTS = 64_000_000
"""Up to this many (candidate, board) squared errors are kept between the scorer's passes (512 MB); beyond, each pass
recomputes them block by block (bounded memory, the same numbers)."""


def _peng_sq_errors(obs: Observations, error: str):
    """``f(C (B,4,4)) -> (B,N)``: each board's squared error under each candidate, for ``peng2022``."""
    if error == "point_line":
        peng2022_outline_warnings(obs)
        return lambda C: in_chunks(lambda c: np.sum(point_line_errors(obs, c) ** 2, axis=-1), obs, C)
    if error == "point_plane":
        data = obs.scan_data
        return lambda C: in_chunks(lambda c: np.stack([np.sum(plane_residuals(c, data)[:, data.board == i] ** 2,
                                                              axis=1) for i in range(obs.n_boards)], axis=1), obs, C)
    raise CalibrationError(f"peng2022: error must be 'point_line' or 'point_plane', got {error!r}")


def _peng_blocks(obs: Observations, candidates: np.ndarray, sq_errors, delta_m: float):
    """``log_pi(k)``: eq. 1's (B,N) log-likelihoods of block ``k`` of the candidates, and the blocks (slices);
    kept between calls when they fit ``PENG_KEEP_ELEMENTS``, else recomputed."""
    M, N = len(candidates), obs.n_boards
    step = max(1, PENG_BLOCK_ELEMENTS // max(1, 9 * N))
    blocks = [slice(i, i + step) for i in range(0, M, step)] or [slice(0, 0)]

    def compute(k):
        return -sq_errors(candidates[blocks[k]]) / (2 * delta_m**2) - np.log(np.sqrt(2 * np.pi) * delta_m)

    if M * N > PENG_KEEP_ELEMENTS:
        return compute, blocks
    kept = [compute(k) for k in range(len(blocks))]
    return kept.__getitem__, blocks


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

    The candidates are scored in blocks (``PENG_BLOCK_ELEMENTS``) over three passes (each board's normaliser and
    best candidate; eq. 3-4; eq. 6), so memory is bounded; with one block the arithmetic is that of one pass,
    with several the normaliser's sum is accumulated block by block (rounding-level differences).
    """
    candidates = np.asarray(candidates, float).reshape(-1, 4, 4)
    if weighting not in ("uncertainty", "equal"):
        raise CalibrationError(f"peng2022: weighting must be 'uncertainty' or 'equal', got {weighting!r}")
    if weighting == "uncertainty" and beta_norm not in ("sum", "max", "none"):
        raise CalibrationError(f"peng2022: beta_norm must be 'sum', 'max' or 'none', got {beta_norm!r}")
    log_pi_of, blocks = _peng_blocks(obs, candidates, _peng_sq_errors(obs, error), delta_m)
    lse, arg = _peng_normaliser(log_pi_of, blocks, obs.n_boards, normalise_candidates)
    R = candidates[:, :3, :3]
    R_hat = R[arg]                                                                       # (N,3,3)
    O = np.zeros(obs.n_boards)
    U = np.zeros(obs.n_boards)
    for k, sl in enumerate(blocks):
        pi = np.exp(log_pi_of(k) - lse)                                                  # eq. 2
        with np.errstate(divide="ignore", invalid="ignore"):
            O -= np.sum(np.where(pi > 0, pi * np.log2(pi), 0.0), axis=0)                 # eq. 3, (N,)
        U += np.sum(pi * np.sum((R[sl][:, None] - R_hat[None]) ** 2, axis=(-2, -1)), axis=0)  # eq. 4
    beta = O * U                                                                          # eq. 5
    if weighting == "equal":
        w = np.ones_like(beta)
    else:
        s = {"sum": beta.sum(), "max": beta.max(initial=0.0), "none": 1.0}[beta_norm]
        if beta_norm != "none":
            beta = beta / s if s > 0 else np.ones_like(beta) / (len(beta) if beta_norm == "sum" else 1)
        w = 1.0 / np.maximum(beta, beta_eps)
    shift = lse if normalise_candidates else 0.0
    log_pi = [log_pi_of(k) - shift for k in range(len(blocks))] if return_details else None
    cost = np.concatenate([-((log_pi[k] if log_pi else log_pi_of(k) - shift) @ w)        # eq. 6, log space
                           for k in range(len(blocks))])
    if len(candidates) and not np.all(np.isfinite(cost)):
        cost = np.where(np.isfinite(cost), cost, np.inf)
    if return_details:
        return cost, {"log_pi": np.concatenate(log_pi), "O": O, "U": U, "beta": beta}
    return cost


def _peng_normaliser(log_pi_of, blocks, N: int, normalise: bool):
    """Per board over all candidates: eq. 2's normaliser ``logsumexp`` (1,N) and the index of the candidate
    of largest likelihood (normalised when ``normalise``; the first one on ties)."""
    if len(blocks) == 1:
        lp = log_pi_of(0)
        lse = logsumexp(lp, axis=0, keepdims=True)
        return lse, (np.argmax(lp - lse if normalise else lp, axis=0) if len(lp) else np.zeros(N, int))
    best, total, arg = np.full(N, -np.inf), np.zeros(N), np.zeros(N, int)
    for sl, k in zip(blocks, range(len(blocks)), strict=True):
        lp = log_pi_of(k)
        j = np.argmax(lp, axis=0)
        m = lp[j, np.arange(N)]
        arg = np.where(m > best, sl.start + j, arg)
        new = np.maximum(best, m)
        with np.errstate(invalid="ignore"):
            total = total * np.where(np.isfinite(best), np.exp(best - new), 0.0) + np.sum(np.exp(lp - new), axis=0)
        best = new
    return (best + np.log(total))[None], arg


PENG2022_OPTIONS = ("delta_m", "normalise_candidates", "beta_norm", "beta_eps", "error", "weighting")
"""The options of the ``peng2022`` scorer (the paper's readings); their defaults are in its signature."""

SCORERS = {"point_to_plane": point_to_plane, "peng2022": peng2022, "lidarcam": evidence_cost}
