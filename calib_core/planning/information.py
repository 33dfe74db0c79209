"""The information a board set holds about the extrinsic and the 1-sigma it predicts (``capture``'s module
docstring for the parameters and units): each board's Fisher information with its own pose marginalised
(``joint.board_informations``) and, with a per-board systematic error (``calib_core.model.board_error``), its
systematic part, so that a set's covariance is the one the calibration reports (``refine.systematic``): the
sandwich ``H^-1 + H^-1 M H^-1`` of the per-beam information ``H`` and the systematic part ``M``, both sums over
boards."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..checks.degeneracy import NULL_CONDITIONING
from ..data.observations import Observations
from ..errors import UncertaintyError
from ..model.board_error import BoardErrorScale, systematic_basis
from ..model.corners import board_row_offsets, normalised_rows, scan_data_at
from ..model.residuals import range_residuals
from ..refine.joint import board_informations
from ..refine.uncertainty import inverse_information

SIGMA_NAMES = ("roll_deg", "pitch_deg", "yaw_deg", "x_mm", "y_mm", "z_mm")
"""The per-axis 1-sigma as reported (``capture``'s module docstring)."""

SCALE_M = 4.0
"""The lever arm (metres) that turns translations into rotation-like units when the rank of an information is
judged (the typical range of a board; the degeneracy analysis uses the set's own)."""


@dataclass(frozen=True, eq=False)
class Prediction:
    """The predicted 1-sigma of a board set (module docstring for the parameters).

    Attributes:
        sigma: (6,) per axis, radians then metres, inf where the set does not determine it.
        rot_sigma_deg, trans_sigma_mm: roots of the traces of the rotation and translation blocks (inf when any
            of their axes is inf). covariance: the 6x6 covariance (the inverse information, with a systematic part its
            ``sandwich``), None when singular.
    """

    sigma: np.ndarray
    rot_sigma_deg: float
    trans_sigma_mm: float
    covariance: np.ndarray | None

    def sigma_dict(self) -> dict:
        """``{"roll_deg": ..., ..., "z_mm": ...}``, None where undetermined."""
        scale = np.r_[np.full(3, np.degrees(1.0)), np.full(3, 1000.0)]
        return {k: (float(v) if np.isfinite(v) else None) for k, v in zip(SIGMA_NAMES, self.sigma * scale,
                                                                          strict=True)}

    def meets(self, target: tuple[float, float]) -> bool:
        """Both ``rot_sigma_deg <= target[0]`` and ``trans_sigma_mm <= target[1]``."""
        return self.rot_sigma_deg <= target[0] and self.trans_sigma_mm <= target[1]


def as_pair(information: np.ndarray) -> np.ndarray:
    """A plan's information as the pair (..., 2, 6, 6) ``(H, M)`` (module docstring); a plain (..., 6, 6) is ``H``
    with no systematic part."""
    a = np.asarray(information, float)
    if a.ndim >= 3 and a.shape[-3] == 2:
        return a
    return np.stack([a, np.zeros_like(a)], axis=-3)


def sandwich(H_inv: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``H^-1 + H^-1 M H^-1`` (..., 6, 6): the covariance of the per-beam-weighted answer under the systematic
    part ``M`` (module docstring). The second term as the Gram matrix of ``H^-1 M^(1/2)`` (``M``'s eigenvalues
    clipped at zero): on an ill-conditioned ``H`` the plain triple product loses its diagonal to cancellation and
    can turn it negative; this keeps it a sum of squares."""
    m, U = np.linalg.eigh(0.5 * (M + np.swapaxes(M, -1, -2)))
    A = H_inv @ (U * np.sqrt(np.clip(m, 0.0, None))[..., None, :])
    C = H_inv + A @ np.swapaxes(A, -1, -2)
    return 0.5 * (C + np.swapaxes(C, -1, -2))


def predict(information: np.ndarray, scale_m: float = SCALE_M) -> Prediction:
    """The 1-sigma of the extrinsic under the Fisher ``information`` (rotation rad then translation m): 6x6, or the
    pair (2,6,6) ``(H, M)`` with the per-board systematic part (``as_pair``; the covariance is their sandwich).

    Where ``H`` is singular (an eigenvalue below ``NULL_CONDITIONING**2`` of the largest, translations in units of
    ``scale_m`` as in the degeneracy analysis), an axis is undetermined when the null space reaches it; the others
    get the variance of an estimable quantity, ``e^T F^+ e`` (with the systematic part, ``F^+ + F^+ M F^+``)."""
    pair = as_pair(information)
    H, M = pair[0], pair[1]
    F = 0.5 * (H + H.T)
    D = np.r_[np.ones(3), np.full(3, float(scale_m))]
    lam, V = np.linalg.eigh(F * np.outer(D, D))
    null = lam <= NULL_CONDITIONING**2 * lam[-1] if lam[-1] > 0 else np.ones(6, bool)
    cov = None
    if not null.any():
        try:
            cov = inverse_information(F, 1e-12)
        except UncertaintyError:
            null = lam <= lam[0]
    if cov is not None:
        cov = sandwich(cov, M)
        sigma = np.sqrt(np.diag(cov))
    else:
        reach = np.sum(V[:, null] ** 2, axis=1) > 1e-9
        pinv = sandwich((V[:, ~null] / lam[~null]) @ V[:, ~null].T * np.outer(D, D), M)
        sigma = np.where(reach, np.inf, np.sqrt(np.clip(np.diag(pinv), 0.0, None)))
    rot = float(np.degrees(np.sqrt(np.sum(sigma[:3] ** 2))))
    return Prediction(sigma, rot, float(1000.0 * np.sqrt(np.sum(sigma[3:] ** 2))), cov)


def set_informations(obs: Observations, T_lidar_cam: np.ndarray, range_sigma_m: float, corner_sigma_px: float,
                     T_cam_board: np.ndarray | None = None, board_error: BoardErrorScale | None = None
                     ) -> np.ndarray:
    """Per-board information of a board set at ``T_lidar_cam`` (``joint.board_informations``): (N,6,6), or with
    ``board_error`` the pairs (N,2,6,6) of each board's per-beam information and systematic part
    (``set_systematic``); range-only for boards without corners or with ``corner_sigma_px <= 0``."""
    T_b = np.array([b.T_cam_board for b in obs.boards]) if T_cam_board is None else np.asarray(T_cam_board, float)
    sc = corner_sigma_px if obs.has_corners else 0.0
    H = board_informations(obs, T_lidar_cam, T_b, sc, range_sigma_m)
    if board_error is None:
        return H
    return np.stack([H, set_systematic(obs, T_lidar_cam, range_sigma_m, sc, board_error, T_b)], axis=1)


def set_systematic(obs: Observations, T_lidar_cam: np.ndarray, range_sigma_m: float, corner_sigma_px: float,
                   scale: BoardErrorScale, T_cam_board: np.ndarray) -> np.ndarray:
    """Each board's systematic part ``M_i`` (N,6,6) of the profiled score covariance: the per-board terms of
    ``refine.systematic.with_systematic``'s ``M`` (its docstring; ``sum_i M_i`` is that ``M``) with the joint
    model's board poses marginalised, or the range model's ``V_i^T P V_i / sigma^4`` (``refine.uncertainty``) with
    ``corner_sigma_px <= 0``. Zero when ``scale`` holds no error."""
    N = obs.n_boards
    if not scale.active:
        return np.zeros((N, 6, 6))
    T_e, T_b = np.asarray(T_lidar_cam, float), np.asarray(T_cam_board, float)
    data = scan_data_at(obs, T_b)
    B = systematic_basis(data, data.normals @ T_e[:3, :3].T)
    P = scale.variances
    if corner_sigma_px <= 0:
        _, J = range_residuals(T_e, data, jacobian=True)
        starts = np.r_[0, np.cumsum([len(b.scan) for b in obs.boards])[:-1]]
        V = np.add.reduceat(np.einsum("ka,kp->kap", B, J), starts)                      # (N,2,6)
        return np.einsum("nap,a,naq->npq", V, P, V) / float(range_sigma_m) ** 4
    _, Jc, Je, Jb = normalised_rows(obs, T_e, T_b, float(corner_sigma_px), float(range_sigma_m), True)
    oc, os = board_row_offsets(obs)
    H_bb = np.add.reduceat(np.einsum("ra,rb->rab", Jc, Jc), oc) + np.add.reduceat(np.einsum("ra,rb->rab", Jb, Jb), os)
    H_eb = np.add.reduceat(np.einsum("ra,rb->rab", Je, Jb), os)
    Vx = np.add.reduceat(np.einsum("ka,kp->kap", B, Je), os)                             # (N,2,6)
    Vb = np.add.reduceat(np.einsum("ka,kp->kap", B, Jb), os)
    W = np.swapaxes(Vx, 1, 2) - H_eb @ np.linalg.solve(H_bb, np.swapaxes(Vb, 1, 2))     # (N,6,2)
    return np.einsum("nga,a,nha->ngh", W, P, W) / float(range_sigma_m) ** 2


SYSTEMATIC_SHARE = 0.5
"""A target out of reach is limited by the per-board systematic error when, at the planner's limit of boards, it
would be met without the term or the term holds more than this share of the missing quantity's variance."""


def limited_by_systematic(information: np.ndarray, target: tuple[float, float]) -> bool:
    """Whether the per-board systematic part of ``information`` (a pair, ``as_pair``) is what keeps its
    prediction from ``target`` (``SYSTEMATIC_SHARE``)."""
    pair = as_pair(information)
    if not pair[1].any():
        return False
    full, beams = predict(pair), predict(pair[0])
    if beams.meets(target):
        return True
    share = [1.0 - (b / f) ** 2 for f, b, t in ((full.rot_sigma_deg, beams.rot_sigma_deg, target[0]),
                                                  (full.trans_sigma_mm, beams.trans_sigma_mm, target[1]))
             if f > t and np.isfinite(f) and np.isfinite(b)]
    return bool(share) and max(share) > SYSTEMATIC_SHARE


__all__ = ["SCALE_M", "SIGMA_NAMES", "SYSTEMATIC_SHARE", "Prediction", "as_pair", "limited_by_systematic", "predict",
           "sandwich", "set_informations", "set_systematic"]
