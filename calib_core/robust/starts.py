"""The start rules every choice of starts shares (the consensus search and the refinement): when two extrinsics are
distinct starts (``distinct_order``, ``near_any``), and where a start heads (``gauss_newton_steps``, the basin test:
a start that lands within the distinct-start rule of an optimum already found is in its basin)."""

from __future__ import annotations

import numpy as np

from ..model.residuals import perturb, range_residuals

DISTINCT_ROT_DEG = 1.0
"""Two extrinsics are distinct starts when they differ by at least this rotation (degrees) ..."""
DISTINCT_TRANS_M = 0.05
"""... or this translation (metres); the one rule for every choice of starts (consensus and refinement)."""
BASIN_STEPS = 2
"""Gauss-Newton steps that tell where a start heads (``gauss_newton_steps``): a start that lands within the
distinct-start rule (``DISTINCT_ROT_DEG``, ``DISTINCT_TRANS_M``) of an optimum already found is in its basin and is
not optimised again."""
BASIN_DAMPING = 1e-12
"""The basin test's normal equations are damped by this times their mean diagonal: the step stays finite along a
direction the boards leave free (where it is not a test of anything)."""


def distinct_order(T: np.ndarray, cost: np.ndarray, n: int, rot_deg: float = DISTINCT_ROT_DEG,
                   trans_m: float = DISTINCT_TRANS_M) -> list[int]:
    """Indices of the ``n`` lowest finite ``cost`` among (M,4,4) ``T`` that differ pairwise by at least
    ``rot_deg`` of rotation or ``trans_m`` of translation, best first."""
    out: list[int] = []
    for j in np.argsort(cost, kind="stable"):
        if not np.isfinite(cost[j]) or len(out) >= n:
            break
        if out and near_any(T[j], T[out], rot_deg, trans_m):
            continue
        out.append(int(j))
    return out


def near_any(A: np.ndarray, K: np.ndarray, rot_deg: float = DISTINCT_ROT_DEG,
             trans_m: float = DISTINCT_TRANS_M) -> bool:
    """Whether the extrinsic ``A`` (4,4) is within ``rot_deg`` of rotation and ``trans_m`` of translation of one of
    ``K`` (k,4,4): the distinct-start rule."""
    cos = (np.einsum("ab,kab->k", A[:3, :3], K[:, :3, :3]) - 1.0) / 2.0         # cos of the relative angle
    near = (cos > np.cos(np.radians(rot_deg))) & (np.linalg.norm(K[:, :3, 3] - A[:3, 3], axis=1) < trans_m)
    return bool(near.any())


def gauss_newton_steps(data, T0: np.ndarray, boards: np.ndarray | None = None, n: int = BASIN_STEPS) -> np.ndarray:
    """The extrinsics ``n`` Gauss-Newton steps on the range residuals (of the scan points of ``boards``, (N,) or
    (M,N) bool; default all) take ``T0`` (4,4) or (M,4,4) to, all starts at once: where refining each heads (each
    step solves the 6x6 normal equations, damped by ``BASIN_DAMPING``: a test of where a start heads, not an
    estimate)."""
    T = np.asarray(T0, float)
    w = np.ones(len(data.points)) if boards is None else np.asarray(boards)[..., data.board].astype(float)
    w = np.broadcast_to(w, T.shape[:-2] + w.shape[-1:])
    for _ in range(n):
        e, J = range_residuals(T, data, jacobian=True)
        Jw = np.swapaxes(J * w[..., None], -1, -2)
        JtJ = Jw @ J
        damp = BASIN_DAMPING * np.trace(JtJ, axis1=-2, axis2=-1)[..., None, None] / 6 * _EYE6
        T = perturb(T, -np.linalg.solve(JtJ + damp, (Jw @ e[..., None]))[..., 0])
    return T


_EYE6 = np.eye(6)
_EYE6.setflags(write=False)  # ``gauss_newton_steps``' identity, built once
