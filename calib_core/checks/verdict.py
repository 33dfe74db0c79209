"""The consistency verdict: is an answer ``T_lidar_cam`` contradicted by the data under the noise model?

Every answer of ``calibrate`` is tested against its observations, whatever the method:

- range residuals of every board's scan points against its plane (lidar frame, metres), in units of the noise
  std: a clipped chi-square per board (each point contributes ``min(z^2, c^2)``, so a few stray points cannot
  condemn a board) against its expectation under Gaussian noise, with room for a quarter of the points to be
  outliers; the noise std is estimated robustly from the scan lines alone (median absolute deviation, no
  extrinsic, ``calib_core.data.lines``), plus a floor ``POSE_FLOOR_M`` for the camera-side board poses; where the
  boards carry image corners, the camera side's error of each board's plane is modelled as well: the residuals
  are taken after the board's pose moves within its covariance from its corners and the stated intrinsics'
  1-sigma, and the move's cost is added to the board's chi-square (``calib_core.refine.camera_side.pose_explained``:
  the board's residuals against ``sigma^2 I + J C J^T``; a plane error shared by all of a board's points is not
  independent noise, and counted as such a far board's 3-sigma plane offset condemns the truth); a move beyond
  that covariance (``d^T C^-1 d`` over the chi-square(6) quantile of the range test's tail probability)
  contradicts the answer on its own;
- the board outline (exact outlines only, ``outline_kind``): scan points mapped into their board's frame must lie on
  the board (at most a quarter of a
  board's inlier points outside it by more than the tolerance);
- boards in front of both sensors: every board's centre in front of the camera (its pose alone), and under the
  answer every board's scan in front of the camera; scan points away from the lidar origin;
- copies (warnings, not contradictions): a board listed twice, a scan that is one point repeated.

A board that fails any test contradicts the answer. ``calib_core.checks.diagnose.judge`` then looks for a likely cause
(units, mispaired or mirrored scans, scaled board poses). Frames and units as in ``calib_core.data.observations``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.stats import chi2 as chi2_dist
from scipy.stats import norm

from ..data.lines import MIN_SPREAD_M, range_sigma
from ..data.observations import MIN_RANGE_M, Observations, ScanData
from ..model.residuals import outside_outline, points_in_boards, range_residuals
from ..refine.camera_side import pose_explained

CLIP_Z = 3.0
"""Residuals beyond this many noise stds count as ``CLIP_Z^2`` in the clipped chi-square."""
OUTLIER_ALLOWANCE = 0.25
"""Fraction of a board's points that may be outliers before its clipped chi-square contradicts the answer."""
CHI2_SIGMAS = 5.0
"""Standard deviations of the clipped chi-square above its mean at which a board contradicts the answer."""
MOVE_CHI2_LIMIT = float(chi2_dist.isf(2 * norm.sf(CHI2_SIGMAS), 6))
"""A board whose pose must move by more than this (``d^T C^-1 d``, its camera-side covariance) to fit the answer
contradicts it: the chi-square(6) quantile at the two-sided tail probability of ``CHI2_SIGMAS`` (about 40)."""
POSE_FLOOR_M = 0.01
"""Spread (metres) added in quadrature to the range noise for errors of the camera-side board planes."""
OUTLINE_TOL_SIGMAS = 4.0
"""A point is off its board when outside the outline by more than this many noise stds plus ``POSE_FLOOR_M``."""
MIN_DEPTH_M = 0.05
"""A board whose centre is not this far in front of the camera is not in view."""


def _clipped_chi2_moments(c: float) -> tuple[float, float]:
    """Mean and variance of ``min(z^2, c^2)`` for standard normal ``z``."""
    p_in, phi, tail = 2 * norm.cdf(c) - 1, norm.pdf(c), 2 * norm.sf(c)
    m1 = p_in - 2 * c * phi + c**2 * tail
    m2 = 3 * p_in - 2 * (c**3 + 3 * c) * phi + c**4 * tail
    return m1, m2 - m1**2


CHI2_MEAN, CHI2_VAR = _clipped_chi2_moments(CLIP_Z)


@dataclass(frozen=True)
class Verdict:
    """The outcome of the consistency tests of one answer.

    Attributes:
        consistent: no board contradicts the answer.
        reason: which boards and tests contradict it, by how much (None when consistent).
        warnings: plain-language warnings (data oddities, likely causes of a contradiction).
        causes: short names of the likely causes found (``units``, ``mispaired``, ``mirrored``, ``scale``,
            ``duplicated``, ``repeated``).
        sigma_m: the noise std used (metres; line estimate and pose floor in quadrature).
        boards: per board, the test statistics (dicts of plain numbers).
    """

    consistent: bool
    reason: str | None = None
    warnings: tuple[str, ...] = ()
    causes: tuple[str, ...] = ()
    sigma_m: float = float("nan")
    boards: tuple[dict, ...] = field(default_factory=tuple)

    def to_dict(self) -> dict:
        return {"consistent": bool(self.consistent), "reason": self.reason, "warnings": list(self.warnings),
                "causes": list(self.causes), "sigma_m": float(self.sigma_m), "boards": list(self.boards)}


def effective_sigma(obs: Observations, range_sigma_m: float | None = None) -> float:
    """The spread (metres) the residuals are tested against: the range noise (given, or estimated from the scan
    lines) and ``POSE_FLOOR_M`` in quadrature."""
    s = range_sigma(obs, range_sigma_m, robust=True)
    return float(np.hypot(0.0 if not np.isfinite(s) else s, POSE_FLOOR_M))


def measured_mask(obs: Observations) -> np.ndarray:
    """(K,) bool over ``obs.scan_data``: the points away from the lidar origin (``MIN_RANGE_M``)."""
    return np.linalg.norm(obs.scan_data.points, axis=1) > MIN_RANGE_M


def measured_points(obs: Observations) -> ScanData:
    """The scan data without points at the lidar origin (``measured_mask``)."""
    data, keep = obs.scan_data, measured_mask(obs)
    return data if keep.all() else ScanData(data.points[keep], data.board[keep], data.normals, data.offsets)


def board_depths(obs: Observations) -> np.ndarray:
    """(N,) depth (metres) of each board's centre (``BoardObservation.centre``) in the camera frame (camera z)."""
    out = []
    for b in obs.boards:
        c = b.centre
        out.append(float(b.T_cam_board[2, :2] @ c + b.T_cam_board[2, 3]))
    return np.array(out)


def board_tests(obs: Observations, T: np.ndarray, sigma: float) -> list[dict]:
    """Per board, the statistics of the tests of ``T`` (see the module docstring); ``bad`` lists failed tests."""
    T = np.asarray(T, float)
    data = measured_points(obs)
    r, moved = pose_explained(obs, T, range_residuals(T, data), measured_mask(obs), sigma)
    z = r / sigma
    q = np.minimum(z**2, CLIP_Z**2)
    N = obs.n_boards
    K = np.bincount(data.board, minlength=N)
    chi2 = np.bincount(data.board, weights=q, minlength=N) + moved
    limit = K * CHI2_MEAN + CHI2_SIGMAS * np.sqrt(K * CHI2_VAR) + OUTLIER_ALLOWANCE * K * (CLIP_Z**2 - CHI2_MEAN)
    depth = board_depths(obs)
    R, t = T[:3, :3], T[:3, 3]
    tol = OUTLINE_TOL_SIGMAS * sigma + POSE_FLOOR_M
    inb = points_in_boards(obs, T[None])
    out = []
    for i, b in enumerate(obs.boards):
        sel = data.board == i
        zi = z[sel]
        st = {"board": i, "n_points": int(K[i]), "chi2": float(chi2[i]), "chi2_limit": float(limit[i]),
              "median_abs_z": float(np.median(np.abs(zi))) if len(zi) else float("nan"),
              "depth_m": float(depth[i]), "pose_move_chi2": float(moved[i]), "bad": []}
        if K[i] and chi2[i] > limit[i]:
            st["bad"].append(f"range residuals {st['median_abs_z']:.1f} sigma (median; sigma {1000 * sigma:.0f} mm, "
                             f"clipped chi-square {chi2[i]:.0f} > {limit[i]:.0f} over {K[i]} points)")
        if moved[i] > MOVE_CHI2_LIMIT:
            st["bad"].append(f"its plane fits the answer only moved beyond what its corners and intrinsics allow "
                             f"(pose move chi-square {moved[i]:.0f} > {MOVE_CHI2_LIMIT:.0f})")
        pts = inb[i][0]
        keep = (np.linalg.norm(b.scan, axis=1) > MIN_RANGE_M)
        inl = np.abs(zi) < CLIP_Z
        if inl.sum() and b.outline_exact:  # a lower-bound outline or none lets the scan run past it
            off = outside_outline(pts[keep][inl, :2], b.outline)
            frac = float(np.mean(off > tol))
            st["off_outline_fraction"] = frac
            if frac > OUTLIER_ALLOWANCE and (off > tol).sum() >= 2:
                st["bad"].append(f"{100 * frac:.0f}% of its on-plane scan points lie off the board outline "
                                 f"(up to {off.max():.2f} m, tolerance {tol:.3f} m)")
        if depth[i] < MIN_DEPTH_M:
            st["bad"].append(f"its pose puts it {depth[i]:.2f} m deep, not in front of the camera")
        elif len(b.scan):
            zc = (b.scan_3d.mean(axis=0) - t) @ R[:, 2]
            if zc <= 0:
                st["bad"].append(f"under this answer its scan lies behind the camera (depth {zc:.2f} m)")
        out.append(st)
    return out


UNIT_RATIO = 50.0
"""Two lengths that should agree but differ by more than this factor point to a unit mistake (mm for m)."""
MAX_PLAUSIBLE_RANGE_M = 200.0
"""Median scan range (metres) above which a 2D lidar's scan is taken to be in millimetres."""
MAX_PLAUSIBLE_BOARD_M = 20.0
"""Board outline diameter (metres) above which the outline is taken to be in millimetres."""


def unit_causes(obs: Observations) -> list[tuple[str, str]]:
    """Unit mistakes visible in the data alone (computed once per ``Observations``)."""
    return list(obs.derived("verdict.unit_causes", _unit_causes))


def _unit_causes(obs: Observations) -> list[tuple[str, str]]:
    if not obs.n_boards:
        return []
    rng = np.median(np.concatenate([np.linalg.norm(b.scan, axis=1) for b in obs.boards]))
    cam = np.median([np.linalg.norm(b.T_cam_board[:3, 3]) for b in obs.boards])
    diam = np.median([np.ptp(b.outline, axis=0).max() for b in obs.boards if b.outline is not None] or [np.nan])
    seg = np.median([np.linalg.norm(b.scan[-1] - b.scan[0]) for b in obs.boards])
    out = []
    scans_big = rng > MAX_PLAUSIBLE_RANGE_M or (rng > UNIT_RATIO * cam and seg > UNIT_RATIO * diam)
    poses_big = cam > MAX_PLAUSIBLE_RANGE_M or cam > UNIT_RATIO * rng
    if scans_big:
        out.append(("units", f"units: the scans look ~1000x too large (median range {rng:.4g} m, board distance "
                             f"{cam:.3g} m from the camera): millimetres written as metres?"))
    if poses_big:
        out.append(("units", f"units: the board poses look ~1000x too large (median board distance {cam:.4g} m from "
                             f"the camera, scan range {rng:.3g} m): millimetres written as metres?"))
    if diam > MAX_PLAUSIBLE_BOARD_M or (diam > UNIT_RATIO * seg and not scans_big):
        out.append(("units", f"units: the board outlines look ~1000x too large (diameter {diam:.4g} m, scan "
                             f"segments {seg:.3g} m): millimetres written as metres?"))
    return out


def copy_causes(obs: Observations, board_ids=None) -> list[tuple[str, str]]:
    """Copies in the data alone: boards listed more than once (identical pose and scan: each copy counts as a
    new view, so every method weighs that board twice and its covariance is too small) and scans that are one
    point repeated (RMS spread under ``MIN_SPREAD_M``). ``board_ids``: the boards' numbers in the messages."""
    ids = list(range(obs.n_boards)) if board_ids is None else [int(i) for i in board_ids]
    groups: dict[bytes, list[int]] = {}
    for i, b in zip(ids, obs.boards, strict=True):
        groups.setdefault(b.T_cam_board.tobytes() + b"|" + b.scan.tobytes(), []).append(i)
    dup = ["boards " + " = ".join(map(str, g)) for g in groups.values() if len(g) > 1]
    out = [("duplicated", f"duplicated boards: {', '.join(dup)} (identical pose and scan, one board listed more than "
                          "once): each copy counts as another view; remove the copies")] if dup else []
    for i, b in zip(ids, obs.boards, strict=True):
        if len(b.scan) > 1 and np.sqrt(np.mean(np.sum((b.scan - b.scan.mean(axis=0)) ** 2, axis=1))) < MIN_SPREAD_M:
            out.append(("repeated", f"board {i}: its {len(b.scan)} scan points are one point repeated: no line, "
                                    "its plane is not constrained"))
    return out


def data_warnings(obs: Observations) -> list[str]:
    """Warnings about the data alone: units (``unit_causes``), copies (``copy_causes``)."""
    return [msg for _, msg in unit_causes(obs) + copy_causes(obs)]


def orientation_warnings(T: np.ndarray) -> list[tuple[str, str]]:
    """An answer with the lidar upside down against the camera: its z axis (up, the scan plane's normal) along
    the camera's +y (down). A lidar may be mounted so; more often its scans are mirrored (angle direction
    reversed), which a 2D scan cannot tell from an upside-down mount."""
    up = float(np.asarray(T, float)[2, 1])      # lidar z in camera coordinates, its y component
    if up > 0.5:
        return [("mirrored", "the answer has the lidar upside down against the camera (lidar z along the camera's "
                             "+y, down): if the lidar is mounted upright, its scans are mirrored (angle direction "
                             "reversed)")]
    return []


def check(obs: Observations, T_lidar_cam: np.ndarray, *, range_sigma_m: float | None = None,
          board_ids=None) -> Verdict:
    """The verdict on ``T_lidar_cam`` for ``obs`` (no explanation: ``diagnose.judge`` adds the likely causes).
    ``range_sigma_m``: the range-noise std, default estimated from the scan lines. ``board_ids``: the boards'
    numbers in the reasons (default 0..N-1; a method that left boards out is judged on those it used)."""
    sigma = effective_sigma(obs, range_sigma_m)
    stats = board_tests(obs, T_lidar_cam, sigma)
    if board_ids is not None:
        for st in stats:
            st["board"] = int(board_ids[st["board"]])
    found = unit_causes(obs) + copy_causes(obs, board_ids) + orientation_warnings(T_lidar_cam)
    warnings = [msg for _, msg in found]
    names = tuple(dict.fromkeys(n for n, _ in found))
    bad = [s for s in stats if s["bad"]]
    if not bad:
        return Verdict(True, None, tuple(warnings), names, sigma, tuple(stats))
    reason = "; ".join(f"board {s['board']}: " + ", ".join(s["bad"]) for s in bad[:4])
    if len(bad) > 4:
        reason += f"; and {len(bad) - 4} more boards"
    return Verdict(False, f"{len(bad)} of {obs.n_boards} boards contradict the answer: {reason}", tuple(warnings),
                   names, sigma, tuple(stats))


def is_consistent(obs: Observations, T_lidar_cam: np.ndarray, sigma: float) -> bool:
    """True when no board's tests contradict ``T_lidar_cam`` at noise ``sigma`` (metres)."""
    return not any(s["bad"] for s in board_tests(obs, T_lidar_cam, sigma))
