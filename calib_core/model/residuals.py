"""The one home of the residuals of an extrinsic against the boards: range and point-to-plane residuals of every
scan point (batched over candidate extrinsics, and with analytic Jacobians at one extrinsic), the endpoint-to-edge
errors of each board's scan and the distances of scan points outside the board outline.

Parameterisation: ``T_lidar_cam = (exp([w]x) R0, t0 + dt)``, a left perturbation of the rotation in the
lidar frame; the 6 parameters are ``x = (w, dt)`` (radians, metres). Board planes are given in the camera
frame (``n . p_C = d``); in the lidar frame the plane of board i is ``m . p_L = d + m . t`` with ``m = R n``.
"""

from __future__ import annotations

import functools
from enum import StrEnum

import numpy as np

from ..data.observations import Observations, ScanData
from ..geometry.transforms import rotvec_to_matrix
from .outline_distance import outside_outline


def perturb(T0: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``T_lidar_cam`` at parameters ``x = (w, dt)`` around ``T0`` (left rotation perturbation); one (4,4) and (6,),
    or a batch (M,4,4) and (M,6)."""
    T = np.array(T0, float)
    T[..., :3, :3] = rotvec_to_matrix(x[..., :3]) @ T[..., :3, :3]
    T[..., :3, 3] += x[..., 3:]
    return T


CHUNK_ELEMENTS = 4_000_000
"""Budget (array elements) of one batch of candidates: scorers work on candidates in chunks of
``candidate_chunk`` so that memory stays bounded whatever the number of candidates, points and vertices."""


def candidate_chunk(obs: Observations) -> int:
    """How many candidates one batch holds within ``CHUNK_ELEMENTS`` (the largest temporaries are (M,K,3) over
    the scan points and (M,N,2,V,V) over endpoint-edge pairs)."""
    K = sum(len(b.scan) for b in obs.boards)
    V = max((len(b.outline) for b in obs.boards if b.outline is not None), default=0)
    return max(1, CHUNK_ELEMENTS // max(1, 3 * K + 2 * obs.n_boards * V * V))


def in_chunks(fn, obs: Observations, candidates: np.ndarray):
    """``fn(candidates)`` evaluated chunk by chunk (``candidate_chunk``) and concatenated along the first axis;
    ``fn`` returns an array, or a (array, dict of arrays) pair."""
    C = np.asarray(candidates, float).reshape(-1, 4, 4)
    step = candidate_chunk(obs)
    if len(C) <= step:
        return fn(C)
    parts = [fn(C[i:i + step]) for i in range(0, len(C), step)]
    if isinstance(parts[0], tuple):
        return (np.concatenate([p[0] for p in parts]),
                {k: np.concatenate([p[1][k] for p in parts]) for k in parts[0][1]})
    return np.concatenate(parts)


MIN_BEAM_INCIDENCE = 1e-6
"""|cos| of the angle between a beam and its board's normal below which the range residual is clamped: beams
nearly parallel to a candidate's plane get residuals of a kilometre or more rather than inf."""


def _planes_lidar(T: np.ndarray, data: ScanData):
    """Per point, the board normal ``m = R n`` (...,K,3) and plane offset ``d + m . t`` (...,K) in the lidar frame;
    ``T`` is one (4,4) or a batch (M,4,4) of ``T_lidar_cam``."""
    R, t = T[..., :3, :3], T[..., :3, 3]
    m = data.normals @ R.swapaxes(-1, -2)                                 # (...,N,3) rows R n
    c = data.offsets + (m @ t[..., None])[..., 0]                             # (...,N)
    return m.take(data.board, axis=-2), c.take(data.board, axis=-1)


def plane_residuals(T: np.ndarray, data: ScanData, jacobian: bool | str = False):
    """Signed point-to-plane distances (metres) of every scan point to its board plane, in the lidar frame.

    ``e_k = m_i . (p_k - t) - d_i`` with ``m_i = R n_i``. ``T``: one (4,4) ``T_lidar_cam`` -> (K,), or a batch
    (M,4,4) -> (M,K). With ``jacobian`` (one ``T`` only), also (K,6) de/d(w, dt) at ``T`` (``"later"``: a function
    of no arguments giving it).
    """
    mk, c = _planes_lidar(T, data)
    e = np.einsum("...kj,kj->...k", mk, data.points) - c
    if not jacobian:
        return e
    J = functools.partial(_plane_jacobian, T, mk, data.points)
    return e, (J if jacobian == "later" else J())


def _plane_jacobian(T: np.ndarray, mk: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``plane_residuals``' Jacobian (K,6) at one ``T`` from its lidar-frame normals ``mk`` (K,3) and scan points."""
    return np.concatenate([np.cross(mk, points - T[:3, 3]), -mk], axis=1)


def range_residuals(T: np.ndarray, data: ScanData, jacobian: bool | str = False):
    """Range residuals (metres): measured range minus the range at which the beam meets its board plane.

    The lidar noise is along each beam, so this is the likelihood's residual. Beam ``b = p/|p|``, measured
    range ``r = |p|``, predicted ``r* = (d_i + m_i . t) / (m_i . b)``; ``e = r - r*`` (``m . b`` clamped at
    ``MIN_BEAM_INCIDENCE``). ``T``: one (4,4) -> (K,), or a batch (M,4,4) -> (M,K). With ``jacobian``, also
    (K,6) de/d(w, dt), or (M,K,6) for a batch; with ``jacobian="later"``, a function of no arguments giving it
    (the same numbers, computed only when asked: a rejected step of an optimisation needs none).
    """
    mk, num = _planes_lidar(T, data)
    r, b = data.ranges, data.beams
    mb = np.einsum("...kj,kj->...k", mk, b)
    small = np.abs(mb) < MIN_BEAM_INCIDENCE
    if small.any():                                                           # rare: clamp only then
        mb = np.where(small, np.copysign(MIN_BEAM_INCIDENCE, mb), mb)
    r_star = num / mb
    e = r - r_star
    if not jacobian:
        return e
    J = functools.partial(_range_jacobian, T, mk, mb, r_star, b)
    return e, (J if jacobian == "later" else J())


def _range_jacobian(T: np.ndarray, mk: np.ndarray, mb: np.ndarray, r_star: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``range_residuals``' Jacobian (...,K,6) from its normals ``mk``, ``m . b``, predicted ranges and beams."""
    # with dm = w x m: d(num)/dw = m x t and d(mb)/dw = m x b, so de/dw = (m x b num / mb - m x t) / mb
    # = m x (p* - t) / mb, with p* = (num / mb) b the point where the beam meets the plane; de/d(dt) = -m / mb
    p_t = r_star[..., None] * b - T[..., None, :3, 3]                                  # p* - t
    J = np.empty(mk.shape[:-1] + (6,))  # p_t has mk's shape
    _cross_into(J[..., :3], mk, p_t)
    np.negative(mk, out=J[..., 3:])
    J /= mb[..., None]
    return J


def range_linearised(T: np.ndarray, data: ScanData) -> tuple[np.ndarray, np.ndarray]:
    """``range_residuals(T, data, jacobian=True)`` at one (4,4) ``T``, read-only and kept on ``data`` for the last
    ``T`` asked: the final checks of an answer (covariance, degeneracy, conditioning) all linearise at it."""
    T = np.ascontiguousarray(T, float)
    kept = data.__dict__.get("_range_linearised")
    if kept is not None and kept[0] == T.tobytes():
        return kept[1], kept[2]
    e, J = range_residuals(T, data, jacobian=True)
    e.setflags(write=False)
    J.setflags(write=False)
    data.__dict__["_range_linearised"] = (T.tobytes(), e, J)
    return e, J


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (...,3) arrays (``np.cross`` without its axis handling, on the hot path)."""
    return _cross_into(np.empty(np.broadcast_shapes(a.shape, b.shape)), a, b)


def _cross_into(out: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``_cross(a, b)`` written into ``out`` (...,3), which it returns."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out[..., 0], out[..., 1], out[..., 2] = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    return out


class Residual(StrEnum):
    """Which residual a refinement minimises: along the beam (the range-noise likelihood) or to the plane."""

    RANGE = "range"
    PLANE = "plane"


RESIDUALS = {Residual.PLANE: plane_residuals, Residual.RANGE: range_residuals}


def endpoints_in_board(obs: Observations, candidates: np.ndarray, frames: tuple | None = None) -> np.ndarray:
    """(M,N,2,3) first and last scan point of each board in that board's frame, per candidate.

    ``p_W = Phi_i^T (R_j^T (p_L - t_j) - Delta_i)`` (docs/METHOD.md eq. 7), metres (``board_frames``; ``frames``:
    theirs, when the caller has them).
    """
    A, c = given_frames(obs, candidates, 3, frames)
    return scan_endpoints(obs)[None] @ A.swapaxes(-1, -2) + c[:, :, None, :]


def scan_endpoints(obs: Observations) -> np.ndarray:
    """(N,2,3) first and last scan point of every board (lidar frame, metres); computed once per observation set."""
    return obs.derived("residuals.endpoints", lambda o: np.array([[b.scan_3d[0], b.scan_3d[-1]]
                                                                  for b in o.boards]).reshape(-1, 2, 3))


def _board_poses(obs: Observations) -> tuple[np.ndarray, np.ndarray]:
    """(N,3,3) ``Phi_i^T`` and (N,3) ``Phi_i^T Delta_i`` of every board (``T_cam_board = (Phi_i, Delta_i)``)."""
    T = np.array([b.T_cam_board for b in obs.boards]).reshape(-1, 4, 4)
    Pt = np.swapaxes(T[:, :3, :3], -1, -2)
    return Pt, (Pt @ T[:, :3, 3, None])[..., 0]


def board_frames(obs: Observations, candidates: np.ndarray, rows: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """The affine map of lidar points into each board's frame under every candidate ``T_lidar_cam`` (M,4,4):
    (M,N,rows,3) ``A`` and (M,N,rows) ``c`` with ``p_W = A p_L + c = Phi_i^T (R^T (p_L - t) - Delta_i)`` (its
    first ``rows`` coordinates), so ``A = Phi_i^T R^T`` and ``c = -A t - Phi_i^T Delta_i``."""
    Pt, PtD = obs.derived("residuals.board_poses", _board_poses)
    R, t = candidates[:, :3, :3], candidates[:, :3, 3]
    A = Pt[None, :, :rows] @ R.swapaxes(-1, -2)[:, None]                  # (M,N,rows,3)
    return A, -(A @ t[:, None, :, None])[..., 0] - PtD[None, :, :rows]


def given_frames(obs: Observations, candidates: np.ndarray, rows: int, frames: tuple | None) -> tuple:
    """``board_frames(obs, candidates, rows)``, or its first ``rows`` rows of ``frames`` when the caller has them."""
    if frames is None:
        return board_frames(obs, candidates, rows)
    return frames[0][:, :, :rows], frames[1][:, :, :rows]


def _board_slices(obs: Observations) -> list[slice]:
    """Each board's rows of ``obs.scan_data`` (the scans are concatenated in board order)."""
    ends = np.cumsum([len(b.scan) for b in obs.boards])
    return [slice(int(e - len(b.scan)), int(e)) for e, b in zip(ends, obs.boards, strict=True)]


def _edge_groups(obs: Observations) -> list[tuple]:
    """Per vertex count V of the boards' outlines: the boards (n,), their vertices ``q_k`` and unit in-plane edge
    normals one after the other (n,2V,2), edge lengths (1,n,1,V), ``q_k . normal_k`` and ``|q_k|^2`` (each
    (1,n,1,V)), the vertices in the board frame (n,V,3) (z = 0), the next vertex's index (V,) and the vertex
    indices (V,)."""
    counts = np.array([0 if b.outline is None else len(b.outline) for b in obs.boards])
    groups = []
    for V in np.unique(counts[counts > 0]):
        idx = np.flatnonzero(counts == V)
        a = np.array([obs.boards[i].outline for i in idx], float)           # (n,V,2) vertices q_k, z = 0
        edge = np.roll(a, -1, axis=1) - a                                    # q_{k+1} - q_k
        L = np.linalg.norm(edge, axis=-1)
        nrm = np.stack([-edge[..., 1], edge[..., 0]], axis=-1) / L[..., None]
        groups.append((idx, np.concatenate([a, nrm], axis=1), L[None, :, None], np.sum(a * nrm, axis=-1)[None, :, None],
                       np.sum(a**2, axis=-1)[None, :, None], np.concatenate([a, np.zeros(a.shape[:2] + (1,))], -1),
                       np.arange(1, V + 1) % V, np.arange(V)))
    return groups


def point_line_errors(obs: Observations, candidates: np.ndarray, gradient: bool | str = False,
                      frames: tuple | None = None, ends: np.ndarray | None = None):
    """(M,N,2) point-line errors (metres) of the two scan endpoints of every board (docs/METHOD.md eq. 8-12);
    with ``gradient`` also (M,N,2,3) their gradients in the endpoints' board-frame coordinates (the pairing of
    endpoints with edges held fixed: it is piecewise constant); ``gradient="later"``: a function of no arguments
    giving them. ``frames``: the candidates' ``board_frames``;
    ``ends``: the (M,N,2,3) endpoints in their boards' frames (``endpoints_in_board``), when the caller has them.

    Each endpoint is paired with the board edge nearest to it (point-to-line distance), the two endpoints
    with different edges (the pair of distinct edges with the least summed distance). The error of an
    endpoint ``p`` against edge ``q_k q_{k+1}`` is ``|p - q_k| + |p - q_{k+1}| - |q_{k+1} - q_k|``, zero
    exactly when ``p`` lies on the edge segment. Boards of different outlines are handled one outline
    shape at a time (vectorised over candidates and boards that share a vertex count). Every outline is read
    as given, whatever its ``outline_kind``; a board without one (kind ``none``) gets 0.
    """
    P = endpoints_in_board(obs, candidates, frames) if ends is None else ends  # (M,N,2,3)
    M, N = P.shape[:2]
    out, kept = np.zeros((M, N, 2)), []
    for idx, a_nrm2, L, a_nrm, a2, a3, nxt, vertex in obs.derived("residuals.edge_vertex_groups", _edge_groups):
        V, n = len(nxt), len(idx)
        Pi = P if n == N else P[:, idx]                                      # one group: every board, in order
        xy, z2 = Pi[..., :2], Pi[..., 2:3] ** 2                               # (M,n,2,2), (M,n,2,1)
        xy_q = np.einsum("mnkc,nvc->mnkv", xy, a_nrm2)                       # xy . q_k, then xy . normal_k
        # |p - q_k| from the expansion |xy|^2 - 2 xy.q_k + |q_k|^2 + z^2; |p - q_{k+1}| is its roll
        d2 = (xy[..., 0] ** 2 + xy[..., 1] ** 2)[..., None] - 2 * xy_q[..., :V] + a2 + z2
        da = np.sqrt(np.maximum(d2, 0.0))                                    # (M,n,2,V)
        db = da[..., nxt]                                                    # |p - q_{k+1}|
        err = da + db - L
        dist = np.sqrt((xy_q[..., V:] - a_nrm) ** 2 + z2)                    # point-to-line distances
        pair = dist[:, :, 0, :, None] + dist[:, :, 1, None, :]              # (M,n,V,V)
        pair[..., vertex, vertex] = np.inf                                   # the two edges differ
        k = np.empty((M, n, 2), int)                                         # each endpoint's edge
        k[..., 0], k[..., 1] = np.divmod(pair.reshape(M, n, V * V).argmin(axis=-1), V)
        at = k.ravel() + np.arange(0, err.size, V)                           # flat index of each one's edge
        out[:, idx] = err.ravel()[at].reshape(M, n, 2)
        if gradient:
            kept.append((idx, Pi, a3, k, nxt, da.ravel()[at], db.ravel()[at]))
    if not gradient:
        return out
    grad = functools.partial(_edge_gradients, (M, N, 2, 3), kept)
    return out, (grad if gradient == "later" else grad())


def _edge_gradients(shape: tuple, kept: list[tuple]) -> np.ndarray:
    """``point_line_errors``' gradients (M,N,2,3) from each vertex-count group's boards, board-frame endpoints
    (M,n,2,3), vertices (n,V,3), paired edges (M,n,2), next-vertex map and distances to the paired edge's two
    vertices (M*n*2,)."""
    grad = np.zeros(shape)
    M = shape[0]
    for idx, Pi, a3, k, nxt, da, db in kept:  # d|p - q_k|/dp = (p - q_k) / |p - q_k|, over the edge's two vertices
        n = len(idx)
        board = np.arange(n)[:, None]
        d_a = np.maximum(da, 1e-300).reshape(M, n, 2, 1)
        d_b = np.maximum(db, 1e-300).reshape(M, n, 2, 1)
        grad[:, idx] = (Pi - a3[board, k]) / d_a + (Pi - a3[board, nxt[k]]) / d_b
    return grad


def take_last(a: np.ndarray, k: np.ndarray) -> np.ndarray:
    """``np.take_along_axis(a, k, axis=-1)`` for ``k`` of ``a``'s shape but its last axis (the same numbers, with
    less overhead on the small arrays of the hot path)."""
    flat = a.reshape(-1, a.shape[-1])
    return flat[np.arange(len(flat))[:, None], k.reshape(len(flat), -1)].reshape(k.shape)


def points_in_boards(obs: Observations, candidates: np.ndarray) -> list[np.ndarray]:
    """Per board, (M,K_i,3) its scan points in the board frame under every candidate (as ``endpoints_in_board``)."""
    A, c = board_frames(obs, candidates)
    return [b.scan_3d @ np.swapaxes(A[:, i], -1, -2) + c[:, i, None] for i, b in enumerate(obs.boards)]


def outline_groups(obs: Observations, kind: str = "exact") -> list[tuple[np.ndarray, np.ndarray]]:
    """(board indices, outline) of each distinct outline of ``outline_kind`` ``kind`` among the boards (boards
    sharing one outline are handled at once); computed once per observation set and kind."""
    return obs.derived(f"residuals.outline_groups.{kind}", lambda o: _outline_groups(o, kind))


def _outline_groups(obs: Observations, kind: str) -> list[tuple[np.ndarray, np.ndarray]]:
    groups: dict[bytes, list[int]] = {}
    for i, b in enumerate(obs.boards):
        if b.outline_kind == kind and b.outline is not None:
            groups.setdefault(np.ascontiguousarray(b.outline).tobytes() + bytes([len(b.outline)]), []).append(i)
    return [(np.array(idx), obs.boards[idx[0]].outline) for idx in groups.values()]


def scan_points_in_boards(obs: Observations, candidates: np.ndarray, rows: int = 3,
                          frames: tuple | None = None) -> np.ndarray:
    """(M,K,rows) every scan point (in ``obs.scan_data`` order) in its own board's frame under every candidate:
    ``p_W = Phi_i^T (R^T (p_L - t) - Delta_i)`` (metres; its first ``rows`` coordinates, ``board_frames``;
    ``frames``: theirs, of at least ``rows`` rows, when the caller has them)."""
    A, c = given_frames(obs, candidates, rows, frames)
    points = obs.scan_data.points
    out = np.empty((len(candidates), len(points), rows))
    for i, sl in enumerate(obs.derived("residuals.board_slices", _board_slices)):
        out[:, sl] = points[sl] @ A[:, i].swapaxes(-1, -2) + c[:, i, None]
    return out


def outside_outlines(obs: Observations, candidates: np.ndarray, gradient: bool | str = False,
                     frames: tuple | None = None, points: np.ndarray | None = None):
    """(M,K) distance (metres) of every scan point outside its board's exact outline under every candidate (0
    inside, and on boards without an exact outline; ``outside_outline`` per group of boards sharing one); with
    ``gradient`` also (M,K,2) its gradient in the point's board-frame (x, y) (``"later"``: a function of no
    arguments giving it). ``frames``: the candidates' ``board_frames``; ``points``: the (M,K,2) points in their
    boards' frames, when the caller has them."""
    P = scan_points_in_boards(obs, candidates, rows=2, frames=frames) if points is None else points
    groups = obs.derived("residuals.outline_point_groups", _outline_point_groups)
    if len(groups) == 1 and groups[0][0].all():                             # one outline for every board
        return outside_outline(P, groups[0][1], gradient=gradient)
    out, parts = np.zeros(P.shape[:2]), []
    for sel, outline in groups:
        if gradient:
            out[:, sel], g = outside_outline(P[:, sel], outline, gradient="later")
            parts.append((sel, g))
        else:
            out[:, sel] = outside_outline(P[:, sel], outline)
    if not gradient:
        return out
    grad = functools.partial(_outline_gradients, P.shape, parts)
    return out, (grad if gradient == "later" else grad())


def _outline_gradients(shape: tuple, parts: list[tuple]) -> np.ndarray:
    """``outside_outlines``' gradient (M,K,2) from each group's scan-point mask and ``outside_outline`` gradient
    function."""
    grad = np.zeros(shape)
    for sel, g in parts:
        grad[:, sel] = g()
    return grad


def _outline_point_groups(obs: Observations) -> list[tuple[np.ndarray, np.ndarray]]:
    """(scan-point mask, outline) of each group of ``outline_groups``."""
    return [(np.isin(obs.scan_data.board, idx), outline) for idx, outline in outline_groups(obs)]


def board_frame_rows(obs: Observations, T: np.ndarray, points: np.ndarray, board: np.ndarray,
                     g: np.ndarray, frames: tuple | None = None) -> np.ndarray:
    """(K,6) rows ``g_k . d p_W,k / d x`` of the chain rule through the board frame: lidar points ``points`` (K,3)
    of boards ``board`` (K,) under one ``T_lidar_cam`` ``T``, ``g`` (K,r) the gradients in the first r board-frame
    coordinates, ``x = (w, dt)`` the module's left perturbation. With ``A = Phi^T R^T`` (``board_frames``; ``frames``:
    those of ``T[None]``, when the caller has them), ``d p_W / d x = A [[p_L - t]_x, -I]``, so the row is
    ``(v x (p_L - t), -v)`` with ``v = A^T g``."""
    A = given_frames(obs, T[None], g.shape[1], frames)[0][0][board]                 # (K,r,3)
    v = g[:, 0, None] * A[:, 0]
    for r in range(1, g.shape[1]):                                                # the sum over the r coordinates
        v = v + g[:, r, None] * A[:, r]
    rows = np.empty((len(v), 6))
    _cross_into(rows[:, :3], v, points - T[:3, 3])
    np.negative(v, out=rows[:, 3:])
    return rows
