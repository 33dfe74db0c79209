"""Batched polynomial roots for the minimal solver: quartics in closed form (Ferrari) or as companion-matrix
eigenvalues, the largest root of a cubic (Cardano), Horner evaluation and Newton polishing; all vectorised over
a leading batch dimension, in complex arithmetic."""

from __future__ import annotations

from enum import StrEnum

import numpy as np


class Quartic(StrEnum):
    """How a minimal solver finds its quartic's roots: ``closed`` (Ferrari, fast) or ``eig`` (companion-matrix
    eigenvalues, the reference)."""

    CLOSED = "closed"
    EIG = "eig"


def poly_eval(A: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quartic (coefficients A (...,5), highest first) and its derivative at x (..., broadcast), Horner."""
    a0, a1, a2, a3, a4 = (A[..., k, None] for k in range(5))
    p = (((a0 * x + a1) * x + a2) * x + a3) * x + a4
    dp = ((4.0 * a0 * x + 3.0 * a1) * x + 2.0 * a2) * x + a3
    return p, dp


def cubic_root_largest(B: np.ndarray, C: np.ndarray, D: np.ndarray) -> np.ndarray:
    """The largest-modulus root of the monic cubic m^3 + B m^2 + C m + D (complex arrays), Cardano."""
    P = C - B * B / 3.0
    Q = 2.0 * B**3 / 27.0 - B * C / 3.0 + D
    S = np.sqrt(Q * Q / 4.0 + P**3 / 27.0)
    w1, w2 = -Q / 2.0 + S, -Q / 2.0 - S
    W = np.where(np.abs(w1) >= np.abs(w2), w1, w2)
    U = W ** (1.0 / 3.0)
    nz = np.abs(U) > 0
    Us = np.where(nz, U, 1.0)
    omega = np.exp(2j * np.pi / 3.0)
    best = np.zeros_like(U)
    best_abs = np.full(U.shape, -1.0)
    for k in range(3):
        Uk = Us * omega**k
        t = np.where(nz, Uk - P / (3.0 * Uk), 0.0)
        m = t - B / 3.0
        am = np.abs(m)
        better = am > best_abs
        best = np.where(better, m, best)
        best_abs = np.where(better, am, best_abs)
    return best


def quartic_roots_closed(A: np.ndarray) -> np.ndarray:
    """All 4 complex roots (K,4) of quartics A (K,5) (highest first, A[:,0] != 0), Ferrari in complex arithmetic."""
    a = (A[:, 1] / A[:, 0]).astype(complex)
    b = (A[:, 2] / A[:, 0]).astype(complex)
    c = (A[:, 3] / A[:, 0]).astype(complex)
    e = (A[:, 4] / A[:, 0]).astype(complex)
    a2 = a * a
    p = b - 3.0 * a2 / 8.0
    q = c - a * b / 2.0 + a2 * a / 8.0
    r = e - a * c / 4.0 + a2 * b / 16.0 - 3.0 * a2 * a2 / 256.0
    # Resolvent: m^3 + p m^2 + (p^2/4 - r) m - q^2/8 = 0; the largest root keeps sqrt(2m) away from 0.
    m = cubic_root_largest(p, p * p / 4.0 - r, -q * q / 8.0)
    w = np.sqrt(2.0 * m)
    nz = np.abs(w) > 0
    qw = np.where(nz, 2.0 * q / np.where(nz, w, 1.0), 0.0)
    roots = np.empty(A.shape[:1] + (4,), dtype=complex)
    k = 0
    for s1 in (1.0, -1.0):
        disc = np.sqrt(-(2.0 * p + 2.0 * m + s1 * qw))
        for s2 in (1.0, -1.0):
            roots[:, k] = (s1 * w + s2 * disc) / 2.0 - a / 4.0
            k += 1
    return roots


def quartic_roots_eig(A: np.ndarray) -> np.ndarray:
    """All 4 complex roots (K,4) of quartics A (K,5) as eigenvalues of batched companion matrices."""
    K = A.shape[0]
    Cm = np.zeros((K, 4, 4))
    Cm[:, 0, :] = -A[:, 1:] / A[:, :1]
    Cm[:, 1, 0] = Cm[:, 2, 1] = Cm[:, 3, 2] = 1.0
    return np.linalg.eigvals(Cm).astype(complex)


def newton_roots(A: np.ndarray, x: np.ndarray, iters: int) -> np.ndarray:
    """``iters`` Newton steps on quartics A (K,5) at roots x (K,R) (real or complex); a step is skipped at p' = 0."""
    for _ in range(iters):
        p, dp = poly_eval(A, x)
        ok = np.abs(dp) > 0
        x = x - np.where(ok, p / np.where(ok, dp, 1.0), 0.0)
    return x


def keep_better(x: np.ndarray, f: np.ndarray, fn: np.ndarray, x_new: np.ndarray, resid) -> tuple:
    """One guarded Newton update over a batch: ``x_new`` (K,n) replaces ``x`` where its residual ``resid(x_new)``
    (K,n) has a finite squared norm below ``fn`` (K,); returns the updated (x, f, fn)."""
    f_new = resid(x_new)
    fn_new = np.einsum("ki,ki->k", f_new, f_new)
    better = np.isfinite(fn_new) & (fn_new < fn)
    return (np.where(better[:, None], x_new, x), np.where(better[:, None], f_new, f), np.where(better, fn_new, fn))


def quartic_roots(A: np.ndarray, quartic: Quartic | str) -> np.ndarray:
    """The four complex roots (...,4) of quartics ``A`` (...,5) by the way ``quartic`` names (``Quartic``)."""
    return quartic_roots_closed(A) if Quartic(quartic) is Quartic.CLOSED else quartic_roots_eig(A)
