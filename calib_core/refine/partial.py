"""Calibrating only what the data determine: the free mounting parameters (``geometry.mounting``) refined on the
scan residuals with the others held at values the user gives, and the covariance of what was estimated.

A rig whose boards all stand vertical determines yaw and the horizontal offsets x, y but not roll, pitch or the
height z (``calib_core.checks.degeneracy``): give those (e.g. a measured mounting height and a level mount) and the
planar part is estimated, with its covariance. ``vertical_start`` also gives such a rig a first extrinsic
without any given value, for the degeneracy analysis.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from ..data.lines import range_sigma, tls_line
from ..data.observations import Observations
from ..errors import SolveFailure, UncertaintyError
from ..geometry.mounting import PARAMS, UNIT_NAMES, T_from_params, params_from_T, params_jacobian, with_units
from ..geometry.transforms import make_T
from ..model.board_error import BoardErrorScale
from ..model.residuals import RESIDUALS
from .refine import MAX_NFEV, loss_name
from .uncertainty import refinement_covariance

PLANAR_FIXED = np.array([True, True, False, False, False, True])
"""roll, pitch and z given: the planar case, with a closed-form start (``planar_start``)."""

FIXED_NOTE = ("fixed parameters are held at the given values, not estimated: their rows and columns of the "
              "covariance are 0")
PRIOR_FIXED_NOTE = ("the parameters the boards leave free are held at the mounting prior's values, not estimated: "
                    "their 1-sigma is the prior's, carried through the fit to the others")


def _scan_line_normals(obs: Observations) -> tuple[np.ndarray, np.ndarray]:
    """Per board, the unit 2D normal of its scan line pointing away from the lidar (N,2) and the line's offset
    along it (N,) (metres): the line is ``nu . p = c`` with ``c >= 0``."""
    nu, c = np.empty((obs.n_boards, 2)), np.empty(obs.n_boards)
    for i, b in enumerate(obs.boards):
        centre, u, _, _ = tls_line(b.scan)
        nu[i] = [-u[1], u[0]]
        c[i] = nu[i] @ centre
    flip = c < 0
    nu[flip], c[flip] = -nu[flip], -c[flip]
    return nu, c


def _horizontal_offsets(obs: Observations, R: np.ndarray, z: float) -> np.ndarray:
    """Least-squares ``(x, y)`` of the camera given its rotation ``R_lidar_cam`` and height ``z``: every scan point
    ``p`` on board i satisfies ``m_xy . (x, y) = m . p - d - m_z z`` with ``m = R n_i`` (metres)."""
    data = obs.scan_data
    m = (data.normals @ R.T)[data.board]
    rhs = np.einsum("kj,kj->k", m, data.points) - data.offsets[data.board] - m[:, 2] * z
    A = m[:, :2]
    if np.linalg.matrix_rank(A.T @ A, tol=1e-9 * max(np.trace(A.T @ A), 1e-300)) < 2:
        raise SolveFailure("the boards' scan lines are all parallel: the horizontal offsets are not determined")
    return np.linalg.lstsq(A, rhs, rcond=None)[0]


def planar_start(obs: Observations, theta: np.ndarray) -> np.ndarray:
    """``T_lidar_cam`` with roll, pitch and z from ``theta`` (radians, metres) and yaw, x, y in closed form.

    Board normals ``m0 = Ry(pitch) Rx(roll) R_BODY_OPTICAL n``; yaw turns their horizontal parts onto the scan
    lines' normals (2D Procrustes, weighted by the points per board); then (x, y) by linear least squares over
    every scan point. Exact on noise-free data when the given values are the truth.
    """
    theta = np.asarray(theta, float)
    R_rp = T_from_params(np.r_[theta[0], theta[1], 0.0, 0.0, 0.0, 0.0])[:3, :3]
    m0 = obs.planes_cam()[0] @ R_rp.T
    nu, _ = _scan_line_normals(obs)
    w = np.array([len(b.scan) for b in obs.boards], float)
    u = m0[:, :2]
    yaw = np.arctan2(np.sum(w * (u[:, 0] * nu[:, 1] - u[:, 1] * nu[:, 0])), np.sum(w * np.einsum("ij,ij->i", u, nu)))
    R = T_from_params(np.r_[theta[0], theta[1], yaw, 0.0, 0.0, 0.0])[:3, :3]
    xy = _horizontal_offsets(obs, R, float(theta[5]))
    return T_from_params(np.r_[theta[0], theta[1], yaw, xy, theta[5]])


def vertical_start(obs: Observations, z: float = 0.0) -> tuple[np.ndarray, float]:
    """A first ``T_lidar_cam`` of a rig whose boards stand vertical, with no given value: the rotation that
    turns every board normal onto its scan line's normal in the scan plane (``Rotation.align_vectors``), the
    horizontal offsets by least squares at height ``z``. Returns it and the RMS misalignment (degrees): large when
    the boards are not vertical. Roll, pitch and z of the result are arbitrary where the rig does not fix them.
    """
    n, _ = obs.planes_cam()
    nu, _ = _scan_line_normals(obs)
    w = np.array([len(b.scan) for b in obs.boards], float)
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)   # scipy warns when the rotation is not unique
        try:
            rot, rssd = Rotation.align_vectors(np.column_stack([nu, np.zeros(len(nu))]), n, weights=w)
        except UserWarning:
            raise SolveFailure("the board normals do not fix a rotation (all parallel)") from None
    R = rot.as_matrix()
    xy = _horizontal_offsets(obs, R, z)
    return make_T(R, np.r_[xy, z]), float(np.degrees(rssd / np.sqrt(w.sum())))


def _refine_free(obs: Observations, theta0: np.ndarray, free: np.ndarray, residual: str, loss: str,
                 f_scale_m: float, max_nfev: int):
    """Minimise the ``residual`` cost over ``theta[free]`` from ``theta0``; returns (theta, scipy result)."""
    fn = RESIDUALS[residual]
    data = obs.scan_data

    def full(x):
        th = theta0.copy()
        th[free] = x
        return th

    def fun(x):
        return fn(T_from_params(full(x)), data)

    def jac(x):
        th = full(x)
        return fn(T_from_params(th), data, jacobian=True)[1] @ params_jacobian(th)[:, free]

    sol = least_squares(fun, theta0[free], jac=jac, method="trf", loss=loss_name(loss), f_scale=f_scale_m,
                        max_nfev=max_nfev, x_scale="jac")
    return full(sol.x), sol


def refine_free(obs: Observations, fixed_mask: np.ndarray, fixed_values: np.ndarray, starts: list[np.ndarray],
                    *, residual: str = "range", loss: str = "linear", f_scale_m: float = 1.0,
                    range_sigma_m: float | None = None, max_nfev: int = MAX_NFEV,
                    fixed_sigma: np.ndarray | None = None,
                    board_error: BoardErrorScale | None = None) -> tuple[np.ndarray, dict]:
    """Refine the free mounting parameters from each start (its fixed parameters replaced by the given values)
    and keep the least cost; returns ``T_lidar_cam`` and ``info``.

    ``info``: ``covariance`` (6x6 in the parameters of ``calib_core.model.residuals``, of rank = the number of free
    parameters), ``covariance_mounting`` (6x6 over ``mounting.PARAMS`` in radians and metres, zero rows and
    columns for the fixed ones), ``mounting`` (all six values, labelled units), ``mounting_sigma`` (1-sigma of
    the free ones, labelled units), ``fixed`` (the given values, labelled units), ``free`` (their names),
    ``note``, and the refinement's cost and evaluations. ``range_sigma_m=None``: the noise is estimated from the
    residuals with ``K - free`` degrees of freedom. ``fixed_sigma``: (6,) the 1-sigma of the given values
    (radians, metres; read at the fixed ones), when they are uncertain (a mounting prior's): the covariance then
    carries it, to the fixed parameters and through the fit to the free ones (``fixed_propagated``), so both
    covariances have full rank and ``mounting_sigma`` holds all six (the answer stays the fit at the given
    values). ``board_error``: the per-board systematic error (``model.board_error``) the free parameters'
    covariance holds (``uncertainty.refinement_covariance``; the beams' noise then the scan lines' unless
    ``range_sigma_m``); None or a zero one: the per-beam model exactly. Raises SolveFailure when no start is given
    or the free parameters are still not determined.
    """
    fixed_mask = np.asarray(fixed_mask, bool)
    free = ~fixed_mask
    if not starts:
        raise SolveFailure("no start for the calibration with fixed parameters")
    best = None
    for T0 in starts:
        theta0 = params_from_T(T0)
        theta0[fixed_mask] = np.asarray(fixed_values, float)[fixed_mask]
        theta, sol = _refine_free(obs, theta0, free, residual, loss, f_scale_m, max_nfev)
        if best is None or sol.cost < best[1].cost:
            best = (theta, sol)
    theta, sol = best
    T = T_from_params(theta)
    M = params_jacobian(theta)
    try:
        term = board_error is not None and board_error.active and residual == "range"
        C_free = refinement_covariance(obs.scan_data, T, residual,
                                       range_sigma(obs, range_sigma_m) if term else range_sigma_m,
                                       basis=M[:, free], board_error=board_error if term else None)
    except UncertaintyError as err:
        names = ", ".join(n for n, f in zip(UNIT_NAMES, free, strict=True) if f)
        raise SolveFailure(f"the free parameters ({names}) are still not determined with the others fixed: {err}",
                           T[None]) from None
    C = np.zeros((6, 6))
    C[np.ix_(free, free)] = C_free
    if fixed_sigma is not None:
        C = fixed_propagated(theta, C, fixed_mask, np.asarray(fixed_sigma, float),
                             lambda t0: _refine_free(obs, t0, free, residual, loss, f_scale_m, max_nfev)[0])
    sig = np.sqrt(np.diag(C))
    units = with_units(theta)
    return T, {"covariance": M @ C @ M.T, "covariance_mounting": C, "mounting": units,
               "mounting_sigma": {k: float(np.degrees(s) if j < 3 else s)
                                  for j, (k, s) in enumerate(zip(UNIT_NAMES, sig, strict=True))
                                  if free[j] or fixed_sigma is not None},
               "fixed": {k: units[k] for j, k in enumerate(UNIT_NAMES) if fixed_mask[j]},
               "free": [PARAMS[j] for j in np.flatnonzero(free)],
               "note": FIXED_NOTE if fixed_sigma is None else PRIOR_FIXED_NOTE,
               "refine_cost": float(sol.cost), "refine_nfev": int(sol.nfev), "n_starts": len(starts)}


GH_NODES, GH_WEIGHTS = np.array([0.0, np.sqrt(3.0), -np.sqrt(3.0)]), np.array([2 / 3, 1 / 6, 1 / 6])
"""The three-point Gauss-Hermite rule for a standard normal: exact for polynomials up to degree 5."""


def fixed_propagated(theta: np.ndarray, C: np.ndarray, fixed_mask: np.ndarray, fixed_sigma: np.ndarray,
                     refit) -> np.ndarray:
    """The covariance ``C`` (6x6 over ``mounting.PARAMS``, zero at the fixed ones) with the fixed values' own
    uncertainty (``fixed_sigma`` at the fixed ones, independent normal) carried through the fit: the fixed values
    moved over the tensor grid of ``GH_NODES`` (``3^n`` points for ``n`` fixed), the free ones re-fitted from
    ``theta`` at each (``refit(theta0) -> theta``), and the weighted second moment of the answers about ``theta``
    (the answer at the given values) added to ``C``. The free parameters do not respond linearly on the scale of
    a rough prior (boards that leave roll and pitch free meet the scan plane at second order in them, and in
    their product), which a first-order propagation or one axis at a time misses."""
    idx = np.flatnonzero(fixed_mask)
    grid = np.stack(np.meshgrid(*[np.arange(3)] * len(idx), indexing="ij"), axis=-1).reshape(-1, len(idx))
    D, w = [], []
    for g in grid:
        t0 = theta.copy()
        t0[idx] += GH_NODES[g] * fixed_sigma[idx]
        D.append((refit(t0) if g.any() else theta) - theta)
        w.append(np.prod(GH_WEIGHTS[g]))
    D = np.array(D)
    return C + (D * np.array(w)[:, None]).T @ D


def fixed_starts(obs: Observations, fixed_mask: np.ndarray, fixed_values: np.ndarray, full_start) -> list[np.ndarray]:
    """Starts for ``refine_free``: the closed-form ``planar_start`` when roll, pitch and z are given, else
    ``full_start()`` (a full calibration's answer; its SolveFailure propagates)."""
    fixed_mask = np.asarray(fixed_mask, bool)
    if np.all(fixed_mask[PLANAR_FIXED]):
        return [planar_start(obs, np.where(fixed_mask, fixed_values, 0.0))]
    return [np.asarray(full_start(), float)]
