"""What a board set cannot determine: the directions of the extrinsic that the range model's information leaves
free, named in lidar-frame axes, and the one home of the plain-language warnings about a board set (used by the
methods and by the rig report, with one set of thresholds).

Axes: a small rigid motion of the camera about the lidar's origin, in lidar axes: ``T_lidar_cam ->
[exp(w) | dt] T_lidar_cam``, ``w = (roll, pitch, yaw)`` rotations about the lidar's x, y, z axes (radians) and
``dt = (x, y, z)`` translations along them (metres). Equivalently the lidar turns about its own axes and shifts
along them relative to the camera. In these axes a vertical-board rig is degenerate along exactly roll, pitch
and z. (``calib_core.model.residuals`` turns the rotation about the camera's centre instead; ``origin_jacobian``
converts.) Translations are scaled by the typical range ``L`` so that radians and metres compare: a unit scaled
direction moves scan points by about the same distance whatever it mixes.

A direction is *weak* when its 1-sigma in scaled units exceeds ``MAX_SCALED_SIGMA`` (0.1: 5.7 deg of rotation,
or 10 % of the typical range of translation): the answer stands and a warning names it with its sigma. It is
*not determined* (``geometric``: the methods refuse to present it, ``ok=False``) only where the data leave it
free: where its profile likelihood (``checks.profile``) does not rise by its 1-sigma anywhere across the span
a small motion of the extrinsic can physically cover (``profile.FREE_SPAN``: a radian of rotation, or one
typical range and at least ``profile.MIN_FREE_SPAN_M`` of translation). The linear analysis only picks the
candidates: a direction with no information at first order (singular value below ``NULL_CONDITIONING`` of the
largest) or a linear 1-sigma beyond ``FOLD_SPAN``, and, where the boards stand (nearly) vertical (normals within
``MIN_NORMAL_SPREAD_DEG`` of the scan plane, the rig of a ground robot), roll, pitch and z, which only the
boards' lean fixes.

Two cases reach the profile. With three boards the answer can sit where two of the minimal solver's solutions
meet (a fold): the residuals change only at second order along one direction (the linear sigma runs to
radians) while the likelihood still rises; the direction is weak (or determined) with its profile sigma, named
as such in the message. With vertical boards, roll, pitch and z are answered with the larger of their linear
(marginal) and profile 1-sigma when the profile of each rises within ``profile.FREE_SPAN`` (boards that lean a
little: the lean fixes them, weakly), and refused together when one of them stays flat (boards exactly vertical
leave z free at every order, and roll and pitch with fourth-order information only): the planar calibration
(``fixed=``) needs all three. The warning then says that the lean is all that fixes them, so that board-pose
errors of the lean's order are not in the range model's sigma (the joint model's board-pose covariance holds
the corners' share of them).

A refusal names as not determined only the axes whose own profile likelihood (that axis moved, the other five
re-fitted) stays flat across the span (``Degeneracy.free_axes``): every named axis is free. The other weak axes
are said with their profile 1-sigma (they are refused with the set, since the answer needs every direction, but
not called free), and the hint lists what a calibration with given axes needs (``axes``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..data.lines import residual_sigma
from ..data.observations import Observations
from ..data.outcome import InfoParts
from ..errors import SolveFailure
from ..geometry.transforms import skew
from ..model.residuals import range_linearised
from ..refine.partial import vertical_start
from ..refine.uncertainty import conditioning, normal_spread_deg, typical_range
from ..solvers._common import MIN_BOARDS
from .axis_words import AXES, AXIS_WORDS, FOLD_WORDS, LEAN_WORDS, describe, fixed_key, flat_words, join_words
from .profile import fold_sigmas, free_span, marginal_sigmas, profile_extent, vertical_sigmas

WARN_BELOW_BOARDS = 4
"""Fewer boards than this is warned about: with 3 the minimal solver's candidates all fit the scan lines exactly
and cannot be told apart by the scan residuals."""

MIN_PAIR_ANGLE_DEG = 15.0
"""Largest angle between two board normals below this: the boards are near-parallel."""

MIN_NORMAL_SPREAD_DEG = 5.0
"""``uncertainty.normal_spread_deg`` below this: the board normals lie nearly in one plane."""

MIN_CONDITIONING = 1e-3
"""``uncertainty.conditioning`` below this: some direction of the extrinsic is barely constrained (warning)."""

NULL_CONDITIONING = 1e-6
"""A direction whose singular value is below this fraction of the largest (scaled Jacobian) carries no
information whatever the noise: undetermined."""

MAX_SCALED_SIGMA = 0.1
"""A direction whose 1-sigma exceeds this in scaled units (radians; translation in units of the typical range)
is undetermined: the data do not fix it."""

FOLD_SPAN = 1.0
"""A direction whose linear 1-sigma exceeds this many scaled units (a radian, or one typical range: as far as a
small motion of the extrinsic means anything), or that has no first-order information at all
(``NULL_CONDITIONING``), is judged by its profile likelihood (``checks.profile``): when that still rises by its
1-sigma within ``profile.FREE_SPAN``, the direction is a fold of the board set's solutions, not one the geometry leaves
free; it is weak (or determined) with its profile 1-sigma, judged by ``MAX_SCALED_SIGMA`` like any other."""



@dataclass(frozen=True)
class DegeneracyOptions:
    """Thresholds of ``undetermined_directions`` for a method's refusal: a direction with no information below
    ``null_conditioning`` (``NULL_CONDITIONING``), or with a scaled 1-sigma above ``max_scaled_sigma``. (The
    warning on a poorly conditioned set, ``MIN_CONDITIONING``, is not an option.)"""

    null_conditioning: float = NULL_CONDITIONING
    max_scaled_sigma: float = MAX_SCALED_SIGMA


ALIGNED_SHARE = 0.9
"""Undetermined directions are named as lidar axes when each named axis lies this much (squared norm of its
projection) inside the undetermined subspace."""

VERTICAL_TOL_DEG = 10.0
"""The normals' common perpendicular within this of the lidar z axis: the boards are called vertical."""

VERTICAL_MISFIT_DEG = 2.5
"""Or: one rotation turns every board normal onto its scan line's normal in the scan plane within this (RMS)."""

def origin_jacobian(J: np.ndarray, T_lidar_cam: np.ndarray) -> np.ndarray:
    """A (K,6) residual Jacobian in the parameters of ``calib_core.model.residuals`` (rotation about the camera centre)
    turned into the lidar-origin axes of this module: ``d_t(residuals) = w x t + dt``."""
    J = np.asarray(J, float)
    t = np.asarray(T_lidar_cam, float)[:3, 3]
    return np.concatenate([J[:, :3] - J[:, 3:] @ skew(t), J[:, 3:]], axis=1)


@dataclass(frozen=True, eq=False)
class Degeneracy:
    """The weak directions of a board set at an extrinsic.

    Attributes:
        directions: (k,6) unit vectors spanning the weak subspace, in the scaled lidar-origin axes (roll, pitch,
            yaw in radians; x, y, z in units of ``scale_m``); k = 0 when everything is well determined.
        sigmas: (k,) their 1-sigma in scaled units (inf where the information is numerically zero).
        axes: the fewest lidar axes (names from ``AXES``) whose span holds every weak direction to at least
            ``ALIGNED_SHARE`` (squared norm): fixing them removes the weak subspace. ``aligned``: there are as many
            of them as weak directions (then exactly these axes are weak; otherwise combinations of them are).
        geometric: the board geometry leaves them free (no information, or vertical boards): they are *not
            determined* and a method must not present them as estimated.
        cause: why, in words (e.g. "every board stands vertical (normals 0.0 deg RMS from the scan plane)").
        scale_m: the typical range used to scale translations; range_sigma_m: the noise std used.
        profile: (k,) bool, the directions whose sigma is the profile likelihood's (a fold: no first-order
            information, or a linear sigma beyond ``FOLD_SPAN``); empty when none.
        floors: (k,) bool, the directions whose sigma the profile likelihood raised above the linear one (the
            vertical axes of boards that lean a little): the covariance is widened to it along them
            (``methods.last_steps.profile_floor``); empty when none.
        free_axes: where the set is refused (``geometric``) at the range optimum, the axes of ``axes`` that the
            refusal names as not determined: those whose own profile likelihood (the other five re-fitted) stays
            flat across ``profile.free_span``; ``axis_sigmas`` (len(axes),) each axis's profile 1-sigma (scaled;
            inf: flat), the others' said in ``cause``; ``free_directions`` (m,6) the directions left free. Empty
            otherwise (a set that is answered, or judged without a profile: ``axes`` are then named). ``axes``
            stays what a calibration with given axes needs (``fixed=``).
    """

    directions: np.ndarray
    sigmas: np.ndarray
    axes: tuple[str, ...]
    aligned: bool
    geometric: bool
    cause: str
    scale_m: float
    range_sigma_m: float
    profile: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    floors: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    free_axes: tuple[str, ...] = ()
    free_directions: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    axis_sigmas: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def determined(self) -> bool:
        """No direction is left free by the geometry (weak ones for lack of data may remain)."""
        return not (len(self.directions) and self.geometric)

    def _what(self, free: bool = False) -> tuple[str, int]:
        """What is named (the free axes with ``free`` where known, else ``axes``) and how many things it counts."""
        axes, dirs, aligned = self.axes, self.directions, self.aligned
        if free and self.free_axes:
            axes, dirs = self.free_axes, self.free_directions
            aligned = len(dirs) == len(axes)
        words = join_words([AXIS_WORDS[a] for a in axes])
        if aligned:
            return words, len(axes)
        k = len(dirs)
        return (f"{'a combination' if k == 1 else f'{k} combinations'} of {words} "
                f"({'; '.join(describe(v) for v in dirs)}; translations in units of {self.scale_m:.2f} m)"), k

    def _sigma_words(self) -> str:
        out = []
        profile = self.profile if len(self.profile) == len(self.sigmas) else np.zeros(len(self.sigmas), bool)
        for v, s, p in zip(self.directions, self.sigmas, profile, strict=True):
            rot = float(v[:3] @ v[:3]) >= 0.5
            out.append(("inf" if not np.isfinite(s) else f"{np.degrees(s):.1f} deg" if rot
                        else f"{1000 * s * self.scale_m:.0f} mm") + (FOLD_WORDS if p else ""))
        return ", ".join(out)

    def message(self, from_prior: bool = False) -> str:
        """One sentence: what is not (or poorly) determined and why; for the former, how to calibrate the rest, or
        with ``from_prior`` that the answer takes them from the mounting prior."""
        if not len(self.directions):
            return "every direction of the extrinsic is determined"
        what, n = self._what(free=self.geometric and not from_prior)
        verb = "is" if n == 1 else "are"
        if from_prior:
            return (f"{what} {verb} not determined by these boards ({self.cause}): the answer takes "
                    f"{'it' if len(self.directions) == 1 else 'them'} from the mounting prior, with the prior's "
                    "uncertainty")
        if not self.geometric:
            return (f"{what} {verb} poorly determined (1-sigma {self._sigma_words()}): {self.cause}; "
                    "add board poses")
        keys = ", ".join(f"{fixed_key(a)!r}: ..." for a in self.axes)
        give = "their values" if set(self.free_axes or self.axes) == set(self.axes) else \
            f"the values of {join_words(list(self.axes))}"
        return (f"{what} {verb} not determined by these boards: {self.cause}; give {give} "
                f"and calibrate the rest with fixed={{{keys}}}")

    def to_dict(self) -> dict:
        """JSON-able summary: axes, aligned, geometric, cause, message, directions, sigmas (None for infinite),
        which are profile sigmas (folds) and which the profile raised (``floors``)."""
        return {"axes": list(self.axes), "aligned": bool(self.aligned), "geometric": bool(self.geometric),
                "cause": self.cause, "message": self.message(), "directions": np.round(self.directions, 6).tolist(),
                "sigmas_scaled": [None if not np.isfinite(s) else float(s) for s in self.sigmas],
                "profile": [bool(p) for p in self.profile], "floors": [bool(p) for p in self.floors],
                "scale_m": self.scale_m, "range_sigma_m": self.range_sigma_m, "free_axes": list(self.free_axes),
                "axis_sigmas_scaled": [None if not np.isfinite(s) else float(s) for s in self.axis_sigmas]}


def board_set_cause(obs: Observations, T_lidar_cam: np.ndarray) -> str:
    """Why a board set is weak, in words: vertical boards, normals near one plane, or few boards."""
    m = obs.planes_cam()[0] @ np.asarray(T_lidar_cam, float)[:3, :3].T      # normals in the lidar frame
    a = np.linalg.eigh(m.T @ m)[1][:, 0]                                     # their common perpendicular
    tilt = float(np.degrees(np.arcsin(np.clip(np.max(np.abs(m @ a)), 0.0, 1.0))))
    if tilt < VERTICAL_TOL_DEG:
        return (f"every board normal lies within {tilt:.1f} deg of the plane perpendicular to "
                f"({a[0]:+.2f}, {a[1]:+.2f}, {a[2]:+.2f}) in the lidar frame")
    if obs.n_boards < MIN_BOARDS:
        return f"only {obs.n_boards} boards"
    return f"too little data for the range noise ({obs.n_boards} boards)"


VERTICAL_AXES = ("roll", "pitch", "z")
"""What a rig of vertical boards leaves free, exactly, in the lidar-origin axes."""


def vertical_boards(obs: Observations, T_lidar_cam: np.ndarray) -> float | None:
    """How far (RMS, degrees) the boards lean from vertical when they stand (nearly) vertical, else None.

    Vertical: normals within ``MIN_NORMAL_SPREAD_DEG`` (spread) of one plane, and that plane is the lidar's
    horizontal: its perpendicular within ``VERTICAL_TOL_DEG`` of the lidar z axis at ``T_lidar_cam``, or, since an
    extrinsic estimated from such boards may itself be tilted, one rotation turns every normal onto its scan
    line's normal in the scan plane within ``VERTICAL_MISFIT_DEG`` (``partial.vertical_start``, no extrinsic;
    from ``WARN_BELOW_BOARDS`` boards on: three normals turn onto three scan lines too easily to tell).
    """
    if obs.n_boards < 2 or normal_spread_deg(obs) >= MIN_NORMAL_SPREAD_DEG:
        return None
    try:
        misfit = vertical_start(obs)[1]
    except (SolveFailure, ValueError, np.linalg.LinAlgError):
        misfit = np.inf
    m = obs.planes_cam()[0] @ np.asarray(T_lidar_cam, float)[:3, :3].T
    a = np.linalg.eigh(m.T @ m)[1][:, 0]
    if np.degrees(np.arccos(min(abs(a[2]), 1.0))) < VERTICAL_TOL_DEG:
        return float(min(misfit, np.degrees(np.arcsin(np.sqrt(np.mean(m[:, 2] ** 2))))))
    return float(misfit) if misfit < VERTICAL_MISFIT_DEG and obs.n_boards >= WARN_BELOW_BOARDS else None


def undetermined_directions(obs: Observations, T_lidar_cam: np.ndarray, range_sigma_m: float | None = None, *,
                            max_scaled_sigma: float = MAX_SCALED_SIGMA,
                            null_conditioning: float = NULL_CONDITIONING,
                            profile_vertical: bool = True) -> Degeneracy:
    """The weak and the not determined directions of the extrinsic at ``T_lidar_cam`` (module docstring).

    Eigen-decomposition of the range model's Fisher information in the scaled lidar-origin axes; the candidates
    of the linear analysis judged by their profile likelihood over ``free_span``. ``range_sigma_m``: the range
    noise std (metres); ``None`` estimates it from the range residuals at ``T_lidar_cam`` (``K - 6`` degrees of
    freedom), as the methods' covariance does.

    Vertical boards (``vertical_boards``) fix roll, pitch and z through their lean alone: the three are named
    (weak, with the larger of their marginal linear and profile sigma, ``floors`` where the profile's is the
    larger), and not determined when the profile of one of them stays flat across ``free_span``.
    ``profile_vertical=False``: they are not determined without a profile (a caller whose ``T_lidar_cam`` is not
    the range likelihood's optimum, e.g. a mounting prior's posterior mode, where the range profile does not
    apply: the prior then holds them).
    """
    T = np.asarray(T_lidar_cam, float)
    e, J = range_linearised(T, obs.scan_data)
    L = typical_range(obs)
    Js = origin_jacobian(J, T) * np.r_[np.ones(3), np.full(3, L)]
    sigma = residual_sigma(e, 6) if range_sigma_m is None else float(range_sigma_m)
    span = free_span(L)
    F = Js.T @ Js
    lam, V = np.linalg.eigh(F)
    null = lam <= (null_conditioning**2) * lam[-1]
    sig = np.where(null, np.inf, sigma / np.sqrt(np.where(null, 1.0, lam)))
    lean = vertical_boards(obs, T)
    vertical = lean is not None
    fold = np.zeros(6, bool)
    E = np.eye(6)[[AXES.index(a) for a in VERTICAL_AXES]]
    candidates = (null | (sig > FOLD_SPAN)) & ~(vertical & (np.sum((E @ V) ** 2, axis=0) >= 0.5))
    if candidates.any():                 # the vertical axes themselves: _vertical_sigmas
        sig, fold = fold_sigmas(obs.scan_data, T, V, candidates, sig, L, sigma, span)
        null = null & ~fold
    weak = null | (sig > max_scaled_sigma)
    U, sig_u, fold_u, null_u = V[:, weak].T, sig[weak], fold[weak], null[weak]
    floor_u = np.zeros(len(U), bool)
    free_vertical = False
    if vertical:
        other = np.sum((U @ E.T) ** 2, axis=1) < 0.5
        if profile_vertical:
            sig_e, floor_e, prof_e = vertical_sigmas(obs.scan_data, T, F, E, sigma, L, span, null_conditioning,
                                                     FOLD_SPAN)
        else:
            sig_e, floor_e = marginal_sigmas(F, E, sigma, null_conditioning), np.zeros(len(E), bool)
            prof_e = np.full(len(E), np.inf)
        free_vertical = not np.all(np.isfinite(prof_e))
        U, sig_u = np.concatenate([E, U[other]]), np.r_[sig_e, sig_u[other]]
        fold_u, null_u = np.r_[np.zeros(len(E), bool), fold_u[other]], np.r_[np.zeros(len(E), bool), null_u[other]]
        floor_u = np.r_[floor_e, np.zeros(int(other.sum()), bool)]
    k = len(U)
    order = np.argsort(-np.sum(U**2, axis=0), kind="stable")
    n_axes = next((n for n in range(k, 6) if np.all(np.sum(U[:, order[:n]] ** 2, axis=1) >= ALIGNED_SHARE)), 6)
    axes = tuple(AXES[j] for j in sorted(order[:n_axes]))
    geometric = bool(k and (free_vertical or null_u.any()))
    cause = "" if not k else board_set_cause(obs, T) if lean is None else \
        f"every board stands vertical (normals {lean:.1f} deg RMS from the scan plane)"
    free = {"free_axes": (), "free_directions": np.zeros((0, 6)), "axis_sigmas": np.zeros(0)}
    if geometric and profile_vertical:
        known = dict(zip(VERTICAL_AXES, prof_e, strict=True)) if vertical else {}
        prof = axis_profiles(obs.scan_data, T, axes, known, span, L, sigma)
        cause += flat_words(axes, prof, L, vertical)
        free = {"free_axes": tuple(a for a, p in zip(axes, prof, strict=True) if not np.isfinite(p)),
                "free_directions": np.concatenate([U[null_u]] + ([E[~np.isfinite(prof_e)]] if vertical else [])),
                "axis_sigmas": prof}
    elif vertical and profile_vertical:
        cause += LEAN_WORDS
    return Degeneracy(U, sig_u, axes, bool(k and n_axes == k), geometric, cause, L, sigma, fold_u, floor_u, **free)


def axis_profiles(data, T: np.ndarray, axes: tuple[str, ...], known: dict, span: float, scale_m: float,
                  sigma_m: float) -> np.ndarray:
    """(len(axes),) each lidar axis's own profile-likelihood 1-sigma (``profile.profile_extent`` along the axis,
    the other five re-fitted; scaled units; ``inf``: flat across ``span``), ``known[axis]`` where given."""
    return np.array([known[a] if a in known else
                     profile_extent(data, T, np.eye(6)[AXES.index(a)], span, scale_m, sigma_m) for a in axes])


def pair_angle_deg(obs: Observations) -> float:
    """Largest angle between two board normals, in degrees (0 with fewer than 2 boards)."""
    n, _ = obs.planes_cam()
    if len(n) < 2:
        return 0.0
    return float(np.degrees(np.arccos(np.clip(np.abs(n @ n.T), 0.0, 1.0).min())))


def board_set_warnings(obs: Observations) -> list[str]:
    """Warnings about the board set alone (no extrinsic), with this module's thresholds: fewer than
    ``WARN_BELOW_BOARDS`` boards; near-parallel boards (``MIN_PAIR_ANGLE_DEG``) or else normals nearly in one plane
    (``MIN_NORMAL_SPREAD_DEG``)."""
    out = []
    N = obs.n_boards
    if N < WARN_BELOW_BOARDS:
        out.append(f"only {N} boards (fewer than {WARN_BELOW_BOARDS}): the solution may be ambiguous; add board poses "
                   "with varied orientations")
    if N >= 2 and (ang := pair_angle_deg(obs)) < MIN_PAIR_ANGLE_DEG:
        out.append(f"board normals are near-parallel (largest angle between two boards {ang:.1f} deg < "
                   f"{MIN_PAIR_ANGLE_DEG:g} deg): tilt and turn the board more between poses")
    elif N >= 3 and (spread := normal_spread_deg(obs)) < MIN_NORMAL_SPREAD_DEG:
        out.append(f"board normals nearly in one plane (spread {spread:.1f} deg < {MIN_NORMAL_SPREAD_DEG:g} deg): "
                   "tilt the board forwards/backwards as well as sideways")
    return out


def degeneracy_warnings(obs: Observations, T_lidar_cam: np.ndarray | None = None) -> list[str]:
    """``board_set_warnings`` and, given ``T_lidar_cam`` (or the ground truth), poor conditioning of the full
    extrinsic (``MIN_CONDITIONING``) naming the weakest direction in lidar axes."""
    out = board_set_warnings(obs)
    T = T_lidar_cam if T_lidar_cam is not None else obs.T_lidar_cam_true
    if T is not None and obs.n_boards:
        c = conditioning(obs, T)
        if c < MIN_CONDITIONING:
            _, J = range_linearised(T, obs.scan_data)
            Js = origin_jacobian(J, T) * np.r_[np.ones(3), np.full(3, typical_range(obs))]
            v = np.linalg.eigh(Js.T @ Js)[1][:, 0]
            out.append(f"poorly conditioned board set (inverse condition number {c:.1e} < {MIN_CONDITIONING:g}): "
                       f"the weakest direction is {describe(v * np.sign(v[np.argmax(np.abs(v))]))} "
                       "(lidar axes, translation in units of the typical range)")
    return out


def explain_failure(obs: Observations, fail: SolveFailure, range_sigma_m: float | None = None) -> SolveFailure:
    """``fail`` with the directions the board set does not determine added to its reason and info, when the
    boards' normals lie nearly in one plane and the rig reads as vertical boards (``partial.vertical_start``
    aligns the normals with the scan lines within ``VERTICAL_TOL_DEG``); ``fail`` itself otherwise."""
    if obs.n_boards < 2 or normal_spread_deg(obs) >= MIN_NORMAL_SPREAD_DEG:
        return fail
    try:
        T0, misalign_deg = vertical_start(obs)
    except (SolveFailure, ValueError, np.linalg.LinAlgError):
        return fail
    if misalign_deg > VERTICAL_TOL_DEG:
        return fail
    deg = undetermined_directions(obs, T0, range_sigma_m)
    if deg.determined:
        return fail
    return SolveFailure(f"{deg.message()} (the solvers: {fail.reason})", np.concatenate([T0[None], fail.candidates]),
                        InfoParts(base=fail.info, degeneracy=deg.to_dict(), warnings=board_set_warnings(obs)).to_info())
