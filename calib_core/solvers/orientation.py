"""Absolute orientation of point sets, batched: the closed form for three points (used by the minimal solver)
and the SVD (Kabsch) reference."""

from __future__ import annotations

import numpy as np


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products of (...,3) vectors."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot products of (...,n) vectors."""
    return np.einsum("...i,...i->...", a, b)


def cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """z of the cross product of (...,2) vectors."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def abs_orientation_3pt(P: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R (K,3,3), t (K,3) with ``[q, 0] ~ R P + t`` for camera triangles P (K,3,3) and scan-plane triangles q (K,3,2).

    Closed form: align the triangles' oriented planes, then take the least-squares in-plane angle.  Equal to
    Kabsch/SVD (det +1) for congruent triangles and to first order for nearly congruent ones.  The scan
    triangle lies in z = 0, so its frame is the identity up to the sign of its orientation.
    """
    cP = P.mean(axis=1)
    Y = P - cP[:, None, :]
    a = P[:, 1] - P[:, 0]
    e1 = a / np.sqrt(np.einsum("ki,ki->k", a, a))[:, None]
    nrm = cross(a, P[:, 2] - P[:, 0])
    nrm /= np.sqrt(np.einsum("ki,ki->k", nrm, nrm))[:, None]
    e2 = cross(nrm, e1)
    xp = np.einsum("kni,ki->kn", Y, e1)
    yp = np.einsum("kni,ki->kn", Y, e2)
    cq = q.mean(axis=1)
    xq, yq = q[:, :, 0] - cq[:, :1], q[:, :, 1] - cq[:, 1:]
    sgn = np.where(cross2(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]) >= 0, 1.0, -1.0)
    yq = yq * sgn[:, None]  # coordinates in the frame (x, sgn y, sgn z), whose third axis is the normal
    sn = np.einsum("kn,kn->k", xp, yq) - np.einsum("kn,kn->k", yp, xq)
    cs = np.einsum("kn,kn->k", xp, xq) + np.einsum("kn,kn->k", yp, yq)
    h = np.hypot(sn, cs)
    h = np.where(h > 0, h, 1.0)
    co, si = (cs / h)[:, None], (sn / h)[:, None]
    R = np.empty(P.shape[:1] + (3, 3))
    R[:, 0] = co * e1 - si * e2
    R[:, 1] = sgn[:, None] * (si * e1 + co * e2)
    R[:, 2] = sgn[:, None] * nrm
    t = -np.einsum("kij,kj->ki", R, cP)
    t[:, :2] += cq
    return R, t


def kabsch(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reference absolute orientation by SVD (det fixed +1): R (K,3,3), t (K,3) minimising sum |Q - (R P + t)|^2.

    ``P, Q`` (K,n,3) corresponding point sets.  The solver uses the faster closed form for three points.
    """
    cP, cQ = P.mean(axis=1), Q.mean(axis=1)
    H = np.einsum("kni,knj->kij", P - cP[:, None], Q - cQ[:, None])
    U, _, Vt = np.linalg.svd(H)
    D = np.ones(U.shape[:-1])
    D[:, -1] = np.sign(np.linalg.det(Vt.transpose(0, 2, 1) @ U.transpose(0, 2, 1)))
    R = (Vt.transpose(0, 2, 1) * D[:, None, :]) @ U.transpose(0, 2, 1)
    return R, cQ - np.einsum("kij,kj->ki", R, cP)
