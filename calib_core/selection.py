"""Selection among candidate extrinsics: interchangeable scorers, each returning a cost (lower is better).

A scorer is ``f(obs, candidates (M,4,4) T_lidar_cam, **options) -> (M,) cost``. ``point_to_plane`` is
Vasconcelos' choice; ``peng2022`` is the paper's uncertainty-weighted joint likelihood of the point-line
error (METHOD.md eq. 1-12), returned as minus its log; ``lidarcam`` is ours: a negative log-likelihood that
uses all the evidence (every scan point's range residual, both endpoints against the board edges, scan points
inside the board outline, boards in front of the camera).
"""

from __future__ import annotations

import numpy as np
from scipy.special import logsumexp

from .errors import CalibrationError
from .observations import Observations
from .residuals import ScanData

EDGE_SIGMA_M = 0.03
"""Scale (metres) of the endpoint-against-edge term of the ``lidarcam`` score: absorbs the range noise and the beam
spacing at the board edges (0.25 deg at 5 m is 22 mm)."""

OUTLINE_SIGMA_M = 0.03
"""Scale (metres) of the points-inside-the-outline term of the ``lidarcam`` score."""


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
        a = np.array([obs.boards[i].outline for i in idx])                  # (n,V,2) vertices q_k, z = 0
        edge = np.roll(a, -1, axis=1) - a                                    # q_{k+1} - q_k
        L = np.linalg.norm(edge, axis=-1)                                    # (n,V)
        nrm = np.stack([-edge[..., 1], edge[..., 0]], axis=-1) / L[..., None]  # in-plane edge normals
        Pi = P[:, idx]
        xy, z2 = Pi[..., :2], Pi[..., 2:3] ** 2                               # (M,n,2,2), (M,n,2,1)
        # |p - q_k| from the expansion |xy|^2 - 2 xy.q_k + |q_k|^2 + z^2; |p - q_{k+1}| is its roll
        d2 = (np.sum(xy**2, axis=-1)[..., None] - 2 * np.einsum("mnkc,nvc->mnkv", xy, a)
              + np.sum(a**2, axis=-1)[None, :, None, :] + z2)
        da = np.sqrt(np.maximum(d2, 0.0))                                    # (M,n,2,V)
        err = da + np.roll(da, -1, axis=-1) - L[None, :, None, :]
        perp = np.einsum("mnkc,nvc->mnkv", xy, nrm) - np.sum(a * nrm, axis=-1)[None, :, None, :]
        dist = np.sqrt(perp**2 + z2)                                         # point-to-line distances
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


def range_distances(obs: Observations, candidates: np.ndarray) -> np.ndarray:
    """(M,K) range residuals (metres) of every scan point under every candidate: measured range minus the range at
    which its beam meets its board plane (as ``calib_core.residuals.range_residuals``).

    The point-to-plane distance is the range residual times ``m . b`` (plane normal in the lidar frame dot beam);
    beams nearly parallel to a candidate's plane get residuals of a kilometre or more rather than inf.
    """
    data = ScanData.from_observations(obs)
    m = np.einsum("mab,nb->mna", candidates[:, :3, :3], data.normals)[:, data.board]   # (M,K,3)
    b = data.points / np.linalg.norm(data.points, axis=1, keepdims=True)
    mb = np.einsum("mka,ka->mk", m, b)
    mb = np.where(np.abs(mb) < 1e-6, np.copysign(1e-6, mb), mb)
    return plane_distances(obs, candidates) / mb


def points_in_boards(obs: Observations, candidates: np.ndarray) -> list[np.ndarray]:
    """Per board, (M,K_i,3) its scan points in the board frame under every candidate (as ``endpoints_in_board``)."""
    R, t = candidates[:, :3, :3], candidates[:, :3, 3]
    out = []
    for b in obs.boards:
        p_C = np.einsum("mba,mkb->mka", R, b.scan_3d[None] - t[:, None, :])
        out.append(np.einsum("ba,mkb->mka", b.T_cam_board[:3, :3], p_C - b.T_cam_board[:3, 3]))
    return out


def outside_outline(xy: np.ndarray, outline: np.ndarray) -> np.ndarray:
    """Distance (metres) of 2D points ``xy`` (...,2) outside the simple polygon ``outline`` (V,2); 0 inside."""
    a, b = outline, np.roll(outline, -1, axis=0)                                # edges a_k -> b_k
    ab = b - a
    w = xy[..., None, :] - a                                                    # (...,V,2)
    s = np.clip(np.einsum("...vc,vc->...v", w, ab) / np.sum(ab**2, axis=1), 0.0, 1.0)
    dist = np.linalg.norm(w - s[..., None] * ab, axis=-1).min(axis=-1)
    x, y = xy[..., 0, None], xy[..., 1, None]                                   # even-odd rule
    crosses = (a[:, 1] > y) != (b[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        x_at = a[:, 0] + (y - a[:, 1]) * ab[:, 0] / ab[:, 1]
    inside = np.sum(crosses & (x < x_at), axis=-1) % 2 == 1
    return np.where(inside, 0.0, dist)


def lidarcam(obs: Observations, candidates: np.ndarray, *, sigma_m: float = 0.02, edge_sigma_m: float = EDGE_SIGMA_M,
             outline_sigma_m: float = OUTLINE_SIGMA_M, behind_penalty: float = np.inf, return_details: bool = False):
    """Our selection cost: a negative log-likelihood over all the evidence, per candidate (lower is better).

    ``cost = 0.5 sum_k (e_k / sigma)^2 + 0.5 sum_{i,end} (d_{i,end} / edge_sigma)^2 + 0.5 sum_k (o_k / outline_sigma)^2
    + behind_penalty * (boards behind the camera)`` with ``e_k`` the range residual of every scan point against
    its board plane, ``d`` the point-line errors of the two endpoints of every board (METHOD.md eq. 8-12), ``o_k``
    the distance of every scan point, mapped into its board's frame, outside the board outline, and a board
    "behind the camera" when the centroid of its scan points mapped into the camera frame has depth <= 0.

    Args:
        sigma_m: range-noise std (metres).
        edge_sigma_m, outline_sigma_m: scales (metres) of the endpoint and outline terms; they absorb the
            range noise and the beam spacing at the board edges (0.25 deg at 5 m is 22 mm).
        behind_penalty: cost per board behind the camera (inf: such a candidate is never chosen).
    Returns:
        (M,) cost; with ``return_details`` also a dict of the four terms, each (M,).
    """
    candidates = np.asarray(candidates, float).reshape(-1, 4, 4)
    rng_term = 0.5 * np.sum((range_distances(obs, candidates) / sigma_m) ** 2, axis=1)
    edge_term = 0.5 * np.sum((point_line_errors(obs, candidates) / edge_sigma_m) ** 2, axis=(1, 2))
    out_term = np.zeros(len(candidates))
    behind = np.zeros(len(candidates))
    R, t = candidates[:, :3, :3], candidates[:, :3, 3]
    for b, P in zip(obs.boards, points_in_boards(obs, candidates), strict=True):
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


def lidarcam_residuals(obs: Observations, T_lidar_cam: np.ndarray, *, sigma_m: float = 0.02,
                       edge_sigma_m: float = EDGE_SIGMA_M, outline_sigma_m: float = OUTLINE_SIGMA_M) -> np.ndarray:
    """The residual vector of the ``lidarcam`` cost at one extrinsic (its squared norm / 2 is the cost without the
    behind-the-camera penalty): range residuals / sigma, endpoint errors / edge sigma, outline distances / outline
    sigma."""
    C = np.asarray(T_lidar_cam, float)[None]
    parts = [range_distances(obs, C)[0] / sigma_m, point_line_errors(obs, C)[0].ravel() / edge_sigma_m]
    parts += [outside_outline(P[0, :, :2], b.outline) / outline_sigma_m
              for b, P in zip(obs.boards, points_in_boards(obs, C), strict=True)]
    return np.concatenate(parts)


PENG2022_OPTIONS = ("delta_m", "normalise_candidates", "beta_norm", "beta_eps", "error", "weighting")
"""The options of the ``peng2022`` scorer (the paper's readings); their defaults are in its signature."""

SCORERS = {"point_to_plane": point_to_plane, "peng2022": peng2022, "lidarcam": lidarcam}
