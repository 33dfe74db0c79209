"""Zhang & Pless 2004: the linear solution of the lidar-camera extrinsic from plane-line pairs.

Zhang, Q., Pless, R., "Extrinsic calibration of a camera and laser range finder (improves camera
calibration)", IROS 2004. With ``p_C = Phi p_L + Delta`` and scan points ``(x, y, 0)``, write
``Phi p_L + Delta = H (x, y, 1)^T`` with ``H = [phi1 phi2 Delta]``; every scan point on board i gives one
linear equation ``N_i^T H (x, y, 1)^T = |N_i|^2`` with ``N_i = d_i n_i`` (camera frame, metres).
"""

from __future__ import annotations

from enum import StrEnum

import numpy as np

from ..data.observations import Observations
from ..errors import SolveFailure
from ..geometry.transforms import invert_T, make_T, project_to_so3

MIN_BOARDS = 5


class Weighting(StrEnum):
    """How Zhang & Pless's linear equations are weighted: ``paper`` (``N_i^T H q = |N_i|^2`` as printed) or
    ``unit`` (each divided by ``|N_i| = 1/d_i``: every equation in metres)."""

    PAPER = "paper"
    UNIT = "unit"


def _equations(obs: Observations, weighting: Weighting | str) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per board, the rows (K_i,9) and right-hand sides (K_i,) of the equations ``N_i^T H q = |N_i|^2`` (``"paper"``)
    or ``n_i^T H q = d_i`` (``"unit"``), the coefficient of ``H[j,l]`` being ``N_j q_l``, ``q = (x, y, 1)``."""
    if weighting not in tuple(Weighting):
        raise ValueError(f"weighting must be one of {', '.join(Weighting)}, got {weighting!r}")
    n, d = obs.planes_cam()
    out = []
    for i, b in enumerate(obs.boards):
        q = np.column_stack([b.scan, np.ones(len(b.scan))])           # (K,3) = (x, y, 1)
        N = d[i] * n[i] if weighting == Weighting.PAPER else n[i]
        out.append((np.einsum("j,kl->kjl", N, q).reshape(len(q), 9),
                    np.full(len(q), N @ N if weighting == Weighting.PAPER else d[i])))
    return out


def linear_H(obs: Observations, *, weighting: Weighting | str = Weighting.PAPER) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares ``H`` (3x3) and the singular values of the scaled design matrix.

    ``weighting="paper"`` uses the equations ``N_i^T H q = |N_i|^2`` as printed; ``"unit"`` divides each by
    ``|N_i|`` (``n_i^T H q = d_i``: every equation is a point-to-plane distance in metres).
    """
    eqs = _equations(obs, weighting)
    A, y = np.concatenate([a for a, _ in eqs]), np.concatenate([r for _, r in eqs])
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    h, *_ = np.linalg.lstsq(A / scale, y, rcond=None)
    sv = np.linalg.svd(A / scale, compute_uv=False)
    return (h / scale).reshape(3, 3), sv


def linear_subsets(obs: Observations, subsets: np.ndarray, *, rank_tol: float = 1e-9) -> tuple[np.ndarray,
                                                                                                np.ndarray]:
    """The linear Zhang & Pless solution on each of many board subsets at once, ``subsets`` (S,N) bool (each of
    at least ``MIN_BOARDS`` boards): (S,4,4) ``T_lidar_cam`` and (S,) whether the subset's system has full rank
    (``rank_tol`` on the singular-value ratio, as ``zhang_pless_linear``). The equations are those of
    ``zhang_pless_linear`` (paper weighting), solved through their normal equations summed per board (the same
    least-squares solution; the squared condition number is harmless for starting points)."""
    eqs = _equations(obs, "paper")
    G = np.array([a.T @ a for a, _ in eqs])                                 # (N,9,9) per-board Gram matrices
    g = np.array([a.T @ r for a, r in eqs])                                 # (N,9)
    GS, gS = np.einsum("sn,nij->sij", subsets, G), subsets.astype(float) @ g
    scale = np.sqrt(np.einsum("sii->si", GS))
    scale[scale == 0] = 1.0
    GS = GS / scale[:, :, None] / scale[:, None, :]
    ev = np.linalg.eigvalsh(GS)                                             # squared singular values, ascending
    full = np.sqrt(np.maximum(ev[:, 0], 0.0)) >= rank_tol * np.sqrt(ev[:, -1])
    A = np.where(full[:, None, None], GS, np.eye(9))
    try:
        h = np.linalg.solve(A, (gS / scale)[..., None])[..., 0] / scale
    except np.linalg.LinAlgError:   # a subset past the rank test yet exactly singular: not of full rank after all
        h = np.zeros((len(A), 9))
        for s, (a, b) in enumerate(zip(A, gS / scale, strict=True)):
            try:
                h[s] = np.linalg.solve(a, b) / scale[s]
            except np.linalg.LinAlgError:
                full[s], h[s] = False, np.eye(3).ravel()
    H = h.reshape(-1, 3, 3)
    phi1, phi2, Delta = H[..., 0], H[..., 1], H[..., 2]
    Phi = project_to_so3(np.stack([phi1, phi2, np.cross(phi1, phi2)], axis=-1))
    return invert_T(make_T(Phi, Delta)), full


def zhang_pless_linear(obs: Observations, *, weighting: Weighting | str = Weighting.PAPER,
                       rank_tol: float = 1e-9) -> np.ndarray:
    """The linear Zhang & Pless solution as ``T_lidar_cam`` (4x4), ``Phi`` projected onto SO(3).

    Raises SolveFailure for fewer than 5 boards or a rank-deficient system (e.g. all boards parallel).
    """
    if obs.n_boards < MIN_BOARDS:
        raise SolveFailure(f"zhang_pless needs at least {MIN_BOARDS} boards, got {obs.n_boards}")
    H, sv = linear_H(obs, weighting=weighting)
    if sv[-1] < rank_tol * sv[0]:
        raise SolveFailure(f"degenerate board set: the linear system is rank deficient "
                           f"(singular value ratio {sv[-1] / sv[0]:.1e}); boards parallel or too few poses")
    phi1, phi2, Delta = H[:, 0], H[:, 1], H[:, 2]
    Phi = project_to_so3(np.column_stack([phi1, phi2, np.cross(phi1, phi2)]))
    return invert_T(make_T(Phi, Delta))
