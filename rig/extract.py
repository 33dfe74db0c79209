"""From a dataset folder to ``Observations``: board poses from images, board points from scans, per-pose diagnostics.

Per pose: ``cv2.findChessboardCornersSB`` -> corner order made canonical (right-handed board frame, origin square
colour from board.yaml) -> undistorted corners -> ``cv2.solvePnP(SOLVEPNP_IPPE)`` + ``cv2.solvePnPRefineLM`` ->
reprojection RMS (pixels, with distortion). Scan: no-returns dropped, optional background subtraction, breakpoint
clustering (adaptive threshold of Borges & Aldon 2004), split-and-merge into line segments, and the segment that
agrees with the camera's view of the board is kept (hard gates: ranges within the camera-to-board distances
+- ``max_offset_m``, length at most the board's diagonal; ranking: distance to the board centre and the expected
chord). A manual bearing window from windows.yaml replaces the search. A pose whose board or segment is not
found is skipped with its reason, never used.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from calib_core.camera import Camera
from calib_core.errors import LidarcamError, ObservationError
from calib_core.lines import tls_line
from calib_core.observations import BoardObservation, Observations
from calib_core.transforms import make_T, transform_points

from .dataset import BoardSpec, CameraModel, Dataset, DatasetError, Pose, Scan

UNDISTORT_CRITERIA = (3, 50, 1e-10)  # cv2.TERM_CRITERIA_COUNT | EPS: OpenCV's default of 5 iterations is too few


class ExtractionError(LidarcamError):
    """A pose's board or scan segment could not be found; the message is the skip reason."""


class AmbiguousSegment(ExtractionError):
    """Several scan segments fit the board about equally; ``segments`` holds their (i0, i1) index ranges, best
    first, so that a later pass (``extract``) can choose with the extrinsic of the unambiguous poses."""

    def __init__(self, message: str, segments: list[tuple[int, int]]) -> None:
        super().__init__(message)
        self.segments = segments


CURVATURE_CHI2 = 15.14
"""A segment is refused as not straight when a parabola along its line explains more of its scatter than a line
by more than this chi-square(1) quantile (1 - 1e-4) in units of the range noise: an arc, not a board."""


@dataclass(frozen=True)
class ExtractOptions:
    """Thresholds of the extraction (metres, radians, pixels).

    Attributes:
        max_offset_m: bound on the lidar-camera separation; a board point's lidar range must lie within the
            camera's distances to the board +- this.
        max_reproj_px: a detection whose corner reprojection RMS exceeds this is rejected.
        range_sigma_m: assumed lidar range noise (1 sigma), used in the breakpoint and split thresholds.
        breakpoint_lambda_deg: Borges-Aldon breakpoint angle (smaller = more permissive of oblique surfaces).
        split_tol_m: split a segment where a point lies further than this from its chord; merge neighbours whose
            union fits a line within it. 0 means ``max(0.05, 4 * range_sigma_m)``.
        min_points: fewest scan points on a board.
        min_length_frac: shortest accepted segment, as a fraction of the outline's shorter side.
        length_slack_m: accepted excess of the segment length over the board's diagonal (noise at the ends).
        background_tol_m: a point whose range is not shorter than the background's by this much is background.
        scan_plane_normal_cam: assumed normal of the scan plane in the camera frame for the expected chord
            (default: camera y, i.e. a lidar scanning roughly parallel to the camera's x-z plane); ranking only.
        chord_weight: weight of the expected-chord term in the ranking (0 disables it).
        detector_flags: extra ``cv2.CALIB_CB_*`` flags for findChessboardCornersSB (default: normalise + exhaustive
            + accuracy).
        auto_background: with no background.csv, drop the points that stay put across the poses (rig.multipose).
        static_tol_m: range agreement for a point to count as the same return in another pose.
        max_curvature_chi2: a segment whose parabola fit beats the line by more than this (chi-square(1) units of
            the range noise) is refused as an arc (``CURVATURE_CHI2``; raise it for a lidar whose range depends on
            the surface's colour).
        outline_known: False when the physical board may be larger than ``board.outline`` (e.g. a printed sheet on
            a larger board): segments longer than the outline's chord are not penalised, up to ``max_board_m``.
        max_board_m: longest accepted segment when the outline is not known.
        skip_ambiguous: skip a pose whose two best segments score within ``ambiguity_margin`` (else keep the best
            with a note).
        merge_duplicates: poses whose camera views agree within ``duplicate_deg`` / ``duplicate_m`` are one board
            pose captured several times: they become one board holding all their scan points.
        resolve_ratio: an ambiguous pose is resolved by the extrinsic of the unambiguous poses when its best
            candidate's point-to-plane RMS is below ``split_tol`` and below this times the next one's.
    """

    max_offset_m: float = 0.5
    max_reproj_px: float = 2.0
    range_sigma_m: float = 0.02
    breakpoint_lambda_deg: float = 10.0
    split_tol_m: float = 0.0
    min_points: int = 5
    min_length_frac: float = 0.25
    length_slack_m: float = 0.1
    background_tol_m: float = 0.1
    scan_plane_normal_cam: tuple[float, float, float] = (0.0, 1.0, 0.0)
    chord_weight: float = 0.5
    detector_flags: int | None = None
    auto_background: bool = True
    static_tol_m: float = 0.03
    outline_known: bool = True
    max_curvature_chi2: float = CURVATURE_CHI2
    max_board_m: float = 2.0
    skip_ambiguous: bool = True
    ambiguity_margin: float = 0.1
    merge_duplicates: bool = True
    duplicate_deg: float = 1.5
    duplicate_m: float = 0.015
    resolve_ratio: float = 0.5

    @property
    def split_tol(self) -> float:
        return self.split_tol_m if self.split_tol_m > 0 else max(0.05, 4.0 * self.range_sigma_m)


@dataclass
class PoseDiagnostics:
    """What extraction found for one pose. ``used`` is True when the pose became a board of the Observations
    (``board_index`` then says which); otherwise ``reason`` says why it was skipped."""

    name: str
    used: bool = False
    reason: str | None = None
    board_index: int | None = None
    n_corners: int = 0
    reproj_rms_px: float = math.nan
    cam_distance_m: float = math.nan
    n_scan: int = 0
    n_background: int = 0
    n_segments: int = 0
    n_candidates: int = 0
    source: str = ""
    segment: tuple[int, int] | None = None
    ambiguous: list[tuple[int, int]] = field(default_factory=list)
    n_points: int = 0
    bearing_deg: tuple[float, float] | None = None
    length_m: float = math.nan
    range_m: float = math.nan
    line_rms_mm: float = math.nan
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        d = asdict(self)
        return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}


# --------------------------------------------------------------------------------------------------- camera side
@dataclass(frozen=True, eq=False)
class BoardDetection:
    """Camera-side result for one image: ``T_cam_board`` 4x4, ``corners`` (N,2) raw pixels in canonical order,
    ``reproj_rms_px``."""

    T_cam_board: np.ndarray
    corners: np.ndarray
    reproj_rms_px: float


def _square_mean(gray: np.ndarray, quad: np.ndarray) -> float:
    """Mean intensity inside the quad (4,2 pixels) shrunk by half towards its centre."""
    import cv2

    c = quad.mean(axis=0)
    q = c + 0.5 * (quad - c)
    mask = np.zeros(gray.shape, np.uint8)
    cv2.fillConvexPoly(mask, np.round(q * 16).astype(np.int32), 1, lineType=cv2.LINE_8, shift=4)
    vals = gray[mask > 0]
    return float(vals.mean()) if vals.size else math.nan


def _solve_pose(obj: np.ndarray, corners: np.ndarray, camera: CameraModel):
    import cv2

    und = cv2.undistortPoints(corners.reshape(-1, 1, 2), camera.K, camera.dist, P=camera.K,
                              criteria=UNDISTORT_CRITERIA).reshape(-1, 2)
    ok, rvec, tvec = cv2.solvePnP(obj, und, camera.K, None, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise ExtractionError("solvePnP (IPPE) failed on the detected corners")
    rvec, tvec = cv2.solvePnPRefineLM(obj, und, camera.K, None, rvec, tvec)
    R, _ = cv2.Rodrigues(rvec)
    proj, _ = cv2.projectPoints(obj, rvec, tvec, camera.K, camera.dist)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - corners) ** 2, axis=1))))
    return make_T(R, tvec.ravel()), rms


def detect_board(gray: np.ndarray, camera: CameraModel, board: BoardSpec, flags: int | None = None,
                 corners: np.ndarray | None = None) -> BoardDetection:
    """Find the checkerboard in ``gray`` and its pose ``T_cam_board``; raises ExtractionError when not found.
    ``corners`` (N,2): the detector's corners found already (e.g. for the intrinsics), to skip the detection; an
    empty array means the detector already found no board.

    The detector's corner order is made canonical: the board frame is right-handed with z pointing away from the
    camera (a mirrored order is reversed along rows) and, when ``cols + rows`` is odd and board.yaml states the
    origin square's colour, a 180-degree reversal is undone.
    """
    import cv2

    if flags is None:
        flags = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    found = corners is not None and len(corners) > 0
    if corners is None:
        found, corners = cv2.findChessboardCornersSB(gray, (board.cols, board.rows), flags=flags)
    if not found or corners is None:
        raise ExtractionError(f"checkerboard with {board.cols}x{board.rows} inner corners not found in the image")
    corners = corners.reshape(-1, 2).astype(float)
    obj = board.corners
    T, rms = _solve_pose(obj, corners, camera)
    if T[:3, 2] @ T[:3, 3] < 0:  # mirrored order: the board's z axis points at the camera
        corners = corners.reshape(board.rows, board.cols, 2)[:, ::-1].reshape(-1, 2).copy()
        T, rms = _solve_pose(obj, corners, camera)
    if not board.reversible and board.origin_square_dark is not None:
        c = board.cols
        origin = _square_mean(gray, corners[[0, 1, c + 1, c]])
        neighbour = _square_mean(gray, corners[[1, 2, c + 2, c + 1]])
        if math.isfinite(origin) and math.isfinite(neighbour) and (origin < neighbour) != board.origin_square_dark:
            corners = corners[::-1].copy()
            T, rms = _solve_pose(obj, corners, camera)
    return BoardDetection(T, corners, rms)


# --------------------------------------------------------------------------------------------------- scan side
def breakpoints(scan: Scan, range_sigma_m: float = 0.02, lambda_deg: float = 10.0) -> np.ndarray:
    """Indices i where the sweep breaks between point i and i+1 (Borges & Aldon's adaptive threshold:
    ``r_i sin(dtheta) / sin(lambda - dtheta) + 3 sigma``)."""
    if len(scan) < 2:
        return np.zeros(0, int)
    P, r = scan.points, scan.range
    gap = np.linalg.norm(np.diff(P, axis=0), axis=1)
    dth = np.abs(np.angle(np.exp(1j * np.diff(scan.bearing))))
    lam = math.radians(lambda_deg)
    with np.errstate(divide="ignore", invalid="ignore"):
        thresh = np.where(dth < lam, r[:-1] * np.sin(dth) / np.sin(lam - dth), 0.0) + 3.0 * range_sigma_m
    return np.flatnonzero(gap > thresh)


def _chord_split(P: np.ndarray, tol: float, min_points: int) -> list[tuple[int, int]]:
    """Recursive split (iterative end-point fit) of the run ``P``; half-open index ranges relative to P."""
    out, stack = [], [(0, len(P))]
    while stack:
        i0, i1 = stack.pop()
        n = i1 - i0
        if n < 3:
            out.append((i0, i1))
            continue
        k = max(1, min(3, n // 6))
        a, b = P[i0:i0 + k].mean(axis=0), P[i1 - k:i1].mean(axis=0)
        u = b - a
        L = np.linalg.norm(u)
        Q = P[i0:i1]
        if L < 1e-9:
            d = np.linalg.norm(Q - a, axis=1)
        else:
            d = np.abs((Q - a) @ np.array([-u[1], u[0]]) / L)
        j = int(np.argmax(d[1:-1])) + 1
        if d[j] > tol:
            stack += [(i0 + j + 1, i1), (i0, i0 + j + 1)] if j < n // 2 else [(i0 + j, i1), (i0, i0 + j)]
        else:
            out.append((i0, i1))
    return sorted(out)


def _merge(P: np.ndarray, segs: list[tuple[int, int]], tol: float) -> list[tuple[int, int]]:
    segs = list(segs)
    merged = True
    while merged and len(segs) > 1:
        merged = False
        best, best_err = None, tol
        for k in range(len(segs) - 1):
            i0, i1 = segs[k][0], segs[k + 1][1]
            err = float(np.max(np.abs(tls_line(P[i0:i1])[2])))
            if err <= best_err:
                best, best_err = k, err
        if best is not None:
            segs[best:best + 2] = [(segs[best][0], segs[best + 1][1])]
            merged = True
    return segs


def split_and_merge(scan: Scan, keep: np.ndarray | None = None, opts: ExtractOptions | None = None
                    ) -> list[tuple[int, int]]:
    """Line segments of a scan as half-open index ranges ``(i0, i1)`` into the scan (only points with ``keep``).

    Breakpoints (range jumps, dropped points) split the sweep into runs; each run is split where a point lies
    further than ``opts.split_tol`` from the chord of its ends, and neighbouring pieces are merged back while
    their union fits one line within the same tolerance. Segments shorter than ``opts.min_points`` are dropped.
    """
    opts = opts or ExtractOptions()
    keep = np.ones(len(scan), bool) if keep is None else np.asarray(keep, bool)
    idx = np.flatnonzero(keep)
    if len(idx) < opts.min_points:
        return []
    sub = Scan(scan.bearing[idx], scan.range[idx], scan.points[idx])
    cuts = breakpoints(sub, opts.range_sigma_m, opts.breakpoint_lambda_deg)
    # a removed point in between also breaks the run
    cuts = np.union1d(cuts, np.flatnonzero(np.diff(idx) > 1))
    bounds = np.concatenate([[0], cuts + 1, [len(idx)]])
    segs = []
    for s0, s1 in zip(bounds[:-1], bounds[1:], strict=True):
        if s1 - s0 < opts.min_points:
            continue
        P = sub.points[s0:s1]
        pieces = _merge(P, _chord_split(P, opts.split_tol, opts.min_points), opts.split_tol)
        segs += [(int(idx[s0 + a]), int(idx[s0 + b - 1]) + 1) for a, b in pieces if b - a >= opts.min_points]
    return segs


def background_mask(scan: Scan, background: Scan, tol_m: float = 0.1) -> np.ndarray:
    """True for points of ``scan`` that are background: not at least ``tol_m`` nearer than the background beam at
    the same bearing (nearest background beam within 1.5 median beam steps; points without one are kept)."""
    if len(background) == 0 or len(scan) == 0:
        return np.zeros(len(scan), bool)
    order = np.argsort(background.bearing)
    bb, br = background.bearing[order], background.range[order]
    step = np.median(np.abs(np.diff(bb))) if len(bb) > 1 else math.inf
    j = np.clip(np.searchsorted(bb, scan.bearing), 1, max(len(bb) - 1, 1))
    left, right = np.clip(j - 1, 0, len(bb) - 1), np.clip(j, 0, len(bb) - 1)
    pick = np.where(np.abs(scan.bearing - bb[left]) <= np.abs(scan.bearing - bb[right]), left, right)
    near = np.abs(scan.bearing - bb[pick]) <= 1.5 * step
    return near & (scan.range > br[pick] - tol_m)


def _polygon_chord(outline: np.ndarray, c: np.ndarray, u: np.ndarray) -> float:
    """Length of the intersection of the line ``c + s u`` (board frame 2D) with the convex hull of ``outline``."""
    s_vals = []
    V = len(outline)
    for k in range(V):
        a, b = outline[k], outline[(k + 1) % V]
        e = b - a
        M = np.array([[u[0], -e[0]], [u[1], -e[1]]])
        if abs(np.linalg.det(M)) < 1e-12:
            continue
        s, t = np.linalg.solve(M, a - c)
        if -1e-9 <= t <= 1 + 1e-9:
            s_vals.append(s)
    return float(max(s_vals) - min(s_vals)) if len(s_vals) >= 2 else 0.0


def expected_chord(T_cam_board: np.ndarray, board: BoardSpec, plane_normal_cam=(0.0, 1.0, 0.0)) -> float:
    """Chord of the board through its centre along the board plane's intersection with a plane of normal
    ``plane_normal_cam`` (camera frame), metres; NaN when the two planes are parallel."""
    n_b = T_cam_board[:3, 2]
    d = np.cross(n_b, np.asarray(plane_normal_cam, float))
    if np.linalg.norm(d) < 1e-6:
        return math.nan
    u = T_cam_board[:3, :3].T @ (d / np.linalg.norm(d))
    return _polygon_chord(board.outline, board.centre, u[:2] / np.linalg.norm(u[:2]))


def board_distance_range(T_cam_board: np.ndarray, board: BoardSpec) -> tuple[float, float]:
    """(nearest, farthest) distance from the camera centre to the board (its plane and outline vertices), metres."""
    V = transform_points(T_cam_board, np.column_stack([board.outline, np.zeros(len(board.outline))]))
    far = float(np.linalg.norm(V, axis=1).max())
    plane = abs(float(T_cam_board[:3, 2] @ T_cam_board[:3, 3]))
    return min(plane, float(np.linalg.norm(V, axis=1).min())), far


@dataclass
class _Segment:
    i0: int
    i1: int
    length: float
    range_mid: float
    rms: float
    score: float = math.inf


def curvature_statistic(P: np.ndarray, range_sigma_m: float) -> float:
    """How much better a parabola than a straight line fits the (K,2) points, in chi-square(1) units of the range
    noise across the line (``sigma |nu . beam|``); about chi-square(1) for a straight segment."""
    if len(P) < 4:
        return 0.0
    c, u, res, _ = tls_line(P)
    nu = np.array([-u[1], u[0]])
    s = (P - c) @ u
    A = np.column_stack([np.ones_like(s), s, s**2])
    coef, *_ = np.linalg.lstsq(A, res, rcond=None)
    gain = float(res @ res - np.sum((res - A @ coef) ** 2))
    beams = P / np.linalg.norm(P, axis=1, keepdims=True)
    sigma_p = range_sigma_m * max(float(np.sqrt(np.mean((beams @ nu) ** 2))), 0.05)
    return gain / sigma_p**2


def _describe(scan: Scan, idx: np.ndarray) -> tuple[float, float, float]:
    P = scan.points[idx]
    c, u, res, _ = tls_line(P)
    s = (P - c) @ u
    return float(s.max() - s.min()), float(np.linalg.norm(c)), float(np.sqrt(np.mean(res ** 2)))


def find_board_segment(scan: Scan, T_cam_board: np.ndarray, board: BoardSpec, opts: ExtractOptions | None = None,
                       background: Scan | None = None, diag: PoseDiagnostics | None = None,
                       static: np.ndarray | None = None) -> np.ndarray:
    """Indices of the scan points on the board (ordered along the sweep); raises ExtractionError when no segment
    agrees with the camera's view of the board. ``static``: mask of points that stay put across poses (dropped)."""
    opts = opts or ExtractOptions()
    diag = diag if diag is not None else PoseDiagnostics("")
    keep = np.ones(len(scan), bool)
    if background is not None:
        bg = background_mask(scan, background, opts.background_tol_m)
        keep &= ~bg
        diag.n_background = int(bg.sum())
    if static is not None:
        keep &= ~static
        diag.n_background += int(static.sum())
    segs = split_and_merge(scan, keep, opts)
    diag.n_segments = len(segs)
    if not segs:
        raise ExtractionError("no line segment in the scan" + (" after background subtraction" if background
                                                               is not None else ""))
    near, far = board_distance_range(T_cam_board, board)
    lo, hi = near - opts.max_offset_m, far + opts.max_offset_m
    ext = board.outline.max(axis=0) - board.outline.min(axis=0)
    min_len, max_len = opts.min_length_frac * float(ext.min()), board.diagonal + opts.length_slack_m
    if not opts.outline_known:
        max_len = max(max_len, opts.max_board_m)
    chord = expected_chord(T_cam_board, board, opts.scan_plane_normal_cam) if opts.chord_weight > 0 else math.nan
    centre_dist = float(np.linalg.norm(transform_points(T_cam_board, [[*board.centre, 0.0]])[0]))
    cands, rejected = [], []
    for i0, i1 in segs:
        idx = np.arange(i0, i1)
        length, rmid, rms = _describe(scan, idx)
        r = scan.range[idx]
        inside = np.mean((r >= lo) & (r <= hi))
        why = None
        if inside < 0.9:
            why = f"range {r.min():.2f}-{r.max():.2f} m outside {lo:.2f}-{hi:.2f} m"
        elif length > max_len:
            why = f"length {length:.2f} m > diagonal {board.diagonal:.2f} m"
        elif length < min_len:
            why = f"length {length:.2f} m < {min_len:.2f} m"
        elif (curv := curvature_statistic(scan.points[idx], opts.range_sigma_m)) > opts.max_curvature_chi2:
            why = (f"not straight within the noise (curvature statistic {curv:.3g} > {opts.max_curvature_chi2:g}): "
                   "an arc (a pillar, a curved object), not a board")
        if why:
            rejected.append(why)
            continue
        score = abs(rmid - centre_dist) / max(board.diagonal / 2, 1e-3)
        if math.isfinite(chord) and chord > 0:
            miss = length - chord if opts.outline_known else max(0.0, chord - length)
            score += opts.chord_weight * abs(miss) / chord
        score += rms / opts.split_tol
        cands.append(_Segment(i0, i1, length, rmid, rms, score))
    diag.n_candidates = len(cands)
    if not cands:
        raise ExtractionError(f"no scan segment matches the board at {near:.2f}-{far:.2f} m "
                              f"({len(segs)} segments; refused: {'; '.join(rejected) if rejected else '-'})")
    cands.sort(key=lambda s: s.score)
    best = cands[0]
    if len(cands) > 1 and cands[1].score - best.score < opts.ambiguity_margin:
        two = ", ".join(f"{math.degrees(scan.bearing[c.i0]):.1f}..{math.degrees(scan.bearing[c.i1 - 1]):.1f} deg "
                        f"(score {c.score:.2f})" for c in cands[:2])
        if opts.skip_ambiguous:
            raise AmbiguousSegment(f"ambiguous: {len(cands)} segments fit the board about equally: {two}",
                                   [(c.i0, c.i1) for c in cands if c.score - best.score < opts.ambiguity_margin])
        diag.notes.append(f"ambiguous: {len(cands)} segments fit the board about equally: {two}")
    return np.arange(best.i0, best.i1)


# --------------------------------------------------------------------------------------------------- per pose
def extract_pose(pose: Pose, dataset: Dataset, opts: ExtractOptions | None = None, det: BoardDetection | None = None,
                 static: np.ndarray | None = None
                 ) -> tuple[BoardObservation | None, PoseDiagnostics, BoardDetection | None]:
    """One pose: (board observation or None, diagnostics, camera detection or None). Never raises for bad data.
    ``det``: the camera detection made already; ``static``: the scan's static points (rig.multipose)."""
    opts = opts or ExtractOptions()
    diag = PoseDiagnostics(pose.name)
    try:
        if pose.error is not None:
            raise pose.error
        if det is None:
            det = detect_board(pose.read_image(), dataset.camera, dataset.board, opts.detector_flags, pose.corners)
        diag.n_corners = len(det.corners)
        diag.reproj_rms_px = det.reproj_rms_px
        diag.cam_distance_m = float(np.linalg.norm(
            transform_points(det.T_cam_board, [[*dataset.board.centre, 0.0]])[0]))
        if det.reproj_rms_px > opts.max_reproj_px:
            raise ExtractionError(f"corner reprojection RMS {det.reproj_rms_px:.2f} px > {opts.max_reproj_px} px")
        scan = pose.scan
        diag.n_scan = len(scan)
        if pose.window is not None:
            lo, hi = pose.window
            idx = np.flatnonzero((scan.bearing >= lo) & (scan.bearing <= hi))
            diag.source = "window"
            if len(idx) < opts.min_points:
                raise ExtractionError(f"manual window {math.degrees(lo):.1f}..{math.degrees(hi):.1f} deg holds "
                                      f"{len(idx)} points (< {opts.min_points})")
        else:
            diag.source = "auto"
            idx = find_board_segment(scan, det.T_cam_board, dataset.board, opts, dataset.background, diag, static)
        _board_finish(scan, idx, diag)
        if diag.source == "window" and diag.line_rms_mm > 1000 * opts.split_tol:
            diag.notes.append(f"window points fit a line only to {diag.line_rms_mm:.0f} mm RMS")
        obs = BoardObservation(det.T_cam_board, dataset.board.outline, scan.points[idx], det.corners,
                               dataset.board.corners)
        diag.used = True
        return obs, diag, det
    except (ExtractionError, DatasetError) as err:
        diag.reason = str(err)
        diag.ambiguous = list(getattr(err, "segments", []))
        return None, diag, det


def _detect_all(dataset: Dataset, opts: ExtractOptions) -> dict[str, BoardDetection | Exception]:
    """Camera side of every pose: its detection, or the error that stops it."""
    out: dict[str, BoardDetection | Exception] = {}
    for pose in dataset.poses:
        try:
            if pose.error is not None:
                raise pose.error
            out[pose.name] = detect_board(pose.read_image(), dataset.camera, dataset.board, opts.detector_flags,
                                          pose.corners)
        except (ExtractionError, DatasetError) as err:
            out[pose.name] = err
    return out


def _board_finish(obs_scan: Scan, idx: np.ndarray, diag: PoseDiagnostics) -> None:
    length, rmid, rms = _describe(obs_scan, idx)
    diag.segment = (int(idx[0]), int(idx[-1]) + 1)
    diag.n_points = len(idx)
    diag.bearing_deg = (math.degrees(obs_scan.bearing[idx[0]]), math.degrees(obs_scan.bearing[idx[-1]]))
    diag.length_m, diag.range_m, diag.line_rms_mm = length, rmid, 1000 * rms


def _resolve_ambiguous(dataset: Dataset, boards: list, diags: list[PoseDiagnostics], dets: dict,
                       opts: ExtractOptions) -> None:
    """Second pass over ambiguous poses: calibrate on the unambiguous boards (``zhang_pless``, or ``vasconcelos``
    with fewer than 5 boards or when it fails: both fast, point-to-plane), then keep the candidate
    segment whose points lie on the board plane through that extrinsic, when it is clearly the best; otherwise
    the pose stays skipped and its reason says what the extrinsic showed."""
    todo = [k for k, d in enumerate(diags) if d.ambiguous]
    good = [replace(b, corners_px=None, corners_board=None) for b in boards if b is not None]
    if not todo or len(good) < 3:
        return
    from calib_core.entry import calibrate
    from calib_core.transforms import invert_T

    res = calibrate(Observations(tuple(good)), "zhang_pless") if len(good) >= 5 else None
    if res is None or not res.ok:
        res = calibrate(Observations(tuple(good)), "vasconcelos")
    if not res.ok:
        return
    T_cam_lidar = invert_T(res.T_lidar_cam)
    by_name = {p.name: p for p in dataset.poses}
    for k in todo:
        d, pose = diags[k], by_name[diags[k].name]
        T_cb = dets[d.name].T_cam_board
        n, off = T_cb[:3, 2], float(T_cb[:3, 2] @ T_cb[:3, 3])
        rms = []
        for i0, i1 in d.ambiguous:
            P = transform_points(T_cam_lidar, np.column_stack([pose.scan.points[i0:i1], np.zeros(i1 - i0)]))
            rms.append(float(np.sqrt(np.mean((P @ n - off) ** 2))))
        order = np.argsort(rms)
        best, second = rms[order[0]], rms[order[1]] if len(rms) > 1 else math.inf
        what = ", ".join(f"{math.degrees(pose.scan.bearing[a]):.1f}..{math.degrees(pose.scan.bearing[b - 1]):.1f} "
                         f"deg at {1000 * r:.0f} mm" for (a, b), r in zip(d.ambiguous, rms, strict=True))
        if best < opts.split_tol and best < opts.resolve_ratio * second:
            i0, i1 = d.ambiguous[order[0]]
            idx = np.arange(i0, i1)
            boards[k] = BoardObservation(T_cb, dataset.board.outline, pose.scan.points[idx], dets[d.name].corners,
                                         dataset.board.corners)
            d.used, d.reason = True, None
            _board_finish(pose.scan, idx, d)
            d.notes.append(f"ambiguous segments resolved by the extrinsic of {len(good)} other boards "
                           f"(point-to-plane RMS: {what})")
        else:
            d.reason += f"; the extrinsic of {len(good)} other boards does not settle it ({what})"


def _merge_duplicates(boards: list, diags: list[PoseDiagnostics], groups: list[int]) -> tuple[list, dict]:
    """One board per duplicate group: the camera pose of the member with the lowest reprojection RMS and the scan
    points of all members (ordered by bearing). Returns (boards, representative pose -> merged pose names)."""
    by_group: dict[int, list[int]] = {}
    for k, d in enumerate(diags):
        if d.used:
            by_group.setdefault(groups[k], []).append(k)
    out, merged = [], {}
    for members in by_group.values():
        rep = min(members, key=lambda k: diags[k].reproj_rms_px)
        pts = np.vstack([boards[k].scan for k in members])
        pts = pts[np.argsort(np.arctan2(pts[:, 1], pts[:, 0]), kind="stable")]
        for k in members:
            diags[k].board_index = len(out)
            if k != rep:
                diags[k].notes.append(f"near-duplicate of pose {diags[rep].name}: merged into its board")
        if len(members) > 1:
            merged[diags[rep].name] = [diags[k].name for k in members if k != rep]
        out.append(replace(boards[rep], scan=pts))
    return out, merged


def extract(dataset: Dataset, opts: ExtractOptions | None = None) -> tuple[Observations, list[PoseDiagnostics]]:
    """Every pose of ``dataset`` -> (Observations of the usable poses, diagnostics of every pose).

    The camera side runs first for every pose; near-duplicate poses (rig.multipose.duplicate_groups) are grouped;
    with no background.csv the points that stay put across the groups are dropped (``opts.auto_background``);
    then each pose's board segment is searched for, and a group's boards are merged into one
    (``opts.merge_duplicates``). ``Observations.meta`` holds ``poses`` (the pose name of each board, in order),
    ``skipped`` (pose -> reason), ``merged`` (pose -> the near-duplicates merged into its board),
    ``reproj_rms_px`` per board and ``dataset`` (the folder). Every board carries its detected corners (distorted
    pixels, canonical order) and their board-frame positions, and the observations the camera intrinsics, so the
    joint model over corners and ranges applies (``meta["camera_note"]`` says why not when the intrinsics do not
    fit ``calib_core.camera.Camera``). The ground truth of a simulated dataset
    (ground_truth.yaml ``T_lidar_cam``) becomes ``T_lidar_cam_true``.
    """
    from .multipose import duplicate_groups, static_masks

    opts = opts or ExtractOptions()
    dets = _detect_all(dataset, opts)
    Ts = [d.T_cam_board if isinstance(d, BoardDetection) else None for d in dets.values()]
    groups = duplicate_groups(Ts, opts.duplicate_deg, opts.duplicate_m) if opts.merge_duplicates \
        else list(range(len(Ts)))
    statics = [None] * len(Ts)
    if opts.auto_background and dataset.background is None:
        statics = static_masks([p.scan if p.error is None else None for p in dataset.poses], groups,
                               opts.static_tol_m)
    boards, diags = [], []
    camera, camera_note = _camera(dataset)
    for k, pose in enumerate(dataset.poses):
        det = dets[pose.name]
        if isinstance(det, Exception):
            obs, diag = None, PoseDiagnostics(pose.name, reason=str(det))
        else:
            obs, diag, _ = extract_pose(pose, dataset, opts, det, statics[k])
        boards.append(obs)
        diags.append(diag)
    _resolve_ambiguous(dataset, boards, diags, dets, opts)
    boards, merged = _merge_duplicates(boards, diags, groups)
    gt = dataset.ground_truth.get("T_lidar_cam") if dataset.ground_truth else None
    if isinstance(gt, dict):
        gt = gt.get("matrix")
    reps = {}
    for d in diags:
        if d.used and d.board_index not in reps and not any(n.startswith("near-duplicate") for n in d.notes):
            reps[d.board_index] = d
    meta = {"source": "lidarcam extract", "dataset": str(dataset.root),
            "poses": [reps[i].name for i in range(len(boards))],
            "skipped": {d.name: d.reason for d in diags if not d.used},
            "merged": merged,
            "reproj_rms_px": [reps[i].reproj_rms_px for i in range(len(boards))]}
    if camera is None:
        boards = [replace(b, corners_px=None, corners_board=None) for b in boards]
        meta["camera_note"] = camera_note
    return Observations(tuple(boards), None if gt is None else np.asarray(gt, float), meta, camera), diags


def _camera(dataset: Dataset) -> tuple[Camera | None, str]:
    """The dataset's intrinsics for the observations (the boards then carry their detected corners), or None and
    why the joint model cannot use them."""
    c = dataset.camera
    try:
        return Camera(c.K, c.dist, c.width, c.height), ""
    except ObservationError as err:
        return None, f"image corners left out, the joint model cannot use the camera: {err}"


def format_diagnostics(diags: list[PoseDiagnostics]) -> str:
    """A fixed-width table of the diagnostics, one pose a line, then the skip reasons."""
    head = f"{'pose':>8} {'board':>5} {'reproj_px':>9} {'dist_m':>7} {'src':>6} {'points':>6} " \
           f"{'bearing_deg':>15} {'len_m':>6} {'line_mm':>7}"
    lines = [head]
    for d in diags:
        b = "-" if d.board_index is None else str(d.board_index)
        br = "-" if d.bearing_deg is None else f"{d.bearing_deg[0]:.1f}..{d.bearing_deg[1]:.1f}"

        def f(v, fmt):
            return "-" if not math.isfinite(v) else format(v, fmt)

        lines.append(f"{d.name:>8} {b:>5} {f(d.reproj_rms_px, '.3f'):>9} {f(d.cam_distance_m, '.2f'):>7} "
                     f"{d.source or '-':>6} {d.n_points:>6} {br:>15} {f(d.length_m, '.3f'):>6} "
                     f"{f(d.line_rms_mm, '.1f'):>7}" + ("" if d.used else "  SKIPPED"))
    skipped = [d for d in diags if not d.used]
    for d in skipped:
        lines.append(f"skipped {d.name}: {d.reason}")
    for d in diags:
        for n in d.notes:
            lines.append(f"note {d.name}: {n}")
    lines.append(f"{sum(d.used for d in diags)} of {len(diags)} poses used")
    return "\n".join(lines)
