"""What the minimal solvers share (``vasconcelos``, ``vasconcelos_dual``, ``zhou2014``): the solutions type, the
reasons a triple is not solved, board triples, and the prologue every solver runs on its input (shapes checked,
non-finite triples set aside, normals and line directions made unit), plus the small closed forms two of them use.

Input of every solver: board planes ``{p_C : n . p_C = d}`` in the camera frame (metres; (B,3,3) normals as rows,
(B,3) offsets) and scan lines ``{p + s u}`` in the lidar scan plane (metres; (B,3,2) points and directions).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..errors import LidarcamError
from ..geometry.transforms import make_T
from .polynomial import Quartic

# Reasons (the ``reasons`` entries; ``None`` means solved).
REASON_NONFINITE = "non-finite input"
REASON_PLANES = "planes do not meet in one point (sigma_min(N) < min_plane_sv)"
REASON_SCAN_LINES = "scan lines nearly parallel (|sin angle| < min_line_sin)"
REASON_TRIANGLE = "scan triangle degenerate (2 area / longest side^2 < min_triangle, or longest side < min_side)"
REASON_QUARTIC = "degenerate quartic (roots at both 0 and infinity)"
REASON_NO_REAL = "no real solution"

MIN_BOARDS = 3
"""The fewest boards that fix the extrinsic: three planes each give a line's two constraints (the minimal solvers'
triples, the consensus's tests, the degeneracy analysis and the methods' minimum all read this one number)."""
MAX_SOLUTIONS = 8
"""Most solutions of one triple: 4 roots of a quartic, each with its mirror."""
SCAN_LINE_PAIRS = np.array([[0, 1], [0, 2], [1, 2]])
"""Which scan lines meet at q_a, a = 12, 13, 23."""

class MinimalSolverError(LidarcamError, ValueError):
    """Bad input shapes or options for the minimal solver."""


@dataclass(frozen=True)
class MinimalSolutions:
    """Every real solution of a batch of B plane-line triples.

    ``T_lidar_cam`` (M,4,4): the candidates, grouped by triple (ascending) and, within one, in root order
    with each solution followed by its mirror.  ``triple`` (M,): index of the input triple of each one.
    ``near_real`` (M,): True where the candidate comes from a complex root pair kept by ``near_real_tol``.
    ``reasons`` (B,) object: ``None`` when the triple was solved, else a ``REASON_*`` string (degenerate,
    or ``REASON_NO_REAL`` when the quartic had no kept root).
    """

    T_lidar_cam: np.ndarray
    triple: np.ndarray
    near_real: np.ndarray
    reasons: np.ndarray

    def __len__(self) -> int:
        return int(self.triple.shape[0])

    def of_triple(self, b: int) -> np.ndarray:
        """The candidates (K,4,4) of input triple ``b``."""
        return self.T_lidar_cam[self.triple == b]

    @classmethod
    def pack(cls, R: np.ndarray, t_m: np.ndarray, triple: np.ndarray, solved: np.ndarray, reasons: np.ndarray,
             near_real: np.ndarray) -> MinimalSolutions:
        """The solutions of a solver: rotations (M,3,3) and translations (M,3) metres of ``T_lidar_cam``, the input
        triple of each; ``solved`` the indices of the B triples that reached the solver, whose ``reasons``
        (B,) become ``REASON_NO_REAL`` where no solution came out (others are kept)."""
        n = len(reasons)
        has = np.zeros(n, dtype=bool)
        has[triple] = True
        reached = np.zeros(n, dtype=bool)
        reached[solved] = True
        reasons[reached & ~has & (reasons == None)] = REASON_NO_REAL  # noqa: E711 -- elementwise on objects
        return cls(T_lidar_cam=make_T(R, t_m), triple=triple, near_real=near_real, reasons=reasons)


def board_triples(n_boards: int) -> np.ndarray:
    """All ``C(n_boards, 3)`` triples of board indices, (C,3) int, lexicographic order."""
    if n_boards < MIN_BOARDS:
        return np.zeros((0, 3), dtype=int)
    return np.array(list(itertools.combinations(range(int(n_boards)), 3)), dtype=int)


def sym3_min_eig(A: np.ndarray) -> np.ndarray:
    """Smallest eigenvalue of symmetric 3x3 matrices (...,3,3), closed form (trigonometric)."""
    a11, a22, a33 = A[..., 0, 0], A[..., 1, 1], A[..., 2, 2]
    a12, a13, a23 = A[..., 0, 1], A[..., 0, 2], A[..., 1, 2]
    q = (a11 + a22 + a33) / 3.0
    p1 = a12**2 + a13**2 + a23**2
    p2 = (a11 - q) ** 2 + (a22 - q) ** 2 + (a33 - q) ** 2 + 2.0 * p1
    p = np.sqrt(p2 / 6.0)
    safe = p > 1e-300
    ps = np.where(safe, p, 1.0)
    b11, b22, b33 = (a11 - q) / ps, (a22 - q) / ps, (a33 - q) / ps
    b12, b13, b23 = a12 / ps, a13 / ps, a23 / ps
    detB = b11 * (b22 * b33 - b23**2) - b12 * (b12 * b33 - b23 * b13) + b13 * (b12 * b23 - b22 * b13)
    phi = np.arccos(np.clip(detB / 2.0, -1.0, 1.0)) / 3.0
    lam_min = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    return np.where(safe, lam_min, q)


def grunert_quartic(aa, bb, cc, ca, cb, cg) -> np.ndarray:
    """Grunert's quartic in v = lambda_3 / lambda_1 (Haralick et al. 1994, eq. 9), coefficients (K,5) highest first.

    ``aa, bb, cc``: squared sides |P2P3|^2, |P1P3|^2, |P1P2|^2; ``ca, cb, cg``: cosines of the angles between
    lines (2,3), (1,3), (1,2).
    """
    q1 = (aa - cc) / bb
    q2 = (aa + cc) / bb
    q3 = (bb - cc) / bb
    q4 = (bb - aa) / bb
    ca2, cb2, cg2 = ca * ca, cb * cb, cg * cg
    A4 = (q1 - 1.0) ** 2 - 4.0 * cc / bb * ca2
    A3 = 4.0 * (q1 * (1.0 - q1) * cb - (1.0 - q2) * ca * cg + 2.0 * cc / bb * ca2 * cb)
    A2 = 2.0 * (q1 * q1 - 1.0 + 2.0 * q1 * q1 * cb2 + 2.0 * q3 * ca2 - 4.0 * q2 * ca * cb * cg + 2.0 * q4 * cg2)
    A1 = 4.0 * (-q1 * (1.0 + q1) * cb + 2.0 * aa / bb * cg2 * cb - (1.0 - q2) * ca * cg)
    A0 = (1.0 + q1) ** 2 - 4.0 * aa / bb * cg2
    return np.stack([A4, A3, A2, A1, A0], axis=-1)


def checked_inputs(n, d, p, u, quartic: Quartic | str):
    """Inputs as float arrays of shapes (B,3,3), (B,3), (B,3,2), (B,3,2); MinimalSolverError otherwise."""
    n, d, p, u = (np.asarray(a, dtype=float) for a in (n, d, p, u))
    if n.ndim != 3 or n.shape[1:] != (3, 3):
        raise MinimalSolverError(f"n must be (B,3,3), got {n.shape}")
    B = n.shape[0]
    if d.shape != (B, 3) or p.shape != (B, 3, 2) or u.shape != (B, 3, 2):
        raise MinimalSolverError(f"expected d (B,3), p and u (B,3,2) with B={B}; got {d.shape}, {p.shape}, {u.shape}")
    if quartic not in tuple(Quartic):
        raise MinimalSolverError(f"quartic must be one of {', '.join(Quartic)}, got {quartic!r}")
    return n, d, p, u


def finite_normalised(n, d, p, u, reasons):
    """Triples with finite, non-zero input (others get ``REASON_NONFINITE``): their indices and the input with
    unit normals (offsets scaled with them) and unit line directions."""
    finite = (np.isfinite(n).all(axis=(1, 2)) & np.isfinite(d).all(axis=1) & np.isfinite(p).all(axis=(1, 2))
              & np.isfinite(u).all(axis=(1, 2)))
    nn = np.linalg.norm(n, axis=2)
    un = np.linalg.norm(u, axis=2)
    finite &= (nn > 0).all(axis=1) & (un > 0).all(axis=1)
    reasons[~finite] = REASON_NONFINITE
    idx = np.flatnonzero(finite)
    return idx, n[idx] / nn[idx][:, :, None], d[idx] / nn[idx], p[idx], u[idx] / un[idx][:, :, None]


def plane_sv_min(n: np.ndarray) -> np.ndarray:
    """Smallest singular value (K,) of each triple's unit-normal matrix ``N`` (K,3,3): near 0, the planes have no
    single common point."""
    return np.sqrt(np.maximum(sym3_min_eig(np.swapaxes(n, 1, 2) @ n), 0.0))


def prologue(n, d, p, u, quartic: Quartic | str):
    """Every solver's first step: ``(reasons, idx, n, d, p, u)`` with ``reasons`` (B,) object (``None`` or
    ``REASON_NONFINITE``), ``idx`` the finite triples and their input made unit (``checked_inputs``,
    ``finite_normalised``)."""
    n, d, p, u = checked_inputs(n, d, p, u, quartic)
    reasons = np.full(n.shape[0], None, dtype=object)
    idx, n, d, p, u = finite_normalised(n, d, p, u, reasons)
    return reasons, idx, n, d, p, u
