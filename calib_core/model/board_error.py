"""The per-board systematic error of the lidar's view of a board: an error shared by all the beams of one board.

A real board, as the lidar sees it, is not exactly the plane the camera sees: the plate is not flat, the range
bias of the surface depends on its finish and on the incidence angle, and the camera's estimate of the board's
pose carries more than its corner noise. What of this moves the board's scan points as a whole is, on the scan
line, an offset along the board normal and a tilt of the plane about the in-plane axis across the scan line (a
2D lidar sees one line of the board, so a tilt about the line itself is not seen apart from an offset). Per board
``i`` the model is

    e_k = n_k  +  u_i,0  +  u_i,1 t_k / (R_i (m . b_k))       (range residual of point k, metres)

with ``n_k`` the per-beam range noise (std ``sigma``), ``m`` the board's unit normal in the lidar frame, ``b_k`` the
beam's unit direction (``1 / (m . b)`` turns a displacement along the normal into one along the beam), ``t_k`` the
point's signed distance along the scan line from the board's centroid of points and ``R_i`` the RMS of ``t_k``;
``u_i ~ N(0, diag(offset_m^2, tilt_m^2))`` independent between boards. ``offset_m`` is the 1-sigma of a range
offset shared by the board's beams (the quantity an observation file states as ``board_range_sigma_m``, and what a
surface's finish and incidence give a lidar; an offset of the plate along its normal is the same up to the
incidence's cosine, and the tilt column takes up the difference along the line); ``tilt_m`` the 1-sigma of a tilt
of the plane about the in-plane axis across the scan line, through the points' centroid, as the RMS displacement
along the normal it gives the board's scan points (the tilt angle's 1-sigma is ``tilt_m / R_i``). Both in
metres.

Marginalising ``u_i`` gives each board's range residuals the covariance ``Sigma_i = sigma^2 I + B_i P B_i^T``
(``B_i`` (K_i,2) the two columns above, ``systematic_basis``; ``P = diag(offset_m^2, tilt_m^2)``). The scales'
estimate and the covariances that hold the term are in ``calib_core.refine.systematic`` (the joint model) and
``calib_core.refine.uncertainty`` (the range model).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.observations import ScanData
from .residuals import MIN_BEAM_INCIDENCE


@dataclass(frozen=True)
class BoardErrorScale:
    """The per-board systematic error's 1-sigma (metres): ``offset_m`` along the board normal, ``tilt_m`` the tilt
    as the RMS displacement of the board's scan points (module docstring)."""

    offset_m: float = 0.0
    tilt_m: float = 0.0

    @property
    def active(self) -> bool:
        """Whether the term holds any error (both zero: the per-beam noise model alone, exactly)."""
        return self.offset_m > 0 or self.tilt_m > 0

    @property
    def variances(self) -> np.ndarray:
        """``(offset_m^2, tilt_m^2)`` (m^2)."""
        return np.array([self.offset_m, self.tilt_m], float) ** 2


def per_board_sum(values: np.ndarray, board: np.ndarray, n_boards: int) -> np.ndarray:
    """Sum of ``values`` (K, ...; one per scan point, any units) over each board's points: (N, ...), board ``i``'s
    row the sum over the points whose ``board`` (K,) index is ``i`` (zero for a board with none)."""
    out = np.zeros((n_boards,) + values.shape[1:])
    np.add.at(out, board, values)
    return out


def systematic_basis(data: ScanData, normals_lidar: np.ndarray) -> np.ndarray:
    """The term's two columns (K,2) at every scan point (module docstring's ``B``): ``1`` (a range offset of 1 m)
    and ``t / (R (m . b))`` (a tilt giving the board's points an RMS displacement of 1 m along the normal);
    ``normals_lidar`` (N,3) the boards' unit normals in the lidar frame (``R_lidar_cam n``). Signs are immaterial
    (the term enters through ``B P B^T``)."""
    N = len(normals_lidar)
    p = data.points[:, :2]
    cnt = np.bincount(data.board, minlength=N).astype(float)
    centroid = per_board_sum(p, data.board, N) / np.maximum(cnt, 1)[:, None]
    d = p - centroid[data.board]
    S = per_board_sum(np.einsum("ka,kb->kab", d, d), data.board, N)            # (N,2,2) scatter
    ang = 0.5 * np.arctan2(2 * S[:, 0, 1], S[:, 0, 0] - S[:, 1, 1])              # principal direction
    v = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    t = np.einsum("ka,ka->k", d, v[data.board])
    R = np.sqrt(per_board_sum(t**2, data.board, N) / np.maximum(cnt, 1))
    b = data.points / np.linalg.norm(data.points, axis=1, keepdims=True)
    mb = np.abs(np.einsum("kj,kj->k", normals_lidar[data.board], b))
    mb = np.maximum(mb, MIN_BEAM_INCIDENCE)
    return np.stack([np.ones(len(t)), t / (np.maximum(R[data.board], 1e-12) * mb)], axis=1)
