"""Camera side of the extraction: the checkerboard in one image and its pose ``T_cam_board`` (metres).

``cv2.findChessboardCornersSB`` -> corner order made canonical (right-handed board frame, origin square colour from
board.yaml) -> undistorted corners -> ``cv2.solvePnP(SOLVEPNP_IPPE)`` + ``cv2.solvePnPRefineLM`` -> reprojection RMS
(pixels, with distortion)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calib_core.geometry.transforms import make_T

from .dataset import BoardSpec, CameraModel
from .extract_options import ExtractionError

UNDISTORT_CRITERIA = (3, 50, 1e-10)  # cv2.TERM_CRITERIA_COUNT | EPS: OpenCV's default of 5 iterations is too few


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


def find_chessboard(gray: np.ndarray, board: BoardSpec, flags: int | None = None) -> np.ndarray | None:
    """(cols*rows, 2) pixel corners of the board in ``gray``, or None: ``cv2.findChessboardCornersSB`` (``flags``;
    default normalise + exhaustive + accuracy), else the classic ``cv2.findChessboardCorners`` refined by
    ``cv2.cornerSubPix`` (it finds some strongly lit or tilted boards the sector detector misses)."""
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
        corners = cv2.cornerSubPix(gray, corners.astype(np.float32), (5, 5), (-1, -1), SUBPIX_CRITERIA)
    return corners.reshape(-1, 2).astype(np.float32)


SUBPIX_CRITERIA = (3, 50, 1e-3)
"""cv2.cornerSubPix stop rule (TERM_CRITERIA_COUNT | EPS, 50 iterations, 1e-3 px)."""


def detect_board(gray: np.ndarray, camera: CameraModel, board: BoardSpec, flags: int | None = None,
                 corners: np.ndarray | None = None) -> BoardDetection:
    """Find the checkerboard in ``gray`` and its pose ``T_cam_board``; raises ExtractionError when not found.
    ``corners`` (N,2): the detector's corners found already (e.g. for the intrinsics), to skip the detection; an
    empty array means the detector already found no board.

    The detector's corner order is made canonical: the board frame is right-handed with z pointing away from the
    camera (a mirrored order is reversed along rows) and, when ``cols + rows`` is odd and board.yaml states the
    origin square's colour (light when board.yaml does not say: the order ``findChessboardCornersSB`` gives; the
    classic detector's fallback may start at the other end), a 180-degree reversal is undone.
    """
    if corners is None:
        corners = find_chessboard(gray, board, flags)
    if corners is None or len(corners) == 0:
        raise ExtractionError(f"checkerboard with {board.cols}x{board.rows} inner corners not found in the image")
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
