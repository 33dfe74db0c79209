"""Camera side of the extraction: the board in one image and its pose ``T_cam_board`` (metres).

Checkerboard: ``cv2.findChessboardCornersSB`` -> corner order made canonical (right-handed board frame, origin square
colour from board.yaml). ChArUco: ``cv2.aruco.CharucoDetector``; AprilGrid: ``cv2.aruco.ArucoDetector`` with the
AprilTag 36h11 dictionary and Kalibr's 2-bit border, each tag corner refined at its junction with the grid's black
square (``cv2.cornerSubPix``); both give each corner its identity, so a board cut by the image edge or partly hidden
counts when its corners are enough and spread over the board (``check_spread``). Pose: undistorted corners ->
``cv2.solvePnP(SOLVEPNP_IPPE)`` + ``cv2.solvePnPRefineLM`` for the OpenCV pinhole, the rays of the camera model
(``calib_core.data.cameras.pose``) for the others -> reprojection RMS (pixels, through the lens)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from calib_core.geometry.transforms import make_T

from .dataset import BoardSpec, CameraModel
from .extract_options import ExtractionError

UNDISTORT_CRITERIA = (3, 50, 1e-10)  # cv2.TERM_CRITERIA_COUNT | EPS: OpenCV's default of 5 iterations is too few


@dataclass(frozen=True, eq=False)
class BoardDetection:
    """Camera-side result for one image: ``T_cam_board`` 4x4, ``corners`` (N,2) raw pixels in canonical order,
    ``reproj_rms_px``, ``ids`` (N,) the corners' identities (rows of ``BoardSpec.corners``; None: all, in order)."""

    T_cam_board: np.ndarray
    corners: np.ndarray
    reproj_rms_px: float
    ids: np.ndarray | None = None

    def corners_board(self, board: BoardSpec) -> np.ndarray:
        """(N,3) board-frame positions of ``corners`` (metres)."""
        return board.corners if self.ids is None else board.corners[self.ids]


def _square_mean(gray: np.ndarray, quad: np.ndarray) -> float:
    """Mean intensity inside the quad (4,2 pixels) shrunk by half towards its centre."""
    import cv2

    c = quad.mean(axis=0)
    q = c + 0.5 * (quad - c)
    mask = np.zeros(gray.shape, np.uint8)
    cv2.fillConvexPoly(mask, np.round(q * 16).astype(np.int32), 1, lineType=cv2.LINE_8, shift=4)
    vals = gray[mask > 0]
    return float(vals.mean()) if vals.size else math.nan


def undistort_points(px: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """(N,2) pixels ``px`` undistorted (OpenCV's model) into the pinhole ``K``'s pixels, with ``UNDISTORT_CRITERIA``
    (``cv2.undistortPoints(criteria=)`` in OpenCV 5, ``cv2.undistortPointsIter`` in OpenCV 4, where
    ``undistortPoints`` takes no criteria)."""
    import cv2

    pts = np.asarray(px, np.float64).reshape(-1, 1, 2)
    if hasattr(cv2, "undistortPointsIter"):
        return cv2.undistortPointsIter(pts, K, dist, None, K, UNDISTORT_CRITERIA).reshape(-1, 2)
    return cv2.undistortPoints(pts, K, dist, P=K, criteria=UNDISTORT_CRITERIA).reshape(-1, 2)


def _solve_pose(obj: np.ndarray, corners: np.ndarray, camera: CameraModel):
    import cv2

    if camera.lens is not None:
        return _solve_pose_lens(obj, corners, camera.lens)

    und = undistort_points(corners, camera.K, camera.dist)
    ok, rvec, tvec = cv2.solvePnP(obj, und, camera.K, None, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise ExtractionError("solvePnP (IPPE) failed on the detected corners")
    rvec, tvec = cv2.solvePnPRefineLM(obj, und, camera.K, None, rvec, tvec)
    R, _ = cv2.Rodrigues(rvec)
    proj, _ = cv2.projectPoints(obj, rvec, tvec, camera.K, camera.dist)
    rms = float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - corners) ** 2, axis=1))))
    return make_T(R, tvec.ravel()), rms


def _solve_pose_lens(obj: np.ndarray, corners: np.ndarray, lens):
    """Pose and reprojection RMS through a ``calib_core.data.cameras`` model (its rays, then its pixels)."""
    from calib_core.data.cameras.pose import pose_from_corners
    from calib_core.errors import ObservationError

    try:
        T = pose_from_corners(lens, obj, corners)
    except ObservationError as err:
        raise ExtractionError(f"board pose through the {lens.name} model failed: {err.message}") from None
    proj = lens.project(obj @ T[:3, :3].T + T[:3, 3])
    return T, float(np.sqrt(np.mean(np.sum((proj - corners) ** 2, axis=1))))


def find_chessboard(gray: np.ndarray, board: BoardSpec, flags: int | None = None) -> np.ndarray | None:
    """(cols*rows, 2) pixel corners of the board in ``gray``, or None: ``cv2.findChessboardCornersSB`` (``flags``;
    default normalise + exhaustive + accuracy), else the classic ``cv2.findChessboardCorners`` (it finds some
    strongly lit or tilted boards the sector detector misses); either refined by ``cv2.cornerSubPix``
    (``refine_corners``)."""
    import cv2

    if flags is None:
        flags = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    size = (board.cols, board.rows)
    found, corners = cv2.findChessboardCornersSB(gray, size, flags=flags)
    if not found or corners is None:
        found, corners = cv2.findChessboardCorners(gray, size, flags=cv2.CALIB_CB_ADAPTIVE_THRESH
                                                   | cv2.CALIB_CB_NORMALIZE_IMAGE)
        if not found or corners is None:
            return None
    return refine_corners(gray, corners.reshape(-1, 2), size)


SUBPIX_CRITERIA = (3, 100, 1e-4)
"""cv2.cornerSubPix stop rule (TERM_CRITERIA_COUNT | EPS, 100 iterations, 1e-4 px)."""
SUBPIX_HALF_WINDOW_PX = 3
"""cv2.cornerSubPix's half window (pixels; a 7x7 window): larger windows reach the squares' edges far from the
corner, where blur, lens distortion and uneven light pull it (measured on Nowicki's images: 1.8 px at 11)."""


def _grid_fit_rms(corners: np.ndarray, size: tuple[int, int]) -> float:
    """RMS (pixels) of the corners about the best homography of the ideal grid: how well they lie on a plane's
    image, with no intrinsics needed."""
    import cv2

    j, i = np.mgrid[0:size[1], 0:size[0]]
    grid = np.column_stack([i.ravel(), j.ravel()]).astype(np.float64)
    H, _ = cv2.findHomography(grid, corners.astype(np.float64), 0)
    if H is None:
        return float("inf")
    proj = cv2.perspectiveTransform(grid.reshape(-1, 1, 2), H).reshape(-1, 2)
    return float(np.sqrt(np.mean(np.sum((proj - corners) ** 2, axis=1))))


def refine_corners(gray: np.ndarray, corners: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``corners`` (cols*rows, 2, row by row) refined by ``cv2.cornerSubPix`` on ``gray`` (half window
    ``SUBPIX_HALF_WINDOW_PX``), kept only where they lie on a plane's image at least as well as the detector's own
    (``_grid_fit_rms``). The sector detector's corners carry an error shared along the board: on the project's
    renders 0.08 px RMS against the truth with a pose error 4x what their residual implies (the demo's false "boards
    disagree" warning); refined, 0.04 px with none (docs/lidarcam.md). On real images with lens distortion the
    refinement may fit worse; the detector's corners then stand."""
    import cv2

    c = np.asarray(corners, np.float32).reshape(-1, 1, 2)
    w = SUBPIX_HALF_WINDOW_PX
    refined = cv2.cornerSubPix(gray, c.copy(), (w, w), (-1, -1), SUBPIX_CRITERIA).reshape(-1, 2)
    c = c.reshape(-1, 2)
    better = _grid_fit_rms(refined, size) <= _grid_fit_rms(c, size)
    return (refined if better else c).astype(np.float32)


def detect_board(gray: np.ndarray, camera: CameraModel, board: BoardSpec, flags: int | None = None,
                 corners: np.ndarray | None = None) -> BoardDetection:
    """Find the board in ``gray`` and its pose ``T_cam_board``; raises ExtractionError when not found (or, for an
    identified board, when its corners are too few or too bunched: ``check_spread``). ``corners``: the detector's
    corners found already (e.g. for the intrinsics), to skip the detection: (N,2) pixels of a checkerboard, (N,3)
    pixels and identity of an identified board; an empty array means the detector already found no board.

    The detector's corner order is made canonical: the board frame is right-handed with z pointing away from the
    camera (a mirrored order is reversed along rows) and, when ``cols + rows`` is odd and board.yaml states the
    origin square's colour (light when board.yaml does not say: the order ``findChessboardCornersSB`` gives; the
    classic detector's fallback may start at the other end), a 180-degree reversal is undone.
    """
    if board.identified:
        ids, corners = (find_identified(gray, board) if corners is None or len(corners) == 0
                        else (corners[:, 2].astype(int), corners[:, :2]))
        check_spread(board, ids)
        T, rms = _solve_pose(board.corners[ids], corners.astype(float), camera)
        keep = _inliers(T, board.corners[ids], corners.astype(float), camera)
        if not keep.all():
            ids, corners = ids[keep], corners[keep]
            check_spread(board, ids)
            T, rms = _solve_pose(board.corners[ids], corners.astype(float), camera)
        return BoardDetection(T, corners.astype(float), rms, ids)
    if corners is None:
        corners = find_chessboard(gray, board, flags)
    if corners is None or len(corners) == 0:
        raise ExtractionError(f"{board.describe()} not found in the image")
    corners = corners.reshape(-1, 2).astype(float)
    obj = board.corners
    T, rms = _solve_pose(obj, corners, camera)
    if T[:3, 2] @ T[:3, 3] < 0:  # mirrored order: the board's z axis points at the camera
        corners = corners.reshape(board.rows, board.cols, 2)[:, ::-1].reshape(-1, 2).copy()
        T, rms = _solve_pose(obj, corners, camera)
    if not board.reversible:  # no origin colour given: light, the order findChessboardCornersSB gives
        dark = bool(board.origin_square_dark)
        c = board.cols
        origin = _square_mean(gray, corners[[0, 1, c + 1, c]])
        neighbour = _square_mean(gray, corners[[1, 2, c + 2, c + 1]])
        if math.isfinite(origin) and math.isfinite(neighbour) and (origin < neighbour) != dark:
            corners = corners[::-1].copy()
            T, rms = _solve_pose(obj, corners, camera)
    return BoardDetection(T, corners, rms)


# ------------------------------------------------------------------------------------------ identified boards
MIN_IDENTIFIED_CORNERS = 6
"""Fewest identified corners of a board (ChArUco, AprilGrid) that make a pose."""
MIN_HULL_SHARE = 0.15
"""Smallest share of the pattern's corner area (convex hulls on the board) the identified corners must span: a pose
from a corner of the board alone is poorly conditioned (its tilt about the far edge is hardly seen)."""
MIN_THINNESS = 0.2
"""Smallest ratio of the identified corners' shorter to longer principal spread on the board: a single row of
corners leaves the rotation about it free, whatever their count."""


def _hull_area(xy: np.ndarray) -> float:
    import cv2

    return float(cv2.contourArea(cv2.convexHull(np.asarray(xy, np.float32).reshape(-1, 1, 2))))


def corner_spread(board: BoardSpec, ids: np.ndarray) -> tuple[float, float]:
    """(hull share, thinness) of the corners ``ids`` on ``board``: the area of their convex hull over the whole
    pattern's, and the ratio of their shorter to longer principal standard deviation (board plane)."""
    xy = board.corners[np.asarray(ids, int), :2]
    if len(xy) < 3:
        return 0.0, 0.0
    share = _hull_area(xy) / _hull_area(board.corners[:, :2])
    ev = np.linalg.eigvalsh(np.cov(xy.T))
    return share, float(np.sqrt(max(ev[0], 0.0) / ev[1])) if ev[1] > 0 else 0.0


def check_spread(board: BoardSpec, ids: np.ndarray) -> None:
    """ExtractionError unless the identified corners ``ids`` are at least ``MIN_IDENTIFIED_CORNERS``, span
    ``MIN_HULL_SHARE`` of the pattern and are not a strip (``MIN_THINNESS``): the PnP's conditioning."""
    n = len(ids)
    if n < MIN_IDENTIFIED_CORNERS:
        raise ExtractionError(f"{board.describe()}: {n} corners found (a pose needs {MIN_IDENTIFIED_CORNERS} "
                              f"spread over the board)")
    share, thin = corner_spread(board, ids)
    if share < MIN_HULL_SHARE or thin < MIN_THINNESS:
        raise ExtractionError(f"{board.describe()}: the {n} corners found span {100 * share:.0f}% of the pattern with "
                              f"a thinness of {thin:.2f} (a pose needs {100 * MIN_HULL_SHARE:.0f}% and "
                              f"{MIN_THINNESS})")


@lru_cache(maxsize=8)
def _aruco(kind: str, cols: int, rows: int, square: float, marker: float, dictionary: str, legacy: bool):
    """The cv2.aruco detector of a board (cached: its construction costs more than a small image's detection)."""
    import cv2

    aruco = cv2.aruco
    d = aruco.getPredefinedDictionary(getattr(aruco, dictionary))
    params = aruco.DetectorParameters()
    if kind == "charuco":
        b = aruco.CharucoBoard((cols + 1, rows + 1), square, marker, d)
        b.setLegacyPattern(legacy)
        return aruco.CharucoDetector(b, aruco.CharucoParameters(), params)
    from .dataset.boards import APRILGRID_BORDER_BITS

    params.markerBorderBits = APRILGRID_BORDER_BITS
    return aruco.ArucoDetector(d, params)


def _detector(board: BoardSpec):
    return _aruco(board.kind, board.cols, board.rows, board.square, board.marker, board.dictionary,
                  board.legacy_pattern)


OUTLIER_PX = 1.0
OUTLIER_FACTOR = 5.0
"""An identified corner whose reprojection residual exceeds both ``OUTLIER_PX`` and ``OUTLIER_FACTOR`` times the
corners' median residual is dropped and the pose fitted again (a refinement that settled on the wrong junction; a
checkerboard's corners stand or fall together)."""


def _inliers(T: np.ndarray, obj: np.ndarray, corners: np.ndarray, camera: CameraModel) -> np.ndarray:
    """Which corners reproject within the ``OUTLIER_PX`` / ``OUTLIER_FACTOR`` bound through pose ``T``."""
    import cv2

    X = obj @ T[:3, :3].T + T[:3, 3]
    if camera.lens is not None:
        proj = camera.lens.project(X)
    else:
        proj = cv2.projectPoints(X, np.zeros(3), np.zeros(3), camera.K, camera.dist)[0].reshape(-1, 2)
    r = np.linalg.norm(proj - corners, axis=1)
    return ~((r > OUTLIER_PX) & (r > OUTLIER_FACTOR * np.median(r)))


def find_identified(gray: np.ndarray, board: BoardSpec) -> tuple[np.ndarray, np.ndarray]:
    """(ids (N,), pixels (N,2)) of the identified corners of a ChArUco board or an AprilGrid in ``gray``: rows of
    ``board.corners``, sorted. ChArUco: ``CharucoDetector.detectBoard``, its corners refined again
    (``refine_charuco``); AprilGrid: ``ArucoDetector.detectMarkers`` (tags of other ids ignored), each tag corner
    then refined by ``cv2.cornerSubPix`` at its junction (``refine_junctions``). Empty arrays when none."""
    if board.kind == "charuco":
        cc, ci, _, _ = _detector(board).detectBoard(gray)
        if ci is None or len(ci) == 0:
            return np.zeros(0, int), np.zeros((0, 2))
        ids, px = ci.ravel().astype(int), cc.reshape(-1, 2).astype(float)
        px = refine_charuco(gray, px, board)
    else:
        mc, mi, _ = _detector(board).detectMarkers(gray)
        if mi is None or len(mi) == 0:
            return np.zeros(0, int), np.zeros((0, 2))
        keep = [k for k, t in enumerate(mi.ravel()) if 0 <= t < board.cols * board.rows]
        if not keep:
            return np.zeros(0, int), np.zeros((0, 2))
        tags = mi.ravel()[keep].astype(int)
        quads = np.stack([np.asarray(mc[k], float).reshape(4, 2) for k in keep])
        ids = (4 * tags[:, None] + np.arange(4)).ravel()
        px = refine_junctions(gray, quads, board).reshape(-1, 2)
    order = np.argsort(ids, kind="stable")
    return ids[order], px[order]


CHARUCO_WINDOW_SHARE = 0.8
"""cv2.cornerSubPix's half window at a ChArUco corner: this share of the white margin between the corner and the
markers beside it (``(square_m - marker_m) / 2``, in pixels from the corner spacing), at most
``SUBPIX_HALF_WINDOW_PX``; no refinement below 2 px."""


def refine_charuco(gray: np.ndarray, px: np.ndarray, board: BoardSpec) -> np.ndarray:
    """ChArUco corners ``px`` (N,2) as ``CharucoDetector`` gives them, refined by ``cv2.cornerSubPix`` within the
    white margin around each (``CHARUCO_WINDOW_SHARE``). OpenCV 4.8.1's detector puts every corner about half a
    pixel off along both axes; OpenCV 5's does not; refined, both agree with the rendered truth (docs/dataset.md)."""
    import cv2

    if len(px) < 2:
        return px
    d = np.linalg.norm(px[:, None] - px[None], axis=2)
    np.fill_diagonal(d, np.inf)
    side = d.min(axis=1)          # at least a square's side in pixels (corners beside it may be missing)
    margin = side * (board.square - board.marker) / (2 * board.square)
    w = np.minimum(np.floor(CHARUCO_WINDOW_SHARE * margin), SUBPIX_HALF_WINDOW_PX).astype(int)
    out = px.astype(np.float32).copy()
    for wi in np.unique(w[w >= 2]):
        sel = w == wi
        c = out[sel].reshape(-1, 1, 2)
        out[sel] = cv2.cornerSubPix(gray, c.copy(), (int(wi), int(wi)), (-1, -1), SUBPIX_CRITERIA).reshape(-1, 2)
    moved = np.linalg.norm(out - px, axis=1) > np.maximum(w, 1)
    return np.where(moved[:, None], px, out).astype(float)


JUNCTION_WINDOWS = ((0.2, 5), (0.12, 3))
"""The two passes of cv2.cornerSubPix at an AprilGrid tag corner: half window as a share of the tag's side in the
image, at most the given pixels (at least 2). The first reaches the junction from the tag detector's corner (pixels
off) within the tag's 2-bit border (a fifth of its side); the second settles there with a window that stays clear
of the tag's code bits and of the gap's far side (measured: docs/dataset.md)."""


def refine_junctions(gray: np.ndarray, quads: np.ndarray, board: BoardSpec) -> np.ndarray:
    """AprilGrid tag corners ``quads`` (T,4,2 pixels, as the tag detector gives them) refined by ``cv2.cornerSubPix``
    where the tag meets its corner square (an X junction like a checkerboard's), in the passes of
    ``JUNCTION_WINDOWS``: the tag detector's own corners there sit pixels off. A corner the refinement moves by more
    than its first window and 2 px is kept as detected."""
    import cv2

    side = np.linalg.norm(quads - np.roll(quads, 1, axis=1), axis=2).mean(axis=1)
    out = quads.astype(np.float32).copy()
    limit = np.zeros(len(quads))
    for k, (share, most) in enumerate(JUNCTION_WINDOWS):
        w = np.clip(np.floor(share * side), 2, most).astype(int)
        if k == 0:
            limit = w + 2.0
        for wi in np.unique(w):
            sel = w == wi
            c = out[sel].reshape(-1, 1, 2)
            out[sel] = cv2.cornerSubPix(gray, c.copy(), (int(wi), int(wi)), (-1, -1), SUBPIX_CRITERIA).reshape(-1, 4, 2)
    moved = np.linalg.norm(out - quads, axis=2) > limit[:, None]
    return np.where(moved[..., None], quads, out).astype(float)
