"""The scale of the per-board systematic error (``calib_core.model.board_error``): stated by the observation file,
estimated from the boards by restricted maximum likelihood, or a prior where the boards leave too few degrees of
freedom.

Estimate. At an answer ``T`` (the range model's, board poses as observed), each board's range residuals ``r_i``
reduce to their two coefficients on the term's columns, ``c_i = G_i^-1 B_i^T r_i`` (``G_i = B_i^T B_i``): the
offset and tilt of the board's scan line against its plane. What is left within the board is per-beam noise and
carries no information on the term. Linearised in the extrinsic ``x`` (6), ``c_i = C_i x + u_i + v_i`` with
``C_i = G_i^-1 B_i^T J_i``, the term ``u_i ~ N(0, diag(theta_o, theta_t))`` and ``v_i ~ N(0, K_i)``,
``K_i = sigma^2 G_i^-1 + Cb_i Sigma_b,i Cb_i^T``: the beams' noise (``sigma`` of the scan lines) and, with image
corners, the camera's board-pose error from its corner noise alone (``Sigma_b,i = sigma_c^2 (Jc_i^T Jc_i)^-1``,
``Cb_i = G_i^-1 B_i^T Jb_i``), so that the camera's known error is not counted as the lidar's. With
``V_i = K_i + diag(theta)`` the restricted log-likelihood (the extrinsic integrated out) is

    l_R(theta) = -1/2 [ sum log det V_i + log det A + sum c_i^T V_i^-1 c_i - b^T A^-1 b ],
    A = sum C_i^T V_i^-1 C_i,  b = sum C_i^T V_i^-1 c_i,

on ``2N - 6`` degrees of freedom (none at three boards). The prior enters as a normal density of each
``log theta`` about the prior's ``log s0^2`` with std ``PRIOR_LOG_SD``: ``-1/2 ((log theta - log s0^2) /
PRIOR_LOG_SD)^2``, mixed with a point mass ``PRIOR_NONE`` on no error at all (both variances at the grid's
smallest): boards that show no systematic error (a renderer's) bring the estimate near zero, boards that show one
are judged by the log-normal alone, and the estimate stays near the prior where the boards have few degrees of
freedom.
The estimate is the square root of each variance's posterior mean over a grid of ``log theta``
(``estimate_scale``), its 1-sigma the scale's posterior std. With
``ESTIMATE_MIN_BOARDS`` boards or more the estimate is used; below, the prior (3-4 boards: 0-2 degrees of freedom
for two components).

The prior (``DEFAULT_PRIOR``) is measured on the public rigs: docs/lidarcam.md, "Per-board systematic error".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.lines import range_sigma, residual_sigma
from ..data.observations import Observations, ScanData
from ..errors import JointError
from ..model.board_error import BoardErrorScale, per_board_sum, systematic_basis
from ..model.corners import board_poses, corner_residuals, joint_range_residuals
from ..model.residuals import range_linearised

DEFAULT_PRIOR = BoardErrorScale(offset_m=0.0058, tilt_m=0.0020)
"""The prior scale of the per-board systematic error (metres; offset along the normal, tilt as the RMS
displacement of the board's scan points), measured on the public rigs: each variance the mean over EdenShin,
Kazmierczak and Nowicki of their restricted maximum likelihood estimates without a prior (docs/lidarcam.md)."""
PRIOR_LOG_SD = 2.0
"""Width of the prior in the estimate: each variance's log is Normal about the prior's with this std (a factor
``e`` in the scale per std): the boards' own disagreement moves the estimate where they have the degrees of
freedom, down to near zero on boards that show none, and leaves it near the prior where they have few."""
PRIOR_NONE = 0.5
"""Prior probability that the rig has no per-board systematic error at all, offset and tilt alike (a renderer, a
clean simulation): this much of the prior sits on the grid's smallest scale of both components (``GRID_SCALES_M``,
0.05 mm: none, for a calibration), the rest is the log-normal about ``DEFAULT_PRIOR``. Without it, boards that show
no systematic error still estimate the scale at about their own coefficients' noise (the restricted likelihood is
flat below it and the log-normal's lower tail holds mass there): the demo's renders gave 1.1 / 0.4 mm and a
covariance 2.5x too large (NEES median 2.3 over 50 seeds; ``dev/demo_nees.py``). Boards that do show one outweigh it
(their likelihood at zero is negligible): the public rigs' all-board estimates do not move (docs/lidarcam.md)."""
ESTIMATE_MIN_BOARDS = 5
"""Fewest boards whose disagreement estimates the scale (4 boards leave 2 degrees of freedom for 2 components)."""
STATED, ESTIMATED, PRIOR = "stated", "estimated", "prior"
"""Where a scale came from (``BoardErrorEstimate.source``)."""


@dataclass(frozen=True)
class BoardErrorEstimate:
    """The per-board systematic error's scale used, its source (``STATED``: the file's ``board_range_sigma_m``,
    an offset, no tilt; ``ESTIMATED``; ``PRIOR``), the boards' degrees of freedom for it (``2N - 6``), the 1-sigma
    of the estimate's two scales (metres; None unless estimated) and the prior."""

    scale: BoardErrorScale
    source: str
    dof: int
    se_offset_m: float | None = None
    se_tilt_m: float | None = None
    prior: BoardErrorScale = DEFAULT_PRIOR

    def to_dict(self) -> dict:
        """``info["board_error"]``: scales in metres and where they came from."""
        return {"offset_m": self.scale.offset_m, "tilt_m": self.scale.tilt_m, "source": self.source,
                "dof": self.dof, "se_offset_m": self.se_offset_m, "se_tilt_m": self.se_tilt_m,
                "prior_offset_m": self.prior.offset_m, "prior_tilt_m": self.prior.tilt_m, "prior_log_sd": PRIOR_LOG_SD,
                "prior_none": PRIOR_NONE}


@dataclass(frozen=True, eq=False)
class BoardCoefficients:
    """Each board's coefficients ``c`` (N,2), their extrinsic Jacobian ``C`` (N,2,6) and known covariance ``K``
    (N,2,2) at an answer (module docstring)."""

    c: np.ndarray
    C: np.ndarray
    K: np.ndarray


def board_coefficients(obs: Observations, T: np.ndarray, range_sigma_m: float | None = None) -> BoardCoefficients:
    """``BoardCoefficients`` of ``obs`` at the extrinsic ``T`` (range model, board poses as observed); the
    camera's board-pose error from the corner noise in ``K`` where every board has corners."""
    T = np.asarray(T, float)
    data, N = obs.scan_data, obs.n_boards
    e, J = range_linearised(T, data)
    B = systematic_basis(data, data.normals @ T[:3, :3].T)
    Gi = np.linalg.inv(per_board_sum(np.einsum("ka,kb->kab", B, B), data.board, N))
    c = np.einsum("nab,nb->na", Gi, per_board_sum(B * e[:, None], data.board, N))
    C = Gi @ per_board_sum(np.einsum("ka,kp->kap", B, J), data.board, N)
    K = range_sigma(obs, range_sigma_m) ** 2 * Gi
    if obs.has_corners and obs.camera is not None:
        try:
            K = K + _camera_part(obs, T, B, Gi)
        except (JointError, np.linalg.LinAlgError):
            pass
    return BoardCoefficients(c, C, K)


def _camera_part(obs: Observations, T: np.ndarray, B: np.ndarray, Gi: np.ndarray) -> np.ndarray:
    """``Cb_i Sigma_b,i Cb_i^T`` (N,2,2): the camera's board-pose error (corner noise alone) in the coefficients."""
    N = obs.n_boards
    Tb = board_poses(obs)
    ec, Jc = corner_residuals(obs, Tb, jacobian=True)
    sc = residual_sigma(ec, 6 * N)
    idx = np.concatenate([np.full(len(b.corners_px), i) for i, b in enumerate(obs.boards)])
    H = per_board_sum(np.einsum("jca,jcb->jab", Jc, Jc), idx, N)          # (N,6,6)
    Sb = sc**2 * np.linalg.inv(H)
    _, _, Jb = joint_range_residuals(obs, T, Tb, jacobian=True)
    Cb = Gi @ per_board_sum(np.einsum("ka,kp->kap", B, Jb), obs.scan_data.board, N)       # (N,2,6)
    return Cb @ Sb @ np.swapaxes(Cb, 1, 2)


ESTIMABLE_RCOND = 1e-9
"""Relative eigenvalue of ``sum C_i^T C_i`` below which a direction of the extrinsic is not in the coefficients at
all (the boards leave it free): ``_estimable`` drops it from what the restricted likelihood integrates out."""


def _estimable(C: np.ndarray) -> np.ndarray:
    """The coefficients' extrinsic Jacobian ``C`` (N,2,6) on the directions of the extrinsic it sees (N,2,r): the
    eigen-directions of ``sum C_i^T C_i`` above ``ESTIMABLE_RCOND`` of the largest. A direction the boards leave
    free moves no coefficient, so it is no parameter of theirs to integrate out (with it ``A`` is singular)."""
    w, U = np.linalg.eigh(np.einsum("nap,naq->pq", C, C))
    return C @ U[:, w > ESTIMABLE_RCOND * max(float(w[-1]), 1e-300)]


def restricted_loglik(theta: np.ndarray, co: BoardCoefficients) -> np.ndarray:
    """``l_R(theta)`` (module docstring) at the variances ``theta`` (..., 2) (m^2), without the prior."""
    theta = np.asarray(theta, float)
    shape = theta.shape[:-1]
    th = theta.reshape(-1, 1, 2)
    V = co.K[None] + th[..., :, None] * np.eye(2)                                     # (M,N,2,2)
    Vi = np.linalg.inv(V)
    Cq = _estimable(co.C)
    A = np.einsum("nap,mnab,nbq->mpq", Cq, Vi, Cq)
    b = np.einsum("nap,mnab,nb->mp", Cq, Vi, co.c)
    sA, ldA = np.linalg.slogdet(A)
    quad = np.einsum("na,mnab,nb->m", co.c, Vi, co.c) - np.einsum("mp,mp->m", b,
                                                                   np.linalg.solve(A, b[..., None])[..., 0])
    out = -0.5 * (np.sum(np.linalg.slogdet(V)[1], axis=1) + ldA + quad)
    return np.where(sA > 0, out, -np.inf).reshape(shape)


GRID_SCALES_M = np.geomspace(5e-5, 0.05, 61)
"""The scales (metres) over which the estimate integrates, each component: 0.05 mm (none, for a calibration) to
50 mm (beyond a board's flatness or a lidar's bias)."""


def _grid_prior(g: np.ndarray, variances: np.ndarray, prior_sd: float, none_prob: float) -> np.ndarray:
    """The prior's weights (G,G) over the grid ``g`` (log variances, ascending) of the two components (they sum to
    1): ``none_prob`` on the grid's first point of both (no such error) and the rest spread as independent normals
    of each ``log theta`` about the log of its ``variances`` (2,) with std ``prior_sd`` (module docstring)."""
    q = [np.exp(-0.5 * ((g - np.log(v)) / prior_sd) ** 2) for v in variances]
    w = (1.0 - none_prob) * np.outer(q[0] / q[0].sum(), q[1] / q[1].sum())
    w[0, 0] += none_prob
    return w


def estimate_scale(co: BoardCoefficients, prior: BoardErrorScale = DEFAULT_PRIOR, prior_sd: float = PRIOR_LOG_SD,
                   none_prob: float = PRIOR_NONE) -> tuple[BoardErrorScale, np.ndarray]:
    """The scale's estimate (module docstring): the square root of each variance's posterior mean under the
    restricted likelihood and the prior (``prior_sd`` its width in ``log theta``, ``inf``: the boards alone, flat
    in ``log theta``; ``none_prob`` the prior probability of no such error at all, ``PRIOR_NONE``), over
    ``GRID_SCALES_M`` each; and the scale's 1-sigma (2,) (metres), its posterior std. A posterior mean, not the
    mode: with few degrees of freedom the restricted likelihood is wide and skewed, and its mode falls near zero by
    chance on a set of boards that agree. Of the variance, not of the scale: the covariances that hold the term
    (the sandwiches of ``with_systematic`` and ``uncertainty.refinement_covariance``) are linear in the variances,
    so the covariance at the variances' posterior mean is the covariance averaged over what the boards leave
    uncertain in the scale (the scale's posterior mean would drop its spread: ``E[s]^2 = E[s^2] - sd^2``, 2x too
    small a variance at 6 boards on EdenShin)."""
    g = np.log(GRID_SCALES_M**2)
    X = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1)                             # (G,G,2) log theta
    logp = restricted_loglik(np.exp(X), co)
    if np.isfinite(prior_sd):
        logp = logp + np.log(_grid_prior(g, prior.variances, prior_sd, none_prob))
    w = np.exp(logp - np.max(logp))
    w /= w.sum()
    s = np.exp(0.5 * X)
    mean, var = np.einsum("ij,ijc->c", w, s), np.einsum("ij,ijc->c", w, s**2)
    sd = np.sqrt(np.maximum(var - mean**2, 0.0))
    rms = np.sqrt(var)
    return BoardErrorScale(float(rms[0]), float(rms[1])), sd


def board_error_estimate(obs: Observations, T: np.ndarray, range_sigma_m: float | None = None,
                         prior: BoardErrorScale = DEFAULT_PRIOR) -> BoardErrorEstimate:
    """The per-board systematic scale for ``obs`` at the answer ``T``: the file's ``board_range_sigma_m`` where it
    states one (an offset, no tilt), else estimated from the boards (``ESTIMATE_MIN_BOARDS`` or more), else the
    prior."""
    dof = max(2 * obs.n_boards - 6, 0)
    if obs.board_range_sigma_m is not None:
        return BoardErrorEstimate(BoardErrorScale(float(obs.board_range_sigma_m), 0.0), STATED, dof, prior=prior)
    if obs.n_boards < ESTIMATE_MIN_BOARDS:
        return BoardErrorEstimate(prior, PRIOR, dof, prior=prior)
    scale, se = estimate_scale(board_coefficients(obs, T, range_sigma_m), prior)
    se = [float(v) if np.isfinite(v) else None for v in se]
    return BoardErrorEstimate(scale, ESTIMATED, dof, se[0], se[1], prior)


def fold_noise_ratio(data: ScanData, T: np.ndarray, scale: BoardErrorScale, range_sigma_m: float) -> float:
    """How much the per-board systematic error ``scale`` adds to what the beams' noise (std ``range_sigma_m``)
    leaves in the boards' offsets and tilts at the extrinsic ``T``: ``sum_i tr(sigma^2 G_i^-1 + P) / sum_i
    tr(sigma^2 G_i^-1)`` (module docstring; 1 without the term). At a fold of three boards' solutions the answer
    along the fold moves with these coefficients at second order (its profile likelihood is quartic there), so
    the fold's profile 1-sigma, computed under the beams' noise alone, grows by this ratio's fourth root
    (``methods.last_steps.fold_covariance``): the ratio of the effective noise's variance to the beams', taken
    over the boards alike since the fold's own combination of them is not at hand."""
    if not scale.active:
        return 1.0
    B = systematic_basis(data, data.normals @ np.asarray(T, float)[:3, :3].T)
    G = per_board_sum(np.einsum("ka,kb->kab", B, B), data.board, len(data.normals))
    known = float(range_sigma_m) ** 2 * np.trace(np.linalg.inv(G), axis1=1, axis2=2)
    return float((known.sum() + len(known) * scale.variances.sum()) / known.sum())


def with_systematic(C: np.ndarray, scale: BoardErrorScale | None, data: ScanData, T_e: np.ndarray, lin: tuple,
                    H_gb: np.ndarray, H_bb: np.ndarray, sr: float, starts: np.ndarray) -> np.ndarray:
    """The joint model's covariance ``C`` (G,G) of its shared parameters (extrinsic, then any free intrinsics;
    ``calib_core.refine.joint``, board poses marginalised) with the per-board systematic error ``scale`` held (``C``
    itself without one): the answer is weighed by the per-beam noise, so its covariance under the term is the
    sandwich ``C + C M C``, ``M = sum_i w_i P w_i^T / sr^2`` the term's part of the profiled score covariance,
    ``w_i = V_g,i^T - H_gb,i H_bb,i^-1 V_b,i^T`` (G,2) with ``V_i = B_i^T J_i`` the term's columns
    (``model.board_error.systematic_basis`` on ``data``, the scan points with the current board planes) on the
    board's normalised range rows (``lin``: ``model.corners.normalised_rows``' output, ``Je`` (K,6) extrinsic and
    ``Jb`` (K,6) board pose columns; the intrinsics' are zero on range rows; rows of board i from ``starts[i]``) and
    ``P`` the term's variances. Linear in the boards."""
    if scale is None or not scale.active:
        return C
    Je, Jb = lin[2], lin[3]
    B = systematic_basis(data, data.normals @ np.asarray(T_e, float)[:3, :3].T)
    N, G = len(data.normals), H_gb.shape[1]
    Vx = np.add.reduceat(np.einsum("ka,kp->kap", B, Je), starts)                      # (N,2,6)
    Vb = np.add.reduceat(np.einsum("ka,kp->kap", B, Jb), starts)                      # (N,2,6)
    Vg = np.zeros((N, G, 2))
    Vg[:, :6, :] = np.swapaxes(Vx, 1, 2)
    W = Vg - H_gb @ np.linalg.solve(H_bb, np.swapaxes(Vb, 1, 2))                       # (N,G,2)
    M = np.einsum("nga,a,nha->gh", W, scale.variances / float(sr) ** 2, W)
    C = C + C @ M @ C
    return 0.5 * (C + C.T)
