"""Selection among candidate extrinsics: interchangeable scorers, each returning a cost (lower is better).

A scorer is ``f(obs, candidates (M,4,4) T_lidar_cam, **options) -> (M,) cost``. ``point_to_plane`` is
Vasconcelos' choice; ``peng2022`` is the paper's uncertainty-weighted joint likelihood of the point-line
error (METHOD.md eq. 1-12), returned as minus its log.
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

from .errors import CalibrationError
from .observations import Observations
from .residuals import ScanData


def plane_distances(obs: Observations, candidates: np.ndarray) -> np.ndarray:
    """(M,K) signed point-to-plane distances (metres) of every scan point under every candidate."""
    data = ScanData.from_observations(obs)
    R, t = candidates[:, :3, :3], candidates[:, :3, 3]
    m = np.einsum("mab,nb->mna", R, data.normals)              # (M,N,3) normals in the lidar frame
    c = data.offsets[None, :] + np.einsum("mna,ma->mn", m, t)  # plane offsets in the lidar frame
    return np.einsum("mka,ka->mk", m[:, data.board], data.points) - c[:, data.board]


def point_to_plane(obs: Observations, candidates: np.ndarray) -> np.ndarray:
    """Sum of squared point-to-plane distances (m^2) of all scan points over all boards, per candidate."""
    return np.sum(plane_distances(obs, candidates) ** 2, axis=1)


def endpoints_in_board(obs: Observations, candidates: np.ndarray) -> np.ndarray:
    """(M,N,2,3) first and last scan point of each board in that board's frame, per candidate.

    ``p_W = Phi_i^T (R_j^T (p_L - t_j) - Delta_i)`` (METHOD.md eq. 7), metres.
    """
    ends = np.array([[b.scan_3d[0], b.scan_3d[-1]] for b in obs.boards])   # (N,2,3) lidar frame
    T_cb = np.array([b.T_cam_board for b in obs.boards])                    # (N,4,4)
    R, t = candidates[:, :3, :3], candidates[:, :3, 3]
    p_C = np.einsum("mba,mnkb->mnka", R, ends[None] - t[:, None, None, :])  # R^T (p - t)
    return np.einsum("nba,mnkb->mnka", T_cb[:, :3, :3], p_C - T_cb[None, :, None, :3, 3])


def point_line_errors(obs: Observations, candidates: np.ndarray) -> np.ndarray:
    """(M,N,2) point-line errors (metres) of the two scan endpoints of every board (METHOD.md eq. 8-12).

    Each endpoint is paired with the board edge nearest to it (point-to-line distance), the two endpoints
    with different edges (the pair of distinct edges with the least summed distance). The error of an
    endpoint ``p`` against edge ``q_k q_{k+1}`` is ``|p - q_k| + |p - q_{k+1}| - |q_{k+1} - q_k|``, zero
    exactly when ``p`` lies on the edge segment. Boards of different outlines are handled one outline
    shape at a time (vectorised over candidates and boards that share a vertex count).
    """
    P = endpoints_in_board(obs, candidates)                                 # (M,N,2,3)
    M, N = P.shape[:2]
    out = np.empty((M, N, 2))
    counts = np.array([len(b.outline) for b in obs.boards])
    for V in np.unique(counts):
        idx = np.flatnonzero(counts == V)
        q = np.array([obs.boards[i].outline for i in idx])                  # (n,V,2)
        q = np.concatenate([q, np.zeros(q.shape[:2] + (1,))], axis=2)        # z = 0
        a, b = q, np.roll(q, -1, axis=1)                                     # edges a_k -> b_k
        p = P[:, idx][:, :, :, None, :]                                      # (M,n,2,1,3)
        da = np.linalg.norm(p - a[None, :, None], axis=-1)                   # (M,n,2,V)
        db = np.linalg.norm(p - b[None, :, None], axis=-1)
        L = np.linalg.norm(b - a, axis=-1)[None, :, None]                   # (1,n,1,V)
        err = da + db - L
        e = (b - a) / L[0, :, 0, :, None]                                    # unit edge directions
        w = p - a[None, :, None]
        dist = np.linalg.norm(w - np.einsum("mnkvc,nvc->mnkv", w, e)[..., None] * e[None, :, None], axis=-1)
        pair = dist[:, :, 0, :, None] + dist[:, :, 1, None, :]              # (M,n,V,V)
        pair[..., np.arange(V), np.arange(V)] = np.inf                       # the two edges differ
        best = np.argmin(pair.reshape(M, len(idx), V * V), axis=-1)
        k0, k1 = np.divmod(best, V)
        mm, nn = np.meshgrid(np.arange(M), np.arange(len(idx)), indexing="ij")
        out[:, idx, 0] = err[mm, nn, 0, k0]
        out[:, idx, 1] = err[mm, nn, 1, k1]
    return out


def peng2022(obs: Observations, candidates: np.ndarray, *, delta_m: float = 0.030,
             normalise_candidates: bool = True, beta_norm: str = "sum", beta_eps: float = 1e-12,
             error: str = "point_line", weighting: str = "uncertainty", return_details: bool = False):
    """Minus the log of the paper's uncertainty-weighted joint likelihood (METHOD.md eq. 1-6), per candidate.

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
        sq = np.sum(point_line_errors(obs, candidates) ** 2, axis=-1)                    # (M,N)
    elif error == "point_plane":
        data = ScanData.from_observations(obs)
        e2 = plane_distances(obs, candidates) ** 2
        sq = np.stack([e2[:, data.board == i].sum(axis=1) for i in range(obs.n_boards)], axis=1)
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


SCORERS = {"point_to_plane": point_to_plane, "peng2022": peng2022}
