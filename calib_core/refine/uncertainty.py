"""Uncertainty of the extrinsic: covariance at an optimum, Fisher information and CRLB of the range-noise model,
a scale-free conditioning measure and the spread of the board normals (the warnings built on them are in
``calib_core.checks.degeneracy``).

Parameters are those of ``calib_core.model.residuals``: ``x = (w, dt)``, ``w`` a left rotation perturbation in the
lidar frame (radians), ``dt`` the translation (metres). A 6x6 covariance is ordered rotation then translation.
Noise model: every scan point is its beam times the true range plus zero-mean Gaussian noise of std ``sigma``
along the beam (the simulator's and the paper's model); camera-side board poses are taken as exact.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.lines import residual_sigma
from ..data.observations import Observations, ScanData
from ..errors import UncertaintyError
from ..geometry.metrics import sigma_rot_deg, sigma_trans_m
from ..model.board_error import BoardErrorScale, per_board_sum, systematic_basis
from ..model.residuals import range_linearised, range_residuals


def inverse_information(A: np.ndarray, rcond: float) -> np.ndarray:
    """Inverse of a symmetric positive semi-definite 6x6 ``A``; UncertaintyError when (nearly) singular."""
    A = 0.5 * (A + A.T)
    # scale to unit diagonal first, so that radians and metres do not decide the rank test
    s = np.sqrt(np.clip(np.diag(A), 1e-300, None))
    An = A / np.outer(s, s)
    lam, V = np.linalg.eigh(An)
    if not np.all(np.isfinite(lam)) or lam[0] <= rcond * lam[-1]:
        raise UncertaintyError(f"information matrix is singular (eigenvalue ratio {lam[0] / lam[-1]:.1e}): "
                               "the board set does not determine all 6 degrees of freedom")
    return (V / lam) @ V.T / np.outer(s, s)


def covariance(jacobian: np.ndarray, residuals: np.ndarray, range_sigma_m: float | None = None, *,
               rcond: float = 1e-12) -> np.ndarray:
    """Gauss-Newton covariance ``sigma^2 (J^T J)^-1`` (6x6, rotation then translation) of a least-squares optimum.

    Args:
        jacobian: (K,6) residual Jacobian at the optimum (parameters as in ``calib_core.model.residuals``).
        residuals: (K,) residuals at the optimum (metres).
        range_sigma_m: the residuals' noise std (metres); ``None`` estimates it as ``sqrt(|e|^2 / (K - 6))``.
    Raises:
        UncertaintyError: fewer than 7 residuals with ``range_sigma_m=None``, or a singular ``J^T J``.
    """
    J = np.asarray(jacobian, float)
    return _noise_variance(residuals, J.shape[1], range_sigma_m) * inverse_information(J.T @ J, rcond)


def _noise_variance(residuals: np.ndarray, n_params: int, range_sigma_m: float | None) -> float:
    """``range_sigma_m^2``, or estimated from the residuals (``lines.residual_sigma``, K - n_params degrees of
    freedom); UncertaintyError when none are left."""
    if range_sigma_m is not None:
        return float(range_sigma_m) ** 2
    if len(residuals) <= n_params:
        raise UncertaintyError(f"{len(residuals)} residuals leave no degrees of freedom to estimate the noise")
    return residual_sigma(residuals, n_params) ** 2


def _extrinsic(obs: Observations, T_lidar_cam) -> np.ndarray:
    if T_lidar_cam is not None:
        return np.asarray(T_lidar_cam, float)
    if obs.T_lidar_cam_true is None:
        raise UncertaintyError("no extrinsic given and the observations carry no ground truth")
    return obs.T_lidar_cam_true


def fisher_information(obs: Observations, T_lidar_cam: np.ndarray, range_sigma_m: float) -> np.ndarray:
    """Fisher information (6x6) of the range-noise model at ``T_lidar_cam``: ``J^T J / sigma^2``.

    ``J`` is the (K,6) Jacobian of the range residuals. It depends on the beam directions, the board planes and
    the extrinsic only, not on the measured ranges, so noisy scans give the exact information of their beams.
    """
    _, J = range_residuals(np.asarray(T_lidar_cam, float), obs.scan_data, jacobian=True)
    return J.T @ J / float(range_sigma_m) ** 2


def range_board_scores(obs: Observations, T_lidar_cam: np.ndarray, range_sigma_m: float) -> tuple[np.ndarray,
                                                                                                   np.ndarray]:
    """The range model's board scores (N,6), ``J_i^T e_i / sigma^2``, and informations (N,6,6), ``J_i^T J_i /
    sigma^2``, at ``T_lidar_cam`` (board poses taken as exact): what ``refine.dispersion`` tests."""
    e, J = range_linearised(np.asarray(T_lidar_cam, float), obs.scan_data)  # the final checks' linearisation
    starts = np.r_[0, np.cumsum([len(b.scan) for b in obs.boards])[:-1]]
    s2 = float(range_sigma_m) ** 2
    return np.add.reduceat(J * e[:, None], starts) / s2, np.add.reduceat(np.einsum("ka,kb->kab", J, J), starts) / s2


@dataclass(frozen=True)
class Crlb:
    """Cramer-Rao lower bound of an unbiased estimator of the extrinsic.

    Attributes:
        rot_rms_deg: ``sqrt(trace(cov[:3,:3]))`` in degrees: the bound on the RMS of the norm of the rotation-vector
            error ``log(R R_true^T)``, i.e. the RMS of the geodesic angle, which is exactly ``e_R`` of docs/METHOD.md
            eq. 13. Compare it with ``sqrt(mean(e_R^2))`` over trials, not with ``mean(e_R)``: for a Gaussian
            error with isotropic covariance, ``mean(e_R)`` is about 0.92 times the RMS.
        trans_rms_m: ``sqrt(trace(cov[3:,3:]))``: the bound on the RMS of ``e_t = |t - t_true|`` (metres).
        cov: the 6x6 inverse Fisher information (rotation in rad, translation in m).
    """

    rot_rms_deg: float
    trans_rms_m: float
    cov: np.ndarray


def crlb(obs: Observations, range_sigma_m: float, T_lidar_cam: np.ndarray | None = None) -> Crlb:
    """CRLB of the extrinsic for range noise of std ``range_sigma_m`` (metres), at ``T_lidar_cam`` (default: the truth).

    Raises UncertaintyError for a singular Fisher information or a missing extrinsic.
    """
    cov = inverse_information(fisher_information(obs, _extrinsic(obs, T_lidar_cam), range_sigma_m), 1e-12)
    return Crlb(sigma_rot_deg(cov), sigma_trans_m(cov), cov)


def typical_range(obs: Observations) -> float:
    """RMS range (metres) of all scan points: the lever arm that turns a rotation into a displacement."""
    pts = np.concatenate([b.scan for b in obs.boards])
    return float(np.sqrt(np.mean(np.sum(pts**2, axis=1))))


def conditioning(obs: Observations, T_lidar_cam: np.ndarray | None = None, *, scale_m: float | None = None) -> float:
    """Inverse condition number (in [0, 1], scale-free) of the range-residual Jacobian with translation in units
    of ``scale_m`` (default: ``typical_range(obs)``), at ``T_lidar_cam`` (default: the ground truth).

    1 means every direction of the 6-dof extrinsic (rotation in radians, translation in ranges) is constrained
    equally; 0 means some combination is not constrained at all (a degenerate board set). It does not depend
    on the noise level or on the number of points, only on the board geometry. Typical well-spread sets of
    6 boards at 3-6 m give about 1e-2; below 1e-3 the extrinsic is poorly determined along one direction.
    """
    T = _extrinsic(obs, T_lidar_cam)
    _, J = range_linearised(T, obs.scan_data)
    L = typical_range(obs) if scale_m is None else float(scale_m)
    s = np.linalg.svd(J * np.r_[np.ones(3), np.full(3, L)], compute_uv=False)
    return float(s[-1] / s[0]) if s[0] > 0 else 0.0


def normal_spread_deg(obs: Observations) -> float:
    """How far the board normals are from all lying in one plane, in degrees (0 = degenerate).

    ``asin(sqrt(2 lambda_min))`` of the mean of ``n n^T`` over the boards: for normals spread evenly on a cone of
    half-angle ``a`` it is ``a``; normals in one plane (e.g. all boards parallel to one axis) give 0, and then
    no three planes meet in a single point (the minimal solver's degeneracy).
    """
    n, _ = obs.planes_cam()
    lam = np.linalg.eigvalsh(n.T @ n / len(n))
    return float(np.degrees(np.arcsin(np.sqrt(np.clip(2 * lam[0], 0.0, 1.0)))))


def systematic_sandwich(Ai: np.ndarray, data: ScanData, T_lidar_cam: np.ndarray, J: np.ndarray,
                        board_error: BoardErrorScale, range_sigma_m: float) -> np.ndarray:
    """The covariance ``Ai`` (k,k) of a per-beam range estimator (the inverse of its information ``J^T J /
    sigma^2``, or any stand-in for it, e.g. ``methods.last_steps.fold_covariance``'s) with the per-board
    systematic error ``board_error`` (``model.board_error``) held: the sandwich ``Ai + Ai M Ai``, ``M = sum_i
    V_i^T P V_i / sigma^4``, ``V_i = B_i^T J_i`` (``J`` (K,k) the range residuals' Jacobian in the estimator's
    parameters, ``B`` the term's columns at ``T_lidar_cam``, ``P`` its variances, ``sigma = range_sigma_m`` the
    beams' noise). ``Ai`` itself when the term holds no error."""
    if not board_error.active:
        return Ai
    V = per_board_sum(np.einsum("ka,kp->kap", systematic_basis(data, data.normals @ T_lidar_cam[:3, :3].T), J),
                       data.board, len(data.normals))                                       # (N,2,k)
    C = Ai + Ai @ np.einsum("nap,a,naq->pq", V, board_error.variances, V) @ Ai / float(range_sigma_m) ** 4
    return 0.5 * (C + C.T)


def refinement_covariance(data: ScanData, T_lidar_cam: np.ndarray, residual: str = "range",
                          range_sigma_m: float | None = None, basis: np.ndarray | None = None,
                          board_error: BoardErrorScale | None = None) -> np.ndarray:
    """Covariance (6x6; kxk with ``basis``) of the minimiser of the ``residual`` least squares at ``T_lidar_cam``,
    under range noise.

    ``"range"``: ``sigma^2 (J^T J)^-1`` (the ML estimate's covariance). ``"plane"``: the point-to-plane distance is
    the range residual times ``w = m . b``, so its noise is not identically distributed; the sandwich
    ``A^-1 J^T diag(sigma^2 w^2) J A^-1`` with ``A = J^T J`` of the plane residuals. ``range_sigma_m=None``: estimated
    from the range residuals at ``T_lidar_cam`` (``K - 6`` degrees of freedom). ``basis``: (6,k), the covariance of
    k parameters that move ``(w, dt)`` by ``basis`` (e.g. the free mounting parameters, ``calib_core.refine.partial``;
    then ``K - k`` degrees of freedom); default the six of ``calib_core.model.residuals``. ``board_error``: the
    per-board systematic error (``model.board_error``) held (range residual only; ``range_sigma_m`` is then the
    beams' noise and must be given): the sandwich ``A^-1 + A^-1 M A^-1`` of the per-beam estimator, ``A = J^T J /
    sigma^2`` and ``M = sum_i V_i^T P V_i / sigma^4`` with ``V_i = B_i^T J_i`` (``model.board_error``).
    """
    T = np.asarray(T_lidar_cam, float)
    e_r, J_r = range_linearised(T, data)
    B = np.eye(6) if basis is None else np.asarray(basis, float)
    J_r = J_r @ B
    if board_error is not None and board_error.active and residual == "range":
        if range_sigma_m is None:
            raise UncertaintyError("the per-board systematic term needs the beams' range noise std")
        s2 = float(range_sigma_m) ** 2
        return systematic_sandwich(inverse_information(J_r.T @ J_r / s2, 1e-12), data, T, J_r, board_error,
                                   float(range_sigma_m))
    if residual == "range":
        return covariance(J_r, e_r, range_sigma_m)
    if residual != "plane":
        raise UncertaintyError(f"unknown residual {residual!r}; 'range' or 'plane'")
    from ..model.residuals import plane_residuals

    sigma2 = _noise_variance(e_r, B.shape[1], range_sigma_m)
    _, J_p = plane_residuals(T, data, jacobian=True)
    J_p = J_p @ B
    m = (data.normals @ T[:3, :3].T)[data.board]
    w = np.einsum("kj,kj->k", m, data.points / np.linalg.norm(data.points, axis=1, keepdims=True))
    Ai = inverse_information(J_p.T @ J_p, 1e-12)
    return Ai @ (J_p.T @ (J_p * (sigma2 * w**2)[:, None])) @ Ai
