"""Zhou 2014 minimal solver: every extrinsic T_lidar_cam from three plane-line pairs, vectorised over triples.

Paper: L. Zhou, "A new minimal solution for the extrinsic calibration of a 2D LIDAR and a camera using three
plane-line correspondences", IEEE Sensors Journal 14(2), 2014.  The derivation below is ours (docs/zhou2014.md
gives it step by step); it follows the algebra the title and abstract describe.

Frames and unknowns: ``p_L = R p_C + t`` (``T_lidar_cam``).  A scan point ``(x, y)`` of the scan plane (z = 0 of the
lidar) is, in the camera frame, ``p_C = x q1 + y q2 + s`` with ``q1, q2`` the first two rows of ``R`` (the lidar's
x and y axes in the camera frame, ``Q = [q1 q2]``) and ``s = -R^T t`` the lidar origin in the camera frame.

1. Board i's plane ``n_i . p_C = d_i`` contains its scan line ``p_i + lambda u_i``, so for every lambda
   ``n_i^T Q u_i = 0`` (direction) and ``n_i^T Q p_i + n_i . s = d_i`` (point).
2. The three direction equations are linear and homogeneous in the six entries of ``Q``: ``M vec(Q) = 0`` with
   rows ``(u_i1 n_i^T, u_i2 n_i^T)``; generically a three-dimensional null space, ``vec(Q) = K alpha``
   (``K`` 6x3 with orthonormal columns, ``alpha`` in R^3).
3. Orthonormality of ``q1, q2``: ``|q1|^2 = |q2|^2 = 1``, ``q1 . q2 = 0``.  As ``K^T K = I``,
   ``|q1|^2 + |q2|^2 = |alpha|^2``, so the system is two homogeneous conics ``alpha^T C1 alpha = 0``
   (``C1 = 2 K1^T K1 - I``, i.e. ``|q1|^2 = |q2|^2``) and ``alpha^T C2 alpha = 0`` (``C2 = sym(K1^T K2)``) with the
   scale ``|alpha|^2 = 2``.  Two conics meet in four points of the projective plane (Bezout), each fixing
   ``alpha`` up to sign: up to 8 real solutions (``-alpha`` is the rotation by pi about the lidar's z axis).
4. The four points: eliminating the first coordinate of ``alpha`` (the Sylvester resultant of the two conics
   as quadratics in it) leaves a quartic in the ratio of the other two; its roots in closed form (Ferrari), each
   polished by Newton steps, then the eliminated coordinate from the pair's linear combination, and Newton
   steps on the three equations in ``alpha``.
5. ``R`` has rows ``q1, q2, q1 x q2``; the point equations are then linear in ``s``: ``N s = d - (n_i^T Q p_i)_i``
   (``N`` the normals as rows), and ``t = -R s``.

Degenerate (refused with a reason): planes that do not meet in one point (``N`` singular: neither the null space
of step 2 nor ``s`` is then determined) and conics that share a component (the quartic vanishes: infinitely
many rotations).  Unlike Vasconcelos' P3P, concurrent or parallel scan lines are not singular here; with all three
scan lines parallel the orthonormality cannot hold and there is no real solution.
"""

from __future__ import annotations

import numpy as np

from ._common import REASON_PLANES, MinimalSolutions, plane_sv_min, prologue
from .orientation import cross
from .polynomial import Quartic, keep_better, newton_roots, quartic_roots

REASON_CONICS = "the orthonormality conics share a component (quartic vanishes: infinitely many rotations)"



def _pmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Product of batched polynomials (K,m), (K,n) (highest first) -> (K,m+n-1)."""
    out = np.zeros(a.shape[:1] + (a.shape[1] + b.shape[1] - 1,), dtype=np.result_type(a, b))
    for i in range(a.shape[1]):
        out[:, i:i + b.shape[1]] += a[:, i, None] * b
    return out


def _resultant_quartic(C1: np.ndarray, C2: np.ndarray) -> np.ndarray:
    """Quartic (K,5) in ``w = alpha_1 / alpha_2`` whose roots are the conics' common points with ``alpha_0``
    eliminated: each conic is ``a x^2 + b x + c`` in ``x = alpha_0`` (at ``alpha = (x, w, 1)``), and the
    Sylvester resultant of two quadratics is ``(a1 c2 - a2 c1)^2 - (a1 b2 - a2 b1)(b1 c2 - b2 c1)``."""
    def abc(C):
        return (C[:, 0, 0][:, None], 2.0 * np.stack([C[:, 0, 1], C[:, 0, 2]], -1),
                np.stack([C[:, 1, 1], 2.0 * C[:, 1, 2], C[:, 2, 2]], -1))

    a1, b1, c1 = abc(C1)
    a2, b2, c2 = abc(C2)
    P1 = a1 * c2 - a2 * c1                          # (K,3)
    P2 = a1 * b2 - a2 * b1                          # (K,2)
    P3 = _pmul(b1, c2) - _pmul(b2, c1)              # (K,4)
    return _pmul(P1, P1) - _pmul(P2, P3)


def _polish_alpha(alpha: np.ndarray, C1: np.ndarray, C2: np.ndarray, iters: int) -> np.ndarray:
    """Newton steps (K,3) on ``(alpha^T C1 alpha, alpha^T C2 alpha, |alpha|^2 - 2) = 0``; a step is kept only
    where it lowers the residual."""
    def resid(a):
        return np.stack([np.einsum("ki,kij,kj->k", a, C1, a), np.einsum("ki,kij,kj->k", a, C2, a),
                         np.einsum("ki,ki->k", a, a) - 2.0], axis=-1)

    f = resid(alpha)
    fn = np.einsum("ki,ki->k", f, f)
    for _ in range(iters):
        J = 2.0 * np.stack([np.einsum("kij,kj->ki", C1, alpha), np.einsum("kij,kj->ki", C2, alpha), alpha], axis=1)
        det = np.linalg.det(J)
        ok = np.abs(det) > 1e-300
        Js = np.where(ok[:, None, None], J, np.eye(3))
        step = np.where(ok[:, None], np.linalg.solve(Js, f[..., None])[..., 0], 0.0)
        a_new = alpha - step
        alpha, f, fn = keep_better(alpha, f, fn, a_new, resid)
    return alpha


def _conics(n: np.ndarray, u: np.ndarray):
    """Step 2-3: the null-space basis K (K,6,3) of the direction equations and the conics C1, C2 (K,3,3)."""
    M = np.concatenate([u[:, :, :1] * n, u[:, :, 1:] * n], axis=2)           # (K,3,6)
    Kb = np.swapaxes(np.linalg.svd(M, full_matrices=True)[2][:, 3:, :], 1, 2)  # (K,6,3)
    K1, K2 = Kb[:, :3], Kb[:, 3:]
    C1 = 2.0 * np.swapaxes(K1, 1, 2) @ K1 - np.eye(3)
    G12 = np.swapaxes(K1, 1, 2) @ K2
    return Kb, C1, 0.5 * (G12 + np.swapaxes(G12, 1, 2))


def _common_points(C1, C2, quartic: Quartic | str, root_newton_iters: int, imag_tol: float, alpha_newton_iters: int):
    """Step 4: the conics' real common points with ``|alpha|^2 = 2``: (index of the triple, alpha (R,3)) per root,
    and the mask (K,) of triples whose quartic vanishes."""
    # Eliminate the coordinate with the largest diagonal weight in the two conics (never zero in both).
    diag = (np.diagonal(C1, axis1=1, axis2=2) ** 2 + np.diagonal(C2, axis1=1, axis2=2) ** 2)
    first = np.argmax(diag, axis=1)
    perm = np.stack([first, (first + 1) % 3, (first + 2) % 3], axis=1)      # (K,3)
    rows = np.arange(len(C1))[:, None, None]
    P1 = C1[rows, perm[:, :, None], perm[:, None, :]]
    P2 = C2[rows, perm[:, :, None], perm[:, None, :]]
    A = _resultant_quartic(P1, P2)
    scale = np.abs(A).max(axis=1, keepdims=True)
    flat = ~(scale[:, 0] > 1e-12)
    A = A / np.where(scale > 0, scale, 1.0)
    rev = np.abs(A[:, 4]) > np.abs(A[:, 0])                                  # roots near infinity: use 1/w
    A = np.where(rev[:, None], A[:, ::-1], A)
    roots = quartic_roots(A, quartic)
    roots = newton_roots(A, roots, root_newton_iters)
    real = (np.abs(roots.imag) <= imag_tol * (1.0 + np.abs(roots))) & ~flat[:, None]
    k, slot = np.nonzero(real)
    w = roots.real[k, slot]
    yz = np.where(rev[k, None], np.stack([np.ones_like(w), w], -1), np.stack([w, np.ones_like(w)], -1))
    # x from  a1 * (conic 2) - a2 * (conic 1):  (a1 b2 - a2 b1) x + (a1 c2 - a2 c1) = 0.
    Q1, Q2 = P1[k], P2[k]

    def bc(C):
        b = 2.0 * (C[:, 0, 1] * yz[:, 0] + C[:, 0, 2] * yz[:, 1])
        c = np.einsum("ki,kij,kj->k", yz, C[:, 1:, 1:], yz)
        return C[:, 0, 0], b, c

    a1, b1, c1 = bc(Q1)
    a2, b2, c2 = bc(Q2)
    den = a1 * b2 - a2 * b1
    x = -(a1 * c2 - a2 * c1) / np.where(np.abs(den) > 1e-300, den, 1e-300)
    ap = np.column_stack([x, yz])
    alpha = np.empty_like(ap)
    alpha[np.arange(len(k))[:, None], perm[k]] = ap
    alpha *= np.sqrt(2.0) / np.linalg.norm(alpha, axis=1, keepdims=True)
    return k, _polish_alpha(alpha, C1[k], C2[k], alpha_newton_iters), flat


def solve_triples(n: np.ndarray, d: np.ndarray, p: np.ndarray, u: np.ndarray, *, imag_tol: float = 1e-8,
                  min_plane_sv: float = 1e-3, quartic: Quartic | str = Quartic.CLOSED, root_newton_iters: int = 2,
                  alpha_newton_iters: int = 3) -> MinimalSolutions:
    """Every real ``T_lidar_cam`` of B plane-line triples by Zhou's algebra (module docstring).

    Args:
        n: (B,3,3) normals of the three board planes in the camera frame (rows; normalised here).
        d: (B,3) plane offsets, plane ``{p_C : n . p_C = d}`` in metres (scaled with ``n``).
        p: (B,3,2) a point of each board's scan line, lidar scan-plane coordinates (x, y) in metres.
        u: (B,3,2) the direction of each scan line (normalised here).
        imag_tol: a quartic root ``w`` counts as real when ``|Im w| <= imag_tol * (1 + |w|)`` (after Newton steps).
        min_plane_sv: degenerate when the smallest singular value of the unit-normal matrix is below this.
        quartic: ``"closed"`` (Ferrari) or ``"eig"`` (companion-matrix eigenvalues).
        root_newton_iters, alpha_newton_iters: Newton steps on the quartic's roots and on the three equations.

    Returns:
        ``MinimalSolutions`` (``near_real`` all False); at most 8 candidates per triple, each root followed by its
        sign-flipped twin.
    """
    reasons, idx, n, d, p, u = prologue(n, d, p, u, quartic)
    sv_min = plane_sv_min(n)
    ok = sv_min >= min_plane_sv
    reasons[idx[~ok]] = REASON_PLANES
    idx, n, d, p, u = idx[ok], n[ok], d[ok], p[ok], u[ok]

    Kb, C1, C2 = _conics(n, u)
    k, alpha, flat = _common_points(C1, C2, quartic, root_newton_iters, imag_tol, alpha_newton_iters)
    reasons[idx[flat]] = REASON_CONICS
    alpha = np.stack([alpha, -alpha], axis=1).reshape(-1, 3)                # each root and its sign flip
    k = np.repeat(k, 2)
    q = np.einsum("kij,kj->ki", Kb[k], alpha)
    q1, q2 = q[:, :3], q[:, 3:]
    R = np.stack([q1, q2, cross(q1, q2)], axis=1)                           # rows: lidar axes in the camera frame
    Qp = q1[:, None, :] * p[k][:, :, :1] + q2[:, None, :] * p[k][:, :, 1:]  # (R,3,3): Q p_i per board
    rhs = d[k] - np.einsum("kij,kij->ki", n[k], Qp)
    s = np.linalg.solve(n[k], rhs[..., None])[..., 0]                       # lidar origin in the camera frame
    return MinimalSolutions.pack(R, -np.einsum("kij,kj->ki", R, s), idx[k], idx, reasons,
                                 np.zeros(len(k), dtype=bool))
