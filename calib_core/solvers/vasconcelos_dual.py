"""Vasconcelos 2012 in the dual-space formulation of the authors' MATLAB: the same minimal problem and, for real
roots, the same solutions as ``solvers.vasconcelos``; it exists for the candidates built from complex roots.

The authors' P3P keeps the real part of every quartic root; a non-real root gives no exact solution, and which
approximate candidate it yields depends on the formulation (the unknown of the quartic, how the depths and the pose
follow from it).  ``vasconcelos_msac`` reproduces their selection, so its candidates are built their way (facts of
their algorithm, our vectorised code), in their frame and units: millimetres, scan plane at z = 10 mm.

Per triple (boards 1, 2, 3; pairs ordered 12, 13, 23):

1. Planes as dual points ``a_i = -n_i / d_i`` (``a . p + 1 = 0``); scan lines as Plucker lines ``(u_i, m_i)`` with
   moment ``m_i = u_i x p_i`` (``p_i = (x, y, 10)``).
2. A P3P with rays ``k_ij = a_i x a_j`` (camera side, the direction of the line where planes i and j meet) and
   points ``P_ij = l_ij / l_ij,z``, ``l_ij = m_i x m_j`` (laser side: the scan lines' meeting point ``q_ij`` scaled
   to z = 1).  Grunert's quartic in ``v = s_3 / s_1`` (Haralick et al. 1994), labels as above; every root's real
   part; ``u = s_2 / s_1`` by Grunert's division, ``s_1`` from the side ``b``; the mirrored depths ``-s`` as well
   (all roots first, then all mirrors).
3. The rotation that best maps the points ``P`` onto ``s k`` (Kabsch; Horn's quaternion gives the same), ``R_h``;
   the candidate's rotation is ``R_h^T``.
4. The translation by least squares on the planes: each rotated camera plane ``r_i = R_h^T a_i`` is met, in the
   dual space, by the line through the origin along ``r_i / r_i,z`` and the board's dual scan line
   ``{a : a . p_i + 1 = 0, a . u_i = 0}``; their least-squares meeting point ``l_i`` must equal the translated
   plane, ``l_i (1 - t . r_i) = r_i``: nine homogeneous equations ``[-l_i r_i^T, l_i - r_i] (t, 1) = 0``, solved by
   SVD.
"""

from __future__ import annotations

import numpy as np

from ._common import (
    REASON_NONFINITE,
    REASON_PLANES,
    REASON_SCAN_LINES,
    SCAN_LINE_PAIRS,
    MinimalSolutions,
    grunert_quartic,
    plane_sv_min,
    prologue,
)
from .orientation import cross, dot, kabsch
from .polynomial import Quartic, newton_roots, quartic_roots

SCAN_PLANE_Z_MM = 10.0


def _closest_point(U: np.ndarray, C: np.ndarray, W: np.ndarray) -> np.ndarray:
    """Least-squares meeting point (...,3) of the lines ``C + s U`` and ``s W`` (through the origin)."""
    def proj(v):
        v = v / np.linalg.norm(v, axis=-1, keepdims=True)
        return np.eye(3) - v[..., :, None] * v[..., None, :]

    Pu = proj(U)
    return np.linalg.solve(Pu + proj(W), np.einsum("...ij,...j->...i", Pu, C)[..., None])[..., 0]


def _translation_mm(R: np.ndarray, a: np.ndarray, u3: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Step 4: the translation (K,3) in millimetres of our frame (scan plane z = 0) of rotations R (K,3,3), from
    the dual plane points ``a``, the scan lines' directions ``u3`` and moments ``m`` (K,3,3)."""
    r = np.einsum("kij,knj->kni", R, a)                                       # rotated camera planes
    C = cross(u3, m) / np.sum(m**2, axis=-1, keepdims=True)                   # dual lines' closest points
    lpt = _closest_point(m, C, r / r[..., 2:])
    M = np.concatenate([-lpt[..., :, None] * r[..., None, :], (lpt - r)[..., None]], axis=-1).reshape(-1, 9, 4)
    V = np.linalg.svd(M)[2][:, -1]
    t = V[:, :3] / V[:, 3:]
    t[:, 2] -= SCAN_PLANE_Z_MM
    return t


def solve_triples(n: np.ndarray, d: np.ndarray, p: np.ndarray, u: np.ndarray, *, real_parts: bool = True,
                  imag_tol: float = 1e-8, min_plane_sv: float = 1e-3, min_line_sin: float = 1e-3,
                  quartic: Quartic | str = Quartic.EIG, root_newton_iters: int = 2) -> MinimalSolutions:
    """Every candidate ``T_lidar_cam`` of B plane-line triples in the authors' dual formulation (module docstring).

    Same inputs as ``solvers.vasconcelos.solve_triples`` (camera planes ``n . p = d`` in metres, scan lines in the
    scan plane in metres); ``real_parts`` keeps a candidate per complex-conjugate pair of roots (marked
    ``near_real``), as the authors' code does.  Candidates are returned in our frame (scan plane z = 0, metres).
    """
    reasons, idx, n, d, p, u = prologue(n, d, p, u, quartic)
    sv = plane_sv_min(n)
    ui, uj = u[:, SCAN_LINE_PAIRS[:, 0]], u[:, SCAN_LINE_PAIRS[:, 1]]
    sin = np.abs(ui[..., 0] * uj[..., 1] - ui[..., 1] * uj[..., 0])
    bad_planes, bad_lines = ~(sv >= min_plane_sv), ~(sin.min(axis=1) >= min_line_sin)
    reasons[idx[bad_lines]] = REASON_SCAN_LINES
    reasons[idx[bad_planes]] = REASON_PLANES
    through = ~(np.abs(d).min(axis=1) > 0)          # a plane through the camera centre has no dual point
    reasons[idx[through & ~bad_planes & ~bad_lines]] = REASON_NONFINITE
    ok = ~(bad_planes | bad_lines | through)
    idx, n, d, p, u = idx[ok], n[ok], d[ok], p[ok], u[ok]

    a = -n / (1e3 * d)[..., None]                                             # (K,3,3) dual points, 1/mm
    p3 = np.concatenate([1e3 * p, np.full(p.shape[:2] + (1,), SCAN_PLANE_Z_MM)], axis=2)
    u3 = np.concatenate([u, np.zeros(u.shape[:2] + (1,))], axis=2)
    m = cross(u3, p3)                                                         # Plucker moments
    k = cross(a[:, SCAN_LINE_PAIRS[:, 0]], a[:, SCAN_LINE_PAIRS[:, 1]])                          # rays k_12, k_13, k_23
    k = k / np.linalg.norm(k, axis=-1, keepdims=True)
    mn = m / np.linalg.norm(m, axis=-1, keepdims=True)
    ll = cross(mn[:, SCAN_LINE_PAIRS[:, 0]], mn[:, SCAN_LINE_PAIRS[:, 1]])
    P = ll / ll[..., 2:]                                                      # (K,3,3) points P_12, P_13, P_23
    ca, cb, cg = dot(k[:, 1], k[:, 2]), dot(k[:, 0], k[:, 2]), dot(k[:, 0], k[:, 1])
    sa = np.linalg.norm(P[:, 1] - P[:, 2], axis=-1)
    sb = np.linalg.norm(P[:, 0] - P[:, 2], axis=-1)
    sc = np.linalg.norm(P[:, 0] - P[:, 1], axis=-1)
    scale = (sa + sb + sc) / 3.0
    sa, sb, sc = sa / scale, sb / scale, sc / scale
    A = grunert_quartic(sa**2, sb**2, sc**2, ca, cb, cg)
    A = A / np.abs(A).max(axis=1, keepdims=True)
    roots = quartic_roots(A, quartic)
    roots = newton_roots(A, roots, root_newton_iters)
    real = np.abs(roots.imag) <= imag_tol * (1.0 + np.abs(roots))
    near = ~real & (roots.imag > 0) if real_parts else np.zeros_like(real)
    kt, slot = np.nonzero(real | near)
    v = roots.real[kt, slot]
    amc = (sa[kt] ** 2 - sc[kt] ** 2) / sb[kt] ** 2
    cak, cbk, cgk = ca[kt], cb[kt], cg[kt]
    with np.errstate(divide="ignore", invalid="ignore"):
        uu = ((1 - amc) * v**2 + 2 * amc * cbk * v - 1 - amc) / (2 * v * cak - 2 * cgk)
    s1 = np.sqrt(sb[kt] ** 2 / (1 + v**2 - 2 * v * cbk)) * scale[kt]
    s = np.stack([s1, uu * s1, v * s1], axis=-1)                               # (R,3)
    # per triple, every root in ascending order (``unique``), then every mirror (the authors' order)
    order = np.lexsort((v, kt))
    kt, s, near_k = kt[order], s[order], near[kt[order], slot[order]]
    groups = np.r_[0, np.flatnonzero(np.diff(kt)) + 1, len(kt)]
    sel = np.concatenate([np.r_[np.arange(g0, g1), np.arange(g0, g1)] for g0, g1 in zip(groups[:-1], groups[1:],
                                                                                        strict=True)]).astype(int)
    sign = np.concatenate([np.r_[np.ones(g1 - g0), -np.ones(g1 - g0)] for g0, g1 in zip(groups[:-1], groups[1:],
                                                                                         strict=True)])
    kt, s, near_k = kt[sel], s[sel] * sign[:, None], near_k[sel]
    finite = np.isfinite(s).all(axis=1)
    kt, s, near_k = kt[finite], s[finite], near_k[finite]

    Rh, _ = kabsch(P[kt], s[:, :, None] * k[kt])                             # maps P onto s k
    R = np.swapaxes(Rh, 1, 2)
    t = _translation_mm(R, a[kt], u3[kt], m[kt])
    return MinimalSolutions.pack(R, t / 1e3, idx[kt], idx, reasons, near_k)
