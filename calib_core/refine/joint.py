"""Joint maximum likelihood over both sensors: the extrinsic and every board's camera pose from the image corners
and the lidar ranges together, with the extrinsic's covariance with the board poses marginalised, and the
Cramer-Rao bound of that model.

Unknowns: ``T_lidar_cam = (exp([w]x) R0, t0 + dt)`` (left rotation perturbation in the lidar frame, as in
``calib_core.model.residuals``) and per board ``T_cam_board_i = (exp([phi_i]x) Phi0_i, Delta0_i + d_i)`` (left
perturbation in the camera frame); the parameter vector is ``(w, dt, phi_0, d_0, phi_1, d_1, ...)``.
Residuals: every corner's reprojection through the camera's model (``calib_core.data.camera.project``) minus its
detection, divided by the corner noise std ``corner_sigma_px`` (pixels, per coordinate), and every scan point's
range residual (``calib_core.model.residuals.range_residuals`` against its board's current plane) divided by the range
noise std ``range_sigma_m``. Each board's residuals touch only its own pose and the extrinsic, so the Jacobian is
block sparse: the Levenberg-Marquardt steps and the covariance both eliminate the board poses by the Schur
complement, so the cost of an iteration is linear in the number of boards. When the camera states
``std_intrinsics``, its free intrinsics join the extrinsic in the shared block with that Gaussian prior
(``calib_core.model.intrinsics``); otherwise they are taken as exact. The residuals and their Jacobians are
in ``calib_core.model.corners``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..data.camera import CameraModel
from ..data.lines import range_sigma, residual_sigma
from ..data.observations import Observations
from ..data.outcome import CovarianceModel
from ..errors import JointError, ObservationError, UncertaintyError
from ..geometry.metrics import sigma_rot_deg, sigma_trans_m
from ..geometry.mounting import MountingPrior
from ..geometry.transforms import rotvec_to_matrix
from ..model.board_error import BoardErrorScale
from ..model.corners import (
    board_poses,
    board_row_offsets,
    corner_residuals,
    joint_range_residuals,
    normalised_rows,
    scan_data_at,
)
from ..model.intrinsics import IntrinsicsPrior, augmented_blocks
from ..model.joint_outline import has_outline_rows, outline_cost, with_outline
from ..model.prior import mounting_cost, with_mounting
from ..model.residuals import perturb, range_residuals
from .bend import HeldDirection
from .refine import F_SCALE_SIGMAS, robust_cost
from .systematic import with_systematic
from .uncertainty import Crlb, inverse_information

JOINT_MODEL = CovarianceModel.JOINT
JOINT_INTRINSICS_MODEL = CovarianceModel.JOINT_INTRINSICS
RANGE_ONLY_MODEL = CovarianceModel.RANGE_ONLY
"""The values of a result's ``info["covariance_model"]``: which likelihood produced its covariance."""

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
    estimated), the robust loss's scale ``f_scale_sigmas`` in noise stds, at most ``max_iter`` iterations; ``widen``:
    the covariance widened where the boards disagree beyond the model (``refine.dispersion``); ``outline``: the
    lower-bound outlines' terms in the cost (``refine.joint_outline``); ``bend``: the covariance takes the
    likelihood's bend along its weakest direction (``refine.bend``); ``board_error``: with a per-board systematic
    error (``refine.systematic``)."""

    use_corners: bool = True
    corner_sigma_px: float | None = None
    f_scale_sigmas: float = F_SCALE_SIGMAS
    max_iter: int = MAX_ITER
    widen: bool = True
    outline: bool = False
    bend: bool = True
    board_error: bool = True


_DRHO = {"linear": lambda z: np.ones_like(z), "huber": lambda z: np.where(z <= 1, 1.0, 1 / np.sqrt(np.maximum(z, 1))),
         "soft_l1": lambda z: 1 / np.sqrt(1 + z), "cauchy": lambda z: 1 / (1 + z), "arctan": lambda z: 1 / (1 + z**2)}
"""rho'(z) of scipy's robust losses (``z`` the squared residual over the squared scale): the IRLS weights."""


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
    """The damped Gauss-Newton step (global (G,): the extrinsic, then any free intrinsics; boards (N,6)) by the
    Schur complement on the board blocks."""
    G = len(g_e)
    Dbb = H_bb + lam * np.einsum("nii->ni", H_bb)[:, :, None] * np.eye(6)
    Dee = H_ee + lam * np.diag(np.diag(H_ee))
    X = np.linalg.solve(Dbb, np.concatenate([np.swapaxes(H_eb, 1, 2), g_b[:, :, None]], axis=2))
    S = Dee - np.einsum("nab,nbc->ac", H_eb, X[:, :, :G])
    de = np.linalg.solve(S, -g_e + np.einsum("nab,nb->a", H_eb, X[:, :, G]))
    db = -X[:, :, G] - np.einsum("nab,b->na", X[:, :, :G], de)
    return de, db


def _apply(T_e, T_b, de, db):
    Tb = T_b.copy()
    Tb[:, :3, :3] = rotvec_to_matrix(db[:, :3]) @ T_b[:, :3, :3]
    Tb[:, :3, 3] += db[:, 3:]
    return perturb(T_e, de[:6]), Tb


def _blocks(obs, offsets, weighted, w, prior, k):
    """The (IRLS-weighted) Gauss-Newton blocks of the linearisation ``weighted`` (``model.corners.normalised_rows``'
    output), with the free intrinsics appended to the global block when there is a ``prior``."""
    e, Jc, Je, Jb = weighted[:4]
    nc = len(Jc)
    blocks = _normal_equations(obs, offsets, e * w, Jc * w[:nc, None], Je * w[nc:, None], Jb * w[nc:, None])
    if prior is None:
        return blocks
    return augmented_blocks(blocks, offsets[0], (e * w)[:nc], Jc * w[:nc, None], weighted[4] * w[:nc, None],
                            prior.residuals(k), prior.std)


def _solve(obs, T_e, T_b, sc, sr, loss, f_scale_sigmas, max_iter, tol=COST_RTOL, prior=None, k=None, outline=False,
           mounting=None, hold=None):
    """Levenberg-Marquardt on the joint cost, each step by the Schur complement (linear in the boards); robust
    losses by iteratively reweighted least squares (the intrinsics prior's, the mounting prior's and a held
    direction's rows are Gaussian, never reweighted). Returns (T_e, T_b, cost, iterations, converged, k) (``k``
    the free intrinsics; None without an intrinsics prior)."""
    drho = _DRHO[loss]
    offsets = board_row_offsets(obs)

    def cost_of(Te, Tb, kk):
        c = robust_cost(normalised_rows(obs, Te, Tb, sc, sr, False, prior, kk), loss, f_scale_sigmas)
        c += (outline_cost(obs, Te, Tb) if outline else 0.0) + mounting_cost(mounting, Te) + mounting_cost(hold, Te)
        return c if prior is None else c + 0.5 * float(np.sum(prior.residuals(kk) ** 2))

    cost, lam, it = cost_of(T_e, T_b, k), INITIAL_LAMBDA, 0
    for it in range(1, max_iter + 1):
        lin = normalised_rows(obs, T_e, T_b, sc, sr, True, prior, k)
        w = np.sqrt(drho((lin[0] / f_scale_sigmas) ** 2))
        blocks = _blocks(obs, offsets, lin, w, prior, k)
        blocks = with_outline(blocks, obs, T_e, T_b) if outline else blocks
        blocks = with_mounting(blocks, mounting, T_e) if mounting is not None else blocks
        blocks = with_mounting(blocks, hold, T_e) if hold is not None else blocks
        while True:
            de, db = _schur_step(*blocks, lam)
            Te, Tb = _apply(T_e, T_b, de, db)
            kn = None if prior is None else k + de[6:]
            try:
                new = cost_of(Te, Tb, kn)
            except (JointError, ObservationError):  # a corner behind the camera, or implausible intrinsics
                new = np.inf
            if new <= cost:
                break
            lam *= LAMBDA_FACTOR
            if lam > MAX_LAMBDA:
                return T_e, T_b, cost, it, True, k
        T_e, T_b, k, old, cost = Te, Tb, kn, cost, new
        lam = max(lam / LAMBDA_FACTOR, MIN_LAMBDA)
        if old - cost <= tol * max(cost, 1e-300) or max(np.abs(de).max(), np.abs(db).max()) < STEP_TOL:
            return T_e, T_b, cost, it, True, k
    return T_e, T_b, cost, it, False, k


@dataclass(frozen=True, eq=False)
class JointResult:
    """Outcome of ``joint_refine``.

    Attributes:
        T_lidar_cam: 4x4 extrinsic; T_cam_board: (N,4,4) refined board poses; covariance: 6x6 of the extrinsic
        (rotation rad then translation m, board poses marginalised); corner_sigma_px, range_sigma_m: the noise
        stds used (given or estimated); corner_rms_px, range_rms_m: RMS of the final residuals; cost: final
        ``0.5 sum rho`` of the normalised residuals; iterations: of the last solve; converged: whether it met the
        tolerance within ``max_iter``; camera: the camera at the estimated intrinsics when they were unknowns
        (``camera.std_intrinsics``), else None (taken as exact); intrinsics: those free intrinsics (the values
        of ``refine.joint_intrinsics.IntrinsicsPrior``), else None.
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
    camera: CameraModel | None = None
    intrinsics: np.ndarray | None = None


def estimate_sigmas(obs, T_e, T_b, n_params_boards: int, camera=None):
    ec = corner_residuals(obs, T_b, camera=camera)
    er = joint_range_residuals(obs, T_e, T_b)
    return (max(residual_sigma(ec, n_params_boards), CORNER_SIGMA_FLOOR_PX),
            max(residual_sigma(er, 6), RANGE_SIGMA_FLOOR_M))


def joint_refine(obs: Observations, T0: np.ndarray, *, corner_sigma_px: float | None = None,
                 range_sigma_m: float | None = None, loss: str = "linear", f_scale_sigmas: float = F_SCALE_SIGMAS,
                 max_iter: int = MAX_ITER, sigma_iters: int = 3, sigma_rtol: float = 0.05,
                 intrinsics: bool = True, outline: bool = False, mounting: MountingPrior | None = None,
                 hold: HeldDirection | None = None, covariance: bool = True,
                 start: JointResult | None = None, tol: float = COST_RTOL,
                 board_error: BoardErrorScale | None = None) -> JointResult:
    """Maximise the joint likelihood from the extrinsic ``T0`` and the observed board poses.

    Args:
        corner_sigma_px, range_sigma_m: noise stds; ``None`` estimates each from its own residuals (corners:
            ``2J - 6N`` degrees of freedom, ranges ``K - 6``), re-solving until they change by less than
            ``sigma_rtol`` (at most ``sigma_iters`` solves). Start values: the corner RMS at the observed poses,
            the scan-line estimate of ``data.lines.range_sigma`` (floored by ``START_*``).
        loss, f_scale_sigmas: robust loss (``refine.Loss``) on the normalised residuals, its scale in noise stds.
        intrinsics: when the camera states ``std_intrinsics``, estimate the intrinsics too, with that Gaussian
            prior (``refine.joint_intrinsics``), so the covariance holds their error; False takes them as exact.
        outline: the lower-bound outlines' chord and margin terms in the cost (``refine.joint_outline``).
        mounting: a mounting prior (``geometry.mounting.MountingPrior``) in the cost: the answer is the posterior's
            mode. The covariance is the data's alone (``methods.finish.with_prior`` adds the prior's information).
        hold: one direction of the extrinsic held at a value (``refine.bend.HeldDirection``, a Gaussian row in the
            cost like the mounting prior's): the re-fits of ``refine.bend``.
        covariance: False skips the covariance (``JointResult.covariance`` is None).
        start: an earlier answer whose board poses and intrinsics start the solve (with the extrinsic ``T0``).
        tol: a solve has converged when a step lowers the cost by less than this fraction of it.
        board_error: a per-board systematic error the covariance holds (``intrinsics_marginal_covariance``).
    Raises:
        JointError: no corners or camera; UncertaintyError: the joint information is singular.
    """
    T_e, T_b = np.asarray(T0, float), board_poses(obs) if start is None else start.T_cam_board
    est_c, _ = estimate_sigmas(obs, T_e, T_b, 6 * obs.n_boards)
    # start weights from each sensor alone, floored so that neither sensor swamps the other before the solve
    sc = corner_sigma_px if corner_sigma_px is not None else max(est_c, START_CORNER_SIGMA_PX)
    sr = range_sigma_m if range_sigma_m is not None else max(range_sigma(obs), START_RANGE_SIGMA_M)
    prior = IntrinsicsPrior.of(obs.camera) if intrinsics else None
    k = None if prior is None else prior.k0.copy() if start is None or start.intrinsics is None else \
        start.intrinsics.copy()
    n_free = 6 * obs.n_boards + (0 if prior is None else prior.size)  # the corners' parameters: poses, intrinsics
    for _ in range(max(1, sigma_iters)):
        T_e, T_b, _, nit, converged, k = _solve(obs, T_e, T_b, sc, sr, loss, f_scale_sigmas, max_iter, tol,
                                                prior=prior, k=k, outline=outline, mounting=mounting, hold=hold)
        cam = None if prior is None else prior.camera_at(k)
        new_c, new_r = estimate_sigmas(obs, T_e, T_b, n_free, cam)
        new_c = corner_sigma_px if corner_sigma_px is not None else new_c
        new_r = range_sigma_m if range_sigma_m is not None else new_r
        done = abs(new_c / sc - 1) < sigma_rtol and abs(new_r / sr - 1) < sigma_rtol
        sc, sr = new_c, new_r
        if done:
            break
    cov = None if not covariance else \
        intrinsics_marginal_covariance(obs, T_e, T_b, sc, sr, prior, k, outline, board_error=board_error)[:6, :6] \
        if prior is not None or (outline and has_outline_rows(obs)) or board_error is not None else \
        marginal_covariance(obs, T_e, T_b, sc, sr)
    ec = corner_residuals(obs, T_b, camera=cam)
    er = joint_range_residuals(obs, T_e, T_b)
    cost = robust_cost(np.r_[ec.ravel() / sc, er / sr], loss, f_scale_sigmas) + \
        (outline_cost(obs, T_e, T_b) if outline else 0.0) + mounting_cost(mounting, T_e) + mounting_cost(hold, T_e)
    if prior is not None:
        cost += 0.5 * float(np.sum(prior.residuals(k) ** 2))
    return JointResult(T_e, T_b, cov, sc, sr, float(np.sqrt(np.mean(np.sum(ec**2, axis=1)))),
                       float(np.sqrt(np.mean(er**2))), cost, nit, converged, cam, k)


def intrinsics_marginal_covariance(obs: Observations, T_lidar_cam: np.ndarray, T_cam_board: np.ndarray,
                                   corner_sigma_px: float, range_sigma_m: float, prior: IntrinsicsPrior | None,
                                   k: np.ndarray | None, outline: bool = False, rcond: float = 1e-12,
                                   board_error: BoardErrorScale | None = None) -> np.ndarray:
    """Covariance (6+m, 6+m) of the extrinsic (rotation rad, translation m) and the free intrinsics ``k`` of
    ``prior`` (their units; none without one), board poses marginalised by the Schur complement: the inverse of
    ``H_gg - sum_i H_gi H_ii^-1 H_ig`` with the prior's information in ``H_gg`` and with ``outline`` the active
    lower-bound outline rows' (``refine.joint_outline``), and a per-board systematic error ``board_error``
    (``refine.systematic.with_systematic``). Linear in the boards.

    UncertaintyError when a board's pose or the extrinsic is not determined.
    """
    lin = normalised_rows(obs, np.asarray(T_lidar_cam, float), np.asarray(T_cam_board, float), float(corner_sigma_px),
                    float(range_sigma_m), True, prior, k)
    blocks = _blocks(obs, board_row_offsets(obs), lin, np.ones(len(lin[0])), prior, k)
    _, _, H_gg, H_gb, H_bb = with_outline(blocks, obs, T_lidar_cam, T_cam_board) if outline else blocks
    try:
        X = np.linalg.solve(H_bb, np.swapaxes(H_gb, 1, 2))
    except np.linalg.LinAlgError:
        raise UncertaintyError("a board's pose is not determined by its corners") from None
    return with_systematic(inverse_information(H_gg - np.einsum("nab,nbc->ac", H_gb, X), rcond), board_error,
                           scan_data_at(obs, T_cam_board), T_lidar_cam, lin, H_gb, H_bb, range_sigma_m,
                           board_row_offsets(obs)[1])


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
    _, Jc, Je, Jb = normalised_rows(obs, T_e, T_b, float(corner_sigma_px), float(range_sigma_m), True)
    oc, os = board_row_offsets(obs)
    H_bb = np.add.reduceat(np.einsum("ra,rb->rab", Jc, Jc), oc) + np.add.reduceat(np.einsum("ra,rb->rab", Jb, Jb), os)
    H_eb = np.add.reduceat(np.einsum("ra,rb->rab", Je, Jb), os)
    H_ee = np.add.reduceat(np.einsum("ra,rb->rab", Je, Je), os)
    try:
        X = np.linalg.solve(H_bb, np.swapaxes(H_eb, 1, 2))          # H_ii^-1 H_ie, (N,6,6)
    except np.linalg.LinAlgError:
        raise UncertaintyError("a board's pose is not determined by its corners") from None
    return H_ee - H_eb @ X


def board_scores(obs: Observations, T_lidar_cam: np.ndarray, T_cam_board: np.ndarray, corner_sigma_px: float,
                 range_sigma_m: float, camera: CameraModel | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each board's score (N,6), the gradient of its normalised cost in the extrinsic (rad, m), its pose profiled
    out to first order (``g_e - H_eb H_bb^-1 g_b``), and its information (N,6,6; ``board_informations``), at
    ``camera``'s intrinsics (default the file's): what ``refine.dispersion`` tests."""
    if camera is not None:
        obs = replace(obs, camera=camera)
    T_e, T_b = np.asarray(T_lidar_cam, float), np.asarray(T_cam_board, float)
    e, Jc, Je, Jb = normalised_rows(obs, T_e, T_b, float(corner_sigma_px), float(range_sigma_m), True)
    offsets = board_row_offsets(obs)
    _, g_b, _, H_eb, H_bb = _normal_equations(obs, offsets, e, Jc, Je, Jb)
    H_ee = np.add.reduceat(np.einsum("ra,rb->rab", Je, Je), offsets[1])
    g_e = np.add.reduceat(Je * e[len(Jc):, None], offsets[1])
    try:
        X = np.linalg.solve(H_bb, np.concatenate([np.swapaxes(H_eb, 1, 2), g_b[:, :, None]], axis=2))
    except np.linalg.LinAlgError:
        raise UncertaintyError("a board's pose is not determined by its corners") from None
    return g_e - np.einsum("nab,nb->na", H_eb, X[:, :, 6]), H_ee - H_eb @ X[:, :, :6]


def marginal_covariance(obs: Observations, T_lidar_cam: np.ndarray, T_cam_board: np.ndarray, corner_sigma_px: float,
                        range_sigma_m: float, rcond: float = 1e-12) -> np.ndarray:
    """The extrinsic block (6x6) of the inverse joint information: ``(H_ee - sum_i H_ei H_ii^-1 H_ie)^-1``.

    UncertaintyError when a board's pose or the extrinsic is not determined.
    """
    S = board_informations(obs, T_lidar_cam, T_cam_board, corner_sigma_px, range_sigma_m).sum(axis=0)
    return inverse_information(S, rcond)


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
