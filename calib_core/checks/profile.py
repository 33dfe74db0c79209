"""The profile likelihood of the range model along one direction of the extrinsic: how far the answer can move
along it before the data object, the other five directions re-fitted at every step.

Used by the degeneracy analysis (``checks.degeneracy``) where the range model's first-order information vanishes
along a direction although the board geometry does not leave it free: at a fold of the board set's solutions.
With three boards the six range constraints meet the six unknowns exactly, and where the scan noise has pushed
two of the minimal solver's real solutions together (or just past the point where they turn complex) the
least-squares answer sits where they meet; there the residuals change only at second order along the direction
joining them, so the Fisher information says "no information" while the likelihood itself still rises. The
linear analysis cannot tell this from a direction the boards leave free at every order (vertical boards, fewer
than three planes); the profile can.

Axes and units as ``checks.degeneracy``: a small rigid motion ``T_lidar_cam -> [exp(w) | dt] T_lidar_cam`` about
the lidar's origin, rotations in radians, translations in units of the typical range ``scale_m``.
"""

from __future__ import annotations

import numpy as np

from ..data.observations import ScanData
from ..geometry.transforms import rotvec_to_matrix, skew
from ..model.residuals import range_residuals

PROFILE_ONE_SIGMA = 0.5
"""A profile rise of this (negative log-likelihood, i.e. half a chi-square with one degree of freedom) marks the
1-sigma bound along the direction: the same rule as ``sigma`` of a quadratic profile."""
PROFILE_GN_STEPS = 8
"""Gauss-Newton steps of the other five directions at each point of the profile (they are well determined, so
a few steps converge; the profile is then an upper bound only by their residual error)."""
PROFILE_DOUBLINGS = 12
"""``profile_sigma`` steps out from ``span`` / 2^12 (scaled units) by doublings ..."""
PROFILE_GRID, PROFILE_GRID_ROUNDS = 4, 5
"""... then finds the first crossing inside the bracket on a grid of ``PROFILE_GRID`` intervals, ``PROFILE_GRID_ROUNDS``
times (to 1/1024 of the bracket, as ten bisections would), every point of a grid re-fitted at once."""


def move(T: np.ndarray, x: np.ndarray, scale_m: float) -> np.ndarray:
    """``T_lidar_cam`` (4,4), or a batch (M,4,4), moved by ``x`` (6,) or (M,6) in the scaled lidar-origin axes:
    ``[exp(w) | dt L] T``."""
    x = np.asarray(x, float)
    M = np.broadcast_to(np.eye(4), x.shape[:-1] + (4, 4)).copy()
    M[..., :3, :3] = rotvec_to_matrix(x[..., :3])
    M[..., :3, 3] = x[..., 3:] * scale_m
    return M @ np.asarray(T, float)


def _origin_jacobian(J: np.ndarray, T: np.ndarray, scale_m: float) -> np.ndarray:
    """The residual Jacobian (K,6) of ``data.residuals``, or a batch (M,K,6) at extrinsics (M,4,4), in the scaled
    lidar-origin axes (``degeneracy.origin_jacobian`` with translations scaled)."""
    t = np.asarray(T, float)[..., :3, 3]
    return np.concatenate([J[..., :3] - J[..., 3:] @ skew(t), J[..., 3:] * scale_m], axis=-1)


def _along(data: ScanData, T: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What every point of one profile shares: the unit direction ``v``, a basis (6,5) of its orthogonal
    complement, and the residuals at ``T``."""
    v = np.asarray(v, float) / np.linalg.norm(v)
    B = np.linalg.svd(np.eye(6) - np.outer(v, v))[0][:, :5]               # the orthogonal complement of v
    return v, B, range_residuals(np.asarray(T, float), data)


def profile_rises(data: ScanData, T: np.ndarray, v: np.ndarray, deltas: np.ndarray, scale_m: float,
                  sigma_m: float, along: tuple | None = None) -> np.ndarray:
    """(M,) the range model's negative log-likelihood at ``T`` moved by each of ``deltas`` (M,) along the unit
    direction ``v`` (scaled axes), minimised over the five directions orthogonal to ``v`` (``PROFILE_GN_STEPS``
    Gauss-Newton steps from there, all points at once, each stopping where its step no longer lowers its cost),
    less its value at ``T``: ``(|e|^2 - |e_0|^2) / (2 sigma^2)``. At an optimum it is >= 0 up to the re-fit's
    error. ``along``: ``_along(data, T, v)`` when the caller has it (one profile's points share it)."""
    v, B, e0 = _along(data, T, v) if along is None else along
    Tk = move(T, np.asarray(deltas, float)[:, None] * v, scale_m)
    e, J = range_residuals(Tk, data, jacobian=True)
    live = np.ones(len(Tk), bool)
    for _ in range(PROFILE_GN_STEPS):
        A = _origin_jacobian(J[live], Tk[live], scale_m) @ B                    # (m,K,5)
        step = np.einsum("mjk,mk->mj", np.linalg.pinv(A), -e[live])           # least squares, as lstsq
        T_next = move(Tk[live], step @ B.T, scale_m)
        e_next, J_next = range_residuals(T_next, data, jacobian=True)
        better = np.einsum("mk,mk->m", e_next, e_next) < np.einsum("mk,mk->m", e[live], e[live])
        idx = np.flatnonzero(live)[better]
        Tk[idx], e[idx], J[idx] = T_next[better], e_next[better], J_next[better]
        live[np.flatnonzero(live)[~better]] = False
        if not live.any():
            break
    return (np.einsum("mk,mk->m", e, e) - e0 @ e0) / (2.0 * sigma_m**2)


def profile_rise(data: ScanData, T: np.ndarray, v: np.ndarray, delta: float, scale_m: float,
                 sigma_m: float) -> float:
    """``profile_rises`` at one ``delta``."""
    return float(profile_rises(data, T, v, np.array([delta]), scale_m, sigma_m)[0])


def _first_rise(data, T, v, deltas, scale_m, sigma_m, along) -> int | None:
    """Index of the first of ``deltas`` whose profile reaches ``PROFILE_ONE_SIGMA``; None when none does."""
    hit = np.flatnonzero(profile_rises(data, T, v, deltas, scale_m, sigma_m, along) >= PROFILE_ONE_SIGMA)
    return int(hit[0]) if len(hit) else None


def profile_sigma(data: ScanData, T: np.ndarray, v: np.ndarray, span: float, scale_m: float,
                  sigma_m: float) -> float:
    """The profile 1-sigma along ``v`` (scaled units): on each side the nearest ``delta`` at which the profile
    (``profile_rises``) reaches ``PROFILE_ONE_SIGMA``, stepping out from ``span`` / 2^``PROFILE_DOUBLINGS`` by
    doublings and then on two grids inside the bracket (``PROFILE_GRID``; the nearest crossing: far out, the five
    re-fitted directions can find other poses); the larger of the two sides, or ``inf`` when a side does not reach
    it within ``span``. Each stage's points are re-fitted at once."""
    out = 0.0
    along = _along(data, T, v)
    for sign in (1.0, -1.0):
        steps = span * 0.5 ** np.arange(PROFILE_DOUBLINGS, -1, -1)
        first = _first_rise(data, T, v, sign * steps, scale_m, sigma_m, along)
        if first is None:
            return float("inf")
        lo, hi = (0.0 if first == 0 else steps[first - 1]), steps[first]
        for _ in range(PROFILE_GRID_ROUNDS):
            grid = lo + (hi - lo) * np.arange(1, PROFILE_GRID + 1) / PROFILE_GRID      # hi itself rises
            k = _first_rise(data, T, v, sign * grid, scale_m, sigma_m, along)
            k = PROFILE_GRID - 1 if k is None else k                                      # hi, as before
            lo, hi = (lo if k == 0 else grid[k - 1]), grid[k]
        out = max(out, hi)
    return float(out)


PROFILE_SCAN_POINTS = 48
"""``profile_extent`` evaluates the profile at this many points on each side, evenly across the span."""
PROFILE_EXTENT_SIGMAS = (1, 2, 3)
"""``profile_extent`` reads the profile's k-sigma region for each of these k (the rise below k^2/2)."""


def profile_extent(data: ScanData, T: np.ndarray, v: np.ndarray, span: float, scale_m: float,
                   sigma_m: float) -> float:
    """The profile-likelihood 1-sigma along ``v`` (scaled units) over the whole ``span``: for each k of
    ``PROFILE_EXTENT_SIGMAS`` the farthest ``delta`` on either side at which the profile (``profile_rises``) is
    still below ``k^2 / 2``, divided by k, the largest of these and of the nearest crossing (``profile_sigma``):
    for a quadratic profile all are its sigma, and where the likelihood has a second mode along ``v`` (a second
    solution of the boards nearly as likely) the 1-sigma reaches a third of the way to it at least. ``inf`` only
    where ``profile_sigma`` is (the profile does not reach its 1-sigma within ``span`` on a side: flat); a profile
    that rises and falls back to the span's end gives a 1-sigma of the span (a mode there is a distinct answer,
    for the choice's tie rule, not a free direction). ``PROFILE_SCAN_POINTS`` points a side, re-fitted at once."""
    near = profile_sigma(data, T, v, span, scale_m, sigma_m)
    if not np.isfinite(near):
        return near
    along = _along(data, T, v)
    steps = span * np.arange(1, PROFILE_SCAN_POINTS + 1) / PROFILE_SCAN_POINTS
    deltas = np.r_[steps, -steps]
    rise = profile_rises(data, T, v, deltas, scale_m, sigma_m, along)
    out = near
    for k in PROFILE_EXTENT_SIGMAS:
        inside = rise < PROFILE_ONE_SIGMA * k**2
        out = max(out, float(np.max(np.abs(deltas[inside]), initial=0.0)) / k)
    return float(out)


MIN_FREE_SPAN_M = 0.3
"""A translation is called free only where its profile stays flat over at least this (metres), however close
the boards: the refusal rule's floor (a rig whose typical range is below it is profiled that far)."""

FREE_SPAN = 1.0
"""The physically possible range of a small motion, in scaled units (a radian; one typical range, and at least
``MIN_FREE_SPAN_M``): a direction whose profile likelihood does not rise by its 1-sigma across it, on either
side, is free (refused by ``checks.degeneracy``); every other direction is answered with its sigma, however
large. Refused directions therefore have a profile 1-sigma above 57 deg or above max(typical range,
``MIN_FREE_SPAN_M``)."""


def free_span(scale_m: float) -> float:
    """``FREE_SPAN`` in scaled units for a typical range ``scale_m`` (metres): at least ``MIN_FREE_SPAN_M`` of
    translation."""
    return FREE_SPAN * max(1.0, MIN_FREE_SPAN_M / float(scale_m))


def marginal_sigmas(F: np.ndarray, E: np.ndarray, sigma: float, null_conditioning: float) -> np.ndarray:
    """1-sigma (scaled) of the unit directions ``E`` (k,6) under information ``F / sigma^2``; inf when the
    smallest eigenvalue of ``F`` is below ``null_conditioning^2`` of the largest."""
    lam, V = np.linalg.eigh(F)
    if lam[0] <= (null_conditioning**2) * lam[-1]:
        return np.full(len(E), np.inf)
    return sigma * np.sqrt(np.einsum("ij,jk,ik->i", E, (V / lam) @ V.T, E))


def vertical_sigmas(data: ScanData, T: np.ndarray, F: np.ndarray, E: np.ndarray, sigma: float, scale_m: float,
                    span: float, null_conditioning: float,
                    linear_span: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The 1-sigma (scaled) of the vertical axes ``E`` (3,6) of ``checks.degeneracy``, which of them the profile
    raised, and their profile 1-sigma (``profile_extent``; ``inf``: flat across ``span``): the marginal linear
    sigmas (information ``F``) when a profile stays flat (the set is refused), else the larger of the linear one
    (where within ``linear_span``) and the profile."""
    lin = marginal_sigmas(F, E, sigma, null_conditioning)
    prof = np.array([profile_extent(data, T, e, span, scale_m, sigma) for e in E])
    if not np.all(np.isfinite(prof)):
        return lin, np.zeros(len(E), bool), prof
    use_lin = np.isfinite(lin) & (lin <= linear_span) & (lin >= prof)
    return np.where(use_lin, lin, prof), ~use_lin, prof


def fold_sigmas(data: ScanData, T: np.ndarray, V: np.ndarray, linear_beyond: np.ndarray, sig: np.ndarray,
                scale_m: float, sigma: float, span: float = FREE_SPAN) -> tuple[np.ndarray, np.ndarray]:
    """The sigmas (scaled) ``sig`` with each direction the linear analysis leaves beyond its span (columns of
    ``V`` where ``linear_beyond``) replaced by its profile 1-sigma (``profile_extent``) where that is finite
    within ``span`` (a fold of the board set's solutions), and the mask of those folds."""
    sig, fold = np.array(sig, float), np.zeros(len(sig), bool)
    for j in np.flatnonzero(linear_beyond):
        s = profile_extent(data, T, V[:, j], span, scale_m, sigma)
        if np.isfinite(s):
            sig[j], fold[j] = s, True
    return sig, fold
