"""Joint maximum likelihood over both sensors: the extrinsic and every board's camera pose from the image corners
and the lidar ranges together, with the extrinsic's covariance with the board poses marginalised, and the
Cramer-Rao bound of that model.

Unknowns: ``T_lidar_cam = (exp([w]x) R0, t0 + dt)`` (left rotation perturbation in the lidar frame, as in
``calib_core.data.residuals``) and per board ``T_cam_board_i = (exp([phi_i]x) Phi0_i, Delta0_i + d_i)`` (left
perturbation in the camera frame); the parameter vector is ``(w, dt, phi_0, d_0, phi_1, d_1, ...)``.
Residuals: every corner's reprojection through the OpenCV model (``calib_core.data.camera.project``) minus its
detection, divided by the corner noise std ``corner_sigma_px`` (pixels, per coordinate), and every scan point's
range residual (``calib_core.data.residuals.range_residuals`` against its board's current plane) divided by the range
noise std ``range_sigma_m``. Each board's residuals touch only its own pose and the extrinsic, so the Jacobian is
block sparse: the Levenberg-Marquardt steps and the covariance both eliminate the board poses by the Schur
complement, so the cost of an iteration is linear in the number of boards.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.camera import project
from ..data.lines import residual_sigma, scan_noise_estimate
from ..data.observations import Observations, ScanData
from ..data.residuals import MIN_BEAM_INCIDENCE, perturb, range_residuals
from ..errors import JointError, UncertaintyError
from ..geometry.metrics import sigma_rot_deg, sigma_trans_m
from ..geometry.transforms import rotvec_to_matrix, skew
from .refine import F_SCALE_SIGMAS, robust_cost
from .uncertainty import Crlb, _inverse_information

JOINT_MODEL = "joint"
RANGE_ONLY_MODEL = "range-only, ignores camera noise"
"""The two values of a result's ``info["covariance_model"]``: which likelihood produced its covariance."""

CORNER_SIGMA_FLOOR_PX = 1e-3
"""Least corner noise std (pixels) an estimate may return (noise-free corners would weigh infinitely)."""
RANGE_SIGMA_FLOOR_M = 1e-6
"""Least range noise std (metres) an estimate may return."""
START_CORNER_SIGMA_PX = 0.1
START_RANGE_SIGMA_M = 0.002
"""Floors of the noise stds of the first solve (corner RMS at the observed poses, scan-line noise estimate)."""
MAX_ITER = 50
"""Levenberg-Marquardt iterations of one joint solve, at most."""
INITIAL_LAMBDA = 1e-3
"""Levenberg-Marquardt damping of the first step (relative to the diagonal) ..."""
LAMBDA_FACTOR = 10.0
"""... multiplied by this after a rejected step, divided by it after an accepted one ..."""
MAX_LAMBDA = 1e10
"""... and the solve stops (converged: no step lowers the cost) above this ..."""
MIN_LAMBDA = 1e-9
"""... and never below this."""
COST_RTOL = 1e-12
"""Converged when a step lowers the cost by less than this fraction, or moves no parameter by ``STEP_TOL``."""
STEP_TOL = 1e-12


@dataclass(frozen=True)
class JointOptions:
    """A method's joint step: ``use_corners`` (when every board carries them), ``corner_sigma_px`` (default
    estimated), the robust loss's scale ``f_scale_sigmas`` in noise stds, at most ``max_iter`` iterations."""

    use_corners: bool = True
    corner_sigma_px: float | None = None
    f_scale_sigmas: float = F_SCALE_SIGMAS
    max_iter: int = MAX_ITER


def _corner_arrays(obs: Observations):
    if not obs.has_corners:
        raise JointError("the joint model needs image corners on every board and the camera intrinsics")
    P = np.concatenate([b.corners_board for b in obs.boards])
    uv = np.concatenate([b.corners_px for b in obs.boards])
    idx = np.concatenate([np.full(len(b.corners_px), i) for i, b in enumerate(obs.boards)])
    return P, uv, idx


def board_poses(obs: Observations, x_boards: np.ndarray | None = None, T0: np.ndarray | None = None) -> np.ndarray:
    """(N,4,4) board poses ``T_cam_board`` at parameters ``x_boards`` (N,6) around ``T0`` (default: the observed)."""
    T0 = np.array([b.T_cam_board for b in obs.boards]) if T0 is None else np.asarray(T0, float)
    if x_boards is None:
        return T0.copy()
    T = T0.copy()
    T[:, :3, :3] = rotvec_to_matrix(x_boards[:, :3]) @ T0[:, :3, :3]
    T[:, :3, 3] += x_boards[:, 3:]
    return T


def corner_residuals(obs: Observations, T_cam_board: np.ndarray, jacobian: bool = False):
    """Reprojection errors (J,2) in pixels of every corner under board poses ``T_cam_board`` (N,4,4); with
    ``jacobian`` also (J,2,6) d e/d(phi, d) of each corner's own board."""
    P, uv, idx = _corner_arrays(obs)
    RP = np.einsum("jab,jb->ja", T_cam_board[idx, :3, :3], P)
    X = RP + T_cam_board[idx, :3, 3]
    if np.any(X[:, 2] <= 0):
        bad = int(idx[np.argmax(X[:, 2] <= 0)])
        raise JointError(f"board {bad}: a corner lies behind the camera under the current pose")
    if not jacobian:
        return project(obs.camera, X) - uv
    proj, Jp = project(obs.camera, X, jacobian=True)
    J = np.concatenate([Jp @ -skew(RP), Jp], axis=2)
    return proj - uv, J


def scan_data_at(obs: Observations, T_cam_board: np.ndarray) -> ScanData:
    """The problem's scan points with the planes of the board poses ``T_cam_board`` (N,4,4)."""
    base = obs.scan_data
    n = T_cam_board[:, :3, 2]
    return ScanData(base.points, base.board, n, np.einsum("na,na->n", n, T_cam_board[:, :3, 3]))


def joint_range_residuals(obs: Observations, T_lidar_cam: np.ndarray, T_cam_board: np.ndarray,
                          jacobian: bool = False):
    """Range residuals (K,) in metres under both the extrinsic and the board poses; with ``jacobian`` also
    (K,6) d e/d(w, dt) and (K,6) d e/d(phi, d) of each point's own board."""
    data = scan_data_at(obs, T_cam_board)
    if not jacobian:
        return range_residuals(T_lidar_cam, data)
    e, J_e = range_residuals(T_lidar_cam, data, jacobian=True)
    R, t = T_lidar_cam[:3, :3], T_lidar_cam[:3, 3]
    n = data.normals[data.board]
    Delta = T_cam_board[data.board, :3, 3]
    m = n @ R.T
    b = data.points / np.linalg.norm(data.points, axis=1, keepdims=True)
    mb = np.einsum("kj,kj->k", m, b)
    mb = np.where(np.abs(mb) < MIN_BEAM_INCIDENCE, np.copysign(MIN_BEAM_INCIDENCE, mb), mb)
    num = data.offsets[data.board] + m @ t
    g = -((t[None] * mb[:, None] - b * num[:, None]) / (mb**2)[:, None]) @ R   # de/dn (camera frame)
    de_dd = -1.0 / mb                                                          # de/d(plane offset)
    # dn = phi x n, d(offset) = phi . (n x Delta) + n . d
    J_b = np.concatenate([np.cross(n, g) + de_dd[:, None] * np.cross(n, Delta), de_dd[:, None] * n], axis=1)
    return e, J_e, J_b


def _weighted(obs: Observations, T_e: np.ndarray, T_b: np.ndarray, sc: float, sr: float, jacobian: bool):
    """Normalised residuals (corners (2J) then ranges (K)); with ``jacobian`` also the corner rows' board
    Jacobian (2J,6), the range rows' extrinsic (K,6) and board (K,6) Jacobians, at the current poses."""
    if not jacobian:
        ec = corner_residuals(obs, T_b)
        return np.r_[ec.ravel() / sc, joint_range_residuals(obs, T_e, T_b) / sr]
    ec, Jc = corner_residuals(obs, T_b, jacobian=True)
    er, Je, Jb = joint_range_residuals(obs, T_e, T_b, jacobian=True)
    return np.r_[ec.ravel() / sc, er / sr], Jc.reshape(-1, 6) / sc, Je / sr, Jb / sr


_DRHO = {"linear": lambda z: np.ones_like(z), "huber": lambda z: np.where(z <= 1, 1.0, 1 / np.sqrt(np.maximum(z, 1))),
         "soft_l1": lambda z: 1 / np.sqrt(1 + z), "cauchy": lambda z: 1 / (1 + z), "arctan": lambda z: 1 / (1 + z**2)}
"""rho'(z) of scipy's robust losses (``z`` the squared residual over the squared scale): the IRLS weights."""


def _row_offsets(obs: Observations) -> tuple[np.ndarray, np.ndarray]:
    """First corner row (of 2J) and first range row (of K) of each board: rows are grouped by board."""
    nc = np.array([2 * len(b.corners_px) for b in obs.boards])
    ns = np.array([len(b.scan) for b in obs.boards])
    return np.r_[0, np.cumsum(nc)[:-1]], np.r_[0, np.cumsum(ns)[:-1]]


def _normal_equations(obs, offsets, e, Jc, Je, Jb):
    """Gauss-Newton blocks of ``0.5 |e|^2``: gradient (g_e (6,), g_b (N,6)) and information (H_ee, H_eb, H_bb)."""
    oc, os = offsets
    nc = len(Jc)
    ec, er = e[:nc], e[nc:]
    H_bb = np.add.reduceat(np.einsum("ra,rb->rab", Jc, Jc), oc) + np.add.reduceat(np.einsum("ra,rb->rab", Jb, Jb), os)
    H_eb = np.add.reduceat(np.einsum("ra,rb->rab", Je, Jb), os)
    g_b = np.add.reduceat(Jc * ec[:, None], oc) + np.add.reduceat(Jb * er[:, None], os)
    return Je.T @ er, g_b, Je.T @ Je, H_eb, H_bb


def _schur_step(g_e, g_b, H_ee, H_eb, H_bb, lam):
    """The damped Gauss-Newton step (extrinsic (6,), boards (N,6)) by the Schur complement on the board blocks."""
    Dbb = H_bb + lam * np.einsum("nii->ni", H_bb)[:, :, None] * np.eye(6)
    Dee = H_ee + lam * np.diag(np.diag(H_ee))
    X = np.linalg.solve(Dbb, np.concatenate([np.swapaxes(H_eb, 1, 2), g_b[:, :, None]], axis=2))
    S = Dee - np.einsum("nab,nbc->ac", H_eb, X[:, :, :6])
    de = np.linalg.solve(S, -g_e + np.einsum("nab,nb->a", H_eb, X[:, :, 6]))
    db = -X[:, :, 6] - np.einsum("nab,b->na", X[:, :, :6], de)
    return de, db


def _apply(T_e, T_b, de, db):
    Tb = T_b.copy()
    Tb[:, :3, :3] = rotvec_to_matrix(db[:, :3]) @ T_b[:, :3, :3]
    Tb[:, :3, 3] += db[:, 3:]
    return perturb(T_e, de), Tb


def _solve(obs, T_e, T_b, sc, sr, loss, f_scale_sigmas, max_iter, tol=COST_RTOL):
    """Levenberg-Marquardt on the joint cost, each step by the Schur complement (linear in the boards); robust
    losses by iteratively reweighted least squares. Returns (T_e, T_b, cost, iterations, converged)."""
    drho = _DRHO[loss]
    offsets = _row_offsets(obs)

    def cost_of(Te, Tb):
        return robust_cost(_weighted(obs, Te, Tb, sc, sr, False), loss, f_scale_sigmas)

    cost, lam, it = cost_of(T_e, T_b), INITIAL_LAMBDA, 0
    for it in range(1, max_iter + 1):
        e, Jc, Je, Jb = _weighted(obs, T_e, T_b, sc, sr, True)
        w = np.sqrt(drho((e / f_scale_sigmas) ** 2))
        nc = len(Jc)
        blocks = _normal_equations(obs, offsets, e * w, Jc * w[:nc, None], Je * w[nc:, None], Jb * w[nc:, None])
        while True:
            de, db = _schur_step(*blocks, lam)
            Te, Tb = _apply(T_e, T_b, de, db)
            try:
                new = cost_of(Te, Tb)
            except JointError:
                new = np.inf
            if new <= cost:
                break
            lam *= LAMBDA_FACTOR
            if lam > MAX_LAMBDA:
                return T_e, T_b, cost, it, True
        T_e, T_b, old, cost = Te, Tb, cost, new
        lam = max(lam / LAMBDA_FACTOR, MIN_LAMBDA)
        if old - cost <= tol * max(cost, 1e-300) or max(np.abs(de).max(), np.abs(db).max()) < STEP_TOL:
            return T_e, T_b, cost, it, True
    return T_e, T_b, cost, it, False


@dataclass(frozen=True, eq=False)
class JointResult:
    """Outcome of ``joint_refine``.

    Attributes:
        T_lidar_cam: 4x4 extrinsic; T_cam_board: (N,4,4) refined board poses; covariance: 6x6 of the extrinsic
        (rotation rad then translation m, board poses marginalised); corner_sigma_px, range_sigma_m: the noise
        stds used (given or estimated); corner_rms_px, range_rms_m: RMS of the final residuals; cost: final
        ``0.5 sum rho`` of the normalised residuals; iterations: of the last solve; converged: whether it met the
        tolerance within ``max_iter``.
    """

    T_lidar_cam: np.ndarray
    T_cam_board: np.ndarray
    covariance: np.ndarray
    corner_sigma_px: float
    range_sigma_m: float
    corner_rms_px: float
    range_rms_m: float
    cost: float
    iterations: int
    converged: bool


def _estimate_sigmas(obs, T_e, T_b, n_params_boards: int):
    ec = corner_residuals(obs, T_b)
    er = joint_range_residuals(obs, T_e, T_b)
    return (max(residual_sigma(ec, n_params_boards), CORNER_SIGMA_FLOOR_PX),
            max(residual_sigma(er, 6), RANGE_SIGMA_FLOOR_M))


def joint_refine(obs: Observations, T0: np.ndarray, *, corner_sigma_px: float | None = None,
                 range_sigma_m: float | None = None, loss: str = "linear", f_scale_sigmas: float = F_SCALE_SIGMAS,
                 max_iter: int = MAX_ITER, sigma_iters: int = 3, sigma_rtol: float = 0.05) -> JointResult:
    """Maximise the joint likelihood from the extrinsic ``T0`` and the observed board poses.

    Args:
        corner_sigma_px, range_sigma_m: noise stds; ``None`` estimates each from its own residuals (corners:
            ``2J - 6N`` degrees of freedom, ranges ``K - 6``), re-solving until they change by less than
            ``sigma_rtol`` (at most ``sigma_iters`` solves). Start values: the corner RMS at the observed poses,
            the scan-line estimate of ``data.lines.scan_noise_estimate`` (floored by ``START_*``).
        loss, f_scale_sigmas: robust loss (``refine.Loss``) on the normalised residuals, its scale in noise stds.
    Raises:
        JointError: no corners or camera; UncertaintyError: the joint information is singular.
    """
    T_e, T_b = np.asarray(T0, float), board_poses(obs)
    est_c, _ = _estimate_sigmas(obs, T_e, T_b, 6 * obs.n_boards)
    # start weights from each sensor alone, floored so that neither sensor swamps the other before the solve
    sc = corner_sigma_px if corner_sigma_px is not None else max(est_c, START_CORNER_SIGMA_PX)
    sr = range_sigma_m if range_sigma_m is not None else max(scan_noise_estimate(obs), START_RANGE_SIGMA_M)
    for _ in range(max(1, sigma_iters)):
        T_e, T_b, _, nit, converged = _solve(obs, T_e, T_b, sc, sr, loss, f_scale_sigmas, max_iter)
        new_c, new_r = _estimate_sigmas(obs, T_e, T_b, 6 * obs.n_boards)
        new_c = corner_sigma_px if corner_sigma_px is not None else new_c
        new_r = range_sigma_m if range_sigma_m is not None else new_r
        done = abs(new_c / sc - 1) < sigma_rtol and abs(new_r / sr - 1) < sigma_rtol
        sc, sr = new_c, new_r
        if done:
            break
    cov = marginal_covariance(obs, T_e, T_b, sc, sr)
    ec = corner_residuals(obs, T_b)
    er = joint_range_residuals(obs, T_e, T_b)
    cost = robust_cost(np.r_[ec.ravel() / sc, er / sr], loss, f_scale_sigmas)
    return JointResult(T_e, T_b, cov, sc, sr, float(np.sqrt(np.mean(np.sum(ec**2, axis=1)))),
                       float(np.sqrt(np.mean(er**2))), cost, nit, converged)


def board_informations(obs: Observations, T_lidar_cam: np.ndarray, T_cam_board: np.ndarray, corner_sigma_px: float,
                       range_sigma_m: float) -> np.ndarray:
    """Each board's Fisher information (N,6,6) about the extrinsic (rotation rad then translation m) with its own
    pose marginalised: ``H_ee,i - H_ei H_ii^-1 H_ie``. Boards are independent, so the information of a set is the
    sum over its boards (what a capture planner adds up). ``corner_sigma_px <= 0``: exact board poses, the range
    model's ``J_i^T J_i / range_sigma_m^2``.

    UncertaintyError when a board's pose is not determined by its corners.
    """
    T_e, T_b = np.asarray(T_lidar_cam, float), np.asarray(T_cam_board, float)
    if corner_sigma_px <= 0:
        _, J = range_residuals(T_e, scan_data_at(obs, T_b), jacobian=True)
        starts = np.r_[0, np.cumsum([len(b.scan) for b in obs.boards])[:-1]]
        return np.add.reduceat(np.einsum("ka,kb->kab", J, J), starts) / float(range_sigma_m) ** 2
    _, Jc, Je, Jb = _weighted(obs, T_e, T_b, float(corner_sigma_px), float(range_sigma_m), True)
    oc, os = _row_offsets(obs)
    H_bb = np.add.reduceat(np.einsum("ra,rb->rab", Jc, Jc), oc) + np.add.reduceat(np.einsum("ra,rb->rab", Jb, Jb), os)
    H_eb = np.add.reduceat(np.einsum("ra,rb->rab", Je, Jb), os)
    H_ee = np.add.reduceat(np.einsum("ra,rb->rab", Je, Je), os)
    try:
        X = np.linalg.solve(H_bb, np.swapaxes(H_eb, 1, 2))          # H_ii^-1 H_ie, (N,6,6)
    except np.linalg.LinAlgError:
        raise UncertaintyError("a board's pose is not determined by its corners") from None
    return H_ee - H_eb @ X


def marginal_covariance(obs: Observations, T_lidar_cam: np.ndarray, T_cam_board: np.ndarray, corner_sigma_px: float,
                        range_sigma_m: float, rcond: float = 1e-12) -> np.ndarray:
    """The extrinsic block (6x6) of the inverse joint information: ``(H_ee - sum_i H_ei H_ii^-1 H_ie)^-1``.

    UncertaintyError when a board's pose or the extrinsic is not determined.
    """
    S = board_informations(obs, T_lidar_cam, T_cam_board, corner_sigma_px, range_sigma_m).sum(axis=0)
    return _inverse_information(S, rcond)


def joint_crlb(obs: Observations, range_sigma_m: float, corner_sigma_px: float, T_lidar_cam: np.ndarray | None = None,
               T_cam_board: np.ndarray | None = None) -> Crlb:
    """CRLB of the extrinsic under both noise sources: range noise ``range_sigma_m`` (metres) along each beam and
    Gaussian corner noise ``corner_sigma_px`` (pixels, per coordinate), board poses unknown (marginalised).

    Evaluated at ``T_lidar_cam`` (default: the ground truth) and ``T_cam_board`` (N,4,4; default: the observed
    poses, which should be the true ones for a bound). ``corner_sigma_px = 0`` gives the range-only bound.
    """
    if T_lidar_cam is None:
        if obs.T_lidar_cam_true is None:
            raise UncertaintyError("no extrinsic given and the observations carry no ground truth")
        T_lidar_cam = obs.T_lidar_cam_true
    T_b = board_poses(obs) if T_cam_board is None else np.asarray(T_cam_board, float)
    cov = marginal_covariance(obs, T_lidar_cam, T_b, corner_sigma_px, range_sigma_m)
    return Crlb(sigma_rot_deg(cov), sigma_trans_m(cov), cov)


def joint_step(obs: Observations, T0: np.ndarray, *, corner_sigma_px: float | None = None,
               range_sigma_m: float | None = None, loss: str = "linear", f_scale_sigmas: float = F_SCALE_SIGMAS,
               max_iter: int = MAX_ITER) -> tuple[np.ndarray, np.ndarray, dict]:
    """A method's final step when the boards carry image corners: ``joint_refine`` from ``T0``; returns
    (T_lidar_cam, covariance, info) with ``info["covariance_model"] = JOINT_MODEL`` and the noise figures.

    Raises JointError (no corners, a board behind the camera) and UncertaintyError (singular information).
    """
    j = joint_refine(obs, T0, corner_sigma_px=corner_sigma_px, range_sigma_m=range_sigma_m, loss=loss,
                     f_scale_sigmas=f_scale_sigmas, max_iter=max_iter)
    info = {"covariance_model": JOINT_MODEL, "corner_sigma_px": j.corner_sigma_px, "range_sigma_m": j.range_sigma_m,
            "corner_rms_px": j.corner_rms_px, "range_rms_m": j.range_rms_m, "joint_cost": j.cost,
            "joint_iterations": j.iterations, "joint_converged": j.converged}
    if not j.converged:
        info["warnings"] = [f"joint refinement stopped after {max_iter} iterations without converging"]
    return j.T_lidar_cam, j.covariance, info
