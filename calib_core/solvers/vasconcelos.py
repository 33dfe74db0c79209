"""Vasconcelos 2012 minimal solver: every extrinsic T_lidar_cam from three plane-line pairs, vectorised.

Equation solved (a P3P problem whose centre is the planes' common point ``O`` and whose "rays" are lines)::

    find lambda_a (a = 12, 13, 23) with  |lambda_a v_a - lambda_b v_b|^2 = |q_a - q_b|^2  for all pairs a, b,

where ``v_ij = n_i x n_j / |n_i x n_j|`` is the direction of the line ``Pi_i ∩ Pi_j`` through ``O`` (camera frame)
and ``q_ij`` is the meeting point of scan lines i and j (lidar scan plane).  Each solution places the scan
triangle at ``P_ij = O + lambda_ij v_ij`` and gives ``T_lidar_cam`` from the three pairs ``q_ij <-> P_ij``.

Paper: F. Vasconcelos, J. P. Barreto, U. Nunes, "A Minimal Solution for the Extrinsic Calibration of a
Camera and a Laser-Rangefinder", IEEE TPAMI 34(11), 2012.

Input assumptions: board plane i is ``{p_C : n_i . p_C = d_i}`` in the CAMERA frame (metres; ``n_i`` is
normalised here, ``d_i`` with it); the scan line of board i is ``{p_i + s u_i}`` in the lidar scan plane
(2D lidar coordinates x, y in metres; the plane is z = 0 of the lidar frame).  The result ``T_lidar_cam``
maps camera points into the lidar frame (``p_L = R p_C + t``).

Method, per triple, all vectorised over triples (no Python loop over triples or candidates):

1. Degeneracy tests (thresholds are keyword options): planes with no single common point (smallest
   singular value of the normal matrix ``N``), nearly parallel scan lines (sine of their angle), a
   collinear scan triangle (twice its area over its longest side squared).
2. Grunert's reduction (as reviewed by Haralick et al., IJCV 1994) to one quartic in a ratio of two
   lambdas.  The points are relabelled so that the side divided by (``b`` of Grunert, between points 1
   and 3) is the longest one, coefficients are scaled to unit max-norm, and the quartic is reversed
   (unknown ``lambda_1/lambda_3`` instead of ``lambda_3/lambda_1``) when that makes the leading
   coefficient the larger end, so roots near infinity never occur.
3. Roots in closed form (Ferrari, complex arithmetic) or, with ``quartic="eig"``, as eigenvalues of the
   batched companion matrix; then two complex Newton steps on every root (which collapses the rounding
   imaginary part of real roots to ~1e-16) before the real/complex test.
4. The lambdas follow from the root without Grunert's unstable division (``lambda_2`` is the common root of
   two quadratics); a few Newton (Gauss-Newton on the square system) steps on the three distance
   equations polish them.  Lines, not rays: every root gives the solution and its mirror ``-lambda``.
5. Absolute orientation of the three point pairs in closed form (plane-to-plane alignment plus the optimal
   in-plane angle; for three points this is the Kabsch/SVD solution with det +1 when the two triangles
   have the same handedness, which they always do up to noise).
"""

from __future__ import annotations

import numpy as np

from ._common import (
    REASON_PLANES,
    REASON_QUARTIC,
    REASON_SCAN_LINES,
    REASON_TRIANGLE,
    SCAN_LINE_PAIRS,
    MinimalSolutions,
    grunert_quartic,
    plane_sv_min,
    prologue,
)
from .orientation import abs_orientation_3pt, cross, cross2, dot, unit
from .polynomial import Quartic, keep_better, newton_roots, quartic_roots

# Grunert point k (k = 1, 2, 3) -> original line index (0: v_12, 1: v_13, 2: v_23), chosen by the longest side.
# Sides: 0 = |q12 q13|, 1 = |q12 q23|, 2 = |q13 q23|; Grunert's b is the side between points 1 and 3.
_PERM_BY_LONGEST = np.array([[0, 2, 1], [0, 1, 2], [1, 0, 2]])


# ----------------------------------------------------------------------------------------------------------
# Small vectorised helpers


def _polish_lambdas(s, aa, bb, cc, ca, cb, cg, iters: int) -> np.ndarray:
    """Newton steps (K,3) on the three distance equations; a step is kept only where it lowers the residual."""

    def resid(s):
        s1, s2, s3 = s[:, 0], s[:, 1], s[:, 2]
        return np.stack([s1 * s1 + s2 * s2 - 2.0 * cg * s1 * s2 - cc,
                         s1 * s1 + s3 * s3 - 2.0 * cb * s1 * s3 - bb,
                         s2 * s2 + s3 * s3 - 2.0 * ca * s2 * s3 - aa], axis=-1)

    f = resid(s)
    fn = np.einsum("ki,ki->k", f, f)
    for _ in range(iters):
        s1, s2, s3 = s[:, 0], s[:, 1], s[:, 2]
        z = np.zeros_like(s1)
        J = np.stack([np.stack([2 * (s1 - cg * s2), 2 * (s2 - cg * s1), z], -1),
                      np.stack([2 * (s1 - cb * s3), z, 2 * (s3 - cb * s1)], -1),
                      np.stack([z, 2 * (s2 - ca * s3), 2 * (s3 - ca * s2)], -1)], axis=1)
        # Cramer: J^-1 = adj(J) / det(J), adj rows from cross products of J's columns.
        c0, c1, c2 = J[:, :, 0], J[:, :, 1], J[:, :, 2]
        adj = np.stack([cross(c1, c2), cross(c2, c0), cross(c0, c1)], axis=1)
        det = dot(c0, adj[:, 0])
        ok = np.abs(det) > 1e-300
        step = -np.einsum("kij,kj->ki", adj, f) / np.where(ok, det, 1.0)[:, None]
        s_new = s + np.where(ok[:, None], step, 0.0)
        s, f, fn = keep_better(s, f, fn, s_new, resid)
    return s


# ----------------------------------------------------------------------------------------------------------
# The solver


def _degeneracy(n, p, u, idx, reasons, *, min_plane_sv, min_line_sin, min_triangle, min_side):
    """Step 1, the degeneracy tests (reasons set in place): the solvable mask (K,), the scan lines' meeting
    points q (K,3,2) (q_12, q_13, q_23) and the squared sides of the scan triangle (K,3)."""
    sv_min = plane_sv_min(n)
    bad_planes = ~(sv_min >= min_plane_sv)
    ui, uj = u[:, SCAN_LINE_PAIRS[:, 0]], u[:, SCAN_LINE_PAIRS[:, 1]]
    pi, pj = p[:, SCAN_LINE_PAIRS[:, 0]], p[:, SCAN_LINE_PAIRS[:, 1]]
    sin_ij = cross2(ui, uj)  # (K,3)
    bad_lines = ~(np.abs(sin_ij).min(axis=1) >= min_line_sin)
    s_ij = cross2(pj - pi, uj) / np.where(bad_lines[:, None], 1.0, sin_ij)
    q = pi + s_ij[..., None] * ui
    sides2 = np.stack([np.sum((q[:, 0] - q[:, 1]) ** 2, -1), np.sum((q[:, 0] - q[:, 2]) ** 2, -1),
                       np.sum((q[:, 1] - q[:, 2]) ** 2, -1)], axis=-1)
    longest2 = sides2.max(axis=1)
    area2 = np.abs(cross2(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]))
    bad_tri = ~(area2 >= min_triangle * longest2) | ~(longest2 >= min_side**2)
    bad_tri &= ~bad_lines
    reasons[idx[bad_tri]] = REASON_TRIANGLE
    reasons[idx[bad_lines]] = REASON_SCAN_LINES
    reasons[idx[bad_planes]] = REASON_PLANES
    return ~(bad_planes | bad_lines | bad_tri), q, sides2


def _grunert_setup(n, d, q, sides2):
    """Step 2: the planes' common point O (K,3), the line directions and scan points relabelled for Grunert
    (side b = |P1 P3| the longest) (K,3,3), (K,3,2), and Grunert's (aa, bb, cc, ca, cb, cg), each (K,)."""
    n1, n2, n3 = n[:, 0], n[:, 1], n[:, 2]
    c23, c31, c12 = cross(n2, n3), cross(n3, n1), cross(n1, n2)
    detN = dot(n1, c23)
    O = (d[:, 0, None] * c23 + d[:, 1, None] * c31 + d[:, 2, None] * c12) / detN[:, None]
    V = unit(np.stack([c12, -c31, c23], axis=1))  # v_12, v_13, v_23
    perm = _PERM_BY_LONGEST[np.argmax(sides2, axis=1)]  # (K,3)
    rows = np.arange(len(n))[:, None]
    Vg = V[rows, perm]
    Qg = q[rows, perm]
    cg = dot(Vg[:, 0], Vg[:, 1])
    cb = dot(Vg[:, 0], Vg[:, 2])
    ca = dot(Vg[:, 1], Vg[:, 2])
    aa = np.sum((Qg[:, 1] - Qg[:, 2]) ** 2, -1)
    bb = np.sum((Qg[:, 0] - Qg[:, 2]) ** 2, -1)
    cc = np.sum((Qg[:, 0] - Qg[:, 1]) ** 2, -1)
    return O, Vg, Qg, (aa, bb, cc, ca, cb, cg)


def _kept_roots(A, quartic: Quartic | str, root_newton_iters: int, imag_tol: float, near_real_tol: float | None):
    """The quartics' real roots (and near-real pairs with ``near_real_tol``), polished: for each kept root its
    quartic's index (row-major, grouped by quartic), its real part and whether it is near-real."""
    roots = quartic_roots(A, quartic)
    roots = newton_roots(A, roots, root_newton_iters)
    im_scale = 1.0 + np.abs(roots)
    is_real = np.abs(roots.imag) <= imag_tol * im_scale
    near = np.zeros_like(is_real)
    if near_real_tol is not None:
        near = ~is_real & (roots.imag > 0) & (roots.imag <= near_real_tol * im_scale)
    k_tr, k_slot = np.nonzero(is_real | near)
    return k_tr, roots.real[k_tr, k_slot], near[k_tr, k_slot]


def _lambdas(x, rev, g, iters: int) -> np.ndarray:
    """Step 4: the three lambdas (M,3) of each root ``x`` (M,), without Grunert's unstable division, polished.

    ``z`` in [-1, 1] is lambda_3/lambda_1 ("v mode") or lambda_1/lambda_3; ``rev`` (M,) says whether the
    quartic was reversed; ``g`` = (aa, bb, cc, ca, cb, cg), each (M,).
    """
    aa, bb, cc, ca, cb, cg = g
    big = np.abs(x) > 1.0
    z = np.where(big, 1.0 / np.where(big, x, 1.0), x)
    v_mode = rev == big
    lead = np.sqrt(bb / (1.0 + z * z - 2.0 * z * cb))
    s1 = np.where(v_mode, lead, z * lead)
    s3 = np.where(v_mode, z * lead, lead)
    # lambda_2: common root of  s2^2 - 2 cg s1 s2 + s1^2 - cc = 0  and  s2^2 - 2 ca s3 s2 + s3^2 - aa = 0.
    r1 = np.sqrt(np.maximum(cc - s1 * s1 * (1.0 - cg * cg), 0.0))
    r3 = np.sqrt(np.maximum(aa - s3 * s3 * (1.0 - ca * ca), 0.0))
    cand1 = (s1 * cg)[:, None] + np.stack([r1, -r1], -1)
    cand3 = (s3 * ca)[:, None] + np.stack([r3, -r3], -1)
    diff = np.abs(cand1[:, :, None] - cand3[:, None, :]).reshape(-1, 4)
    best = np.argmin(diff, axis=1)
    rr = np.arange(best.size)
    s2 = 0.5 * (cand1[rr, best // 2] + cand3[rr, best % 2])
    return _polish_lambdas(np.stack([s1, s2, s3], axis=-1), aa, bb, cc, ca, cb, cg, iters)


def solve_triples(n: np.ndarray, d: np.ndarray, p: np.ndarray, u: np.ndarray, *,
                  imag_tol: float = 1e-8, near_real_tol: float | None = None, real_parts: bool = False,
                  min_plane_sv: float = 1e-3, min_line_sin: float = 1e-3, min_triangle: float = 1e-3,
                  min_side: float = 1e-6,
                  quartic: Quartic | str = Quartic.CLOSED, root_newton_iters: int = 2,
                  lambda_newton_iters: int = 2) -> MinimalSolutions:
    """Every real ``T_lidar_cam`` of B plane-line triples (Vasconcelos, Barreto & Nunes, TPAMI 2012).

    Solves ``|lambda_a v_a - lambda_b v_b| = |q_a - q_b|`` (a, b in {12, 13, 23}) for points
    ``P_a = O + lambda_a v_a`` on the lines where the boards' planes meet, then aligns ``q_a <-> P_a``.

    Args:
        n: (B,3,3) normals of the three board planes in the camera frame (rows; normalised here).
        d: (B,3) plane offsets, plane ``{p_C : n . p_C = d}`` in metres (scaled with ``n``).
        p: (B,3,2) a point of each board's scan line, lidar scan-plane coordinates (x, y) in metres.
        u: (B,3,2) the direction of each scan line (normalised here).
        imag_tol: a quartic root ``x`` counts as real when ``|Im x| <= imag_tol * (1 + |x|)`` (after Newton
            polishing in complex arithmetic, exact real roots have ``|Im x|`` ~ 1e-16); its real part is used.
        near_real_tol: ``None`` (default) keeps only real roots.  A float keeps also each complex-conjugate
            pair with ``|Im x| <= near_real_tol * (1 + |x|)`` through its real part (one root per pair; noise
            can turn two real roots into such a pair); these candidates are marked ``near_real``.
        real_parts: keep the real part of EVERY complex-conjugate pair, however far from real (one root per
            pair, marked ``near_real``), as the authors' MATLAB P3P does (``unique(real(roots(...)))``); the
            paper's ``vasconcelos`` keeps real roots only (off), ``vasconcelos_msac`` turns it on.
        min_plane_sv: degenerate when the smallest singular value of the unit-normal matrix ``N`` is below
            this (the planes' common point ``O`` is at or near infinity).
        min_line_sin: degenerate when two scan lines meet at an angle whose |sine| is below this.
        min_triangle: degenerate when the scan triangle's ``2 area / longest side^2`` is below this
            (equilateral: 0.866).
        min_side: degenerate when the triangle's longest side is below this (metres): three concurrent
            scan lines.
        quartic: ``"closed"`` (Ferrari, fast) or ``"eig"`` (companion-matrix eigenvalues, reference).
        root_newton_iters: complex Newton steps on each quartic root before the real test.
        lambda_newton_iters: Newton steps on the three distance equations per candidate.

    Returns:
        ``MinimalSolutions``; at most 8 candidates per triple (4 roots, each with its mirror through ``O``).
    """
    reasons, idx, n, d, p, u = prologue(n, d, p, u, quartic)
    ok, q, sides2 = _degeneracy(n, p, u, idx, reasons, min_plane_sv=min_plane_sv, min_line_sin=min_line_sin,
                                min_triangle=min_triangle, min_side=min_side)
    idx, n, d, q, sides2 = idx[ok], n[ok], d[ok], q[ok], sides2[ok]
    O, Vg, Qg, g = _grunert_setup(n, d, q, sides2)

    # 3. Quartic, normalised; reversed where the constant term dominates.
    A = grunert_quartic(*g)
    A = A / np.abs(A).max(axis=1, keepdims=True)
    rev = np.abs(A[:, 4]) > np.abs(A[:, 0])
    A = np.where(rev[:, None], A[:, ::-1], A)
    bad_q = ~(np.abs(A[:, 0]) > 1e-12)
    reasons[idx[bad_q]] = REASON_QUARTIC
    keep = ~bad_q
    idx, O, Vg, Qg, A, rev = idx[keep], O[keep], Vg[keep], Qg[keep], A[keep], rev[keep]
    g = tuple(v[keep] for v in g)
    k_tr, x, near_k = _kept_roots(A, quartic, root_newton_iters, imag_tol, np.inf if real_parts else near_real_tol)

    s = _lambdas(x, rev[k_tr], tuple(v[k_tr] for v in g), lambda_newton_iters)
    # Lines, not rays: each root and its mirror through O.
    s = np.stack([s, -s], axis=1).reshape(-1, 3)
    k_tr2 = np.repeat(k_tr, 2)
    P = O[k_tr2, None, :] + s[:, :, None] * Vg[k_tr2]

    # 5. Absolute orientation: lidar = R camera + t.
    R, t = abs_orientation_3pt(P, Qg[k_tr2])
    return MinimalSolutions.pack(R, t, idx[k_tr2], idx, reasons, np.repeat(near_k, 2))


def solve_triple(n3: np.ndarray, d3: np.ndarray, p3: np.ndarray, u3: np.ndarray, **options) -> list[np.ndarray]:
    """Every real ``T_lidar_cam`` (list of 4x4, possibly empty) of one triple: n3 (3,3), d3 (3,), p3, u3 (3,2).

    Same options as ``solve_triples``.
    """
    sol = solve_triples(np.asarray(n3, float)[None], np.asarray(d3, float)[None], np.asarray(p3, float)[None],
                        np.asarray(u3, float)[None], **options)
    return list(sol.T_lidar_cam)
