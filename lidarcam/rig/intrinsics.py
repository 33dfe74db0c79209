"""Camera intrinsics from the calibration images themselves (``cv2.calibrateCameraExtended``; for an equidistant
camera ``cv2.fisheye.calibrate``; the other models are not refitted, ``REFIT_MODELS``).

Used when a rig's intrinsics are missing or rough: the same checkerboard views that calibrate the extrinsic
calibrate the camera. The result carries the reprojection RMS and the standard deviation of every intrinsic
parameter (OpenCV's ``stdDeviationsIntrinsics``: fx, fy, cx, cy, k1, k2, p1, p2, k3, ...), so a report can say
how well each is determined.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from .dataset import BoardSpec, CameraModel, Dataset, DatasetError
from .dataset.camera_files import lens_camera
from .detect import find_chessboard
from .markdown import md_table

PARAM_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3")
MIN_VIEWS = 3


@dataclass(frozen=True, eq=False)
class IntrinsicsFit:
    """``camera`` (the fitted model), ``rms_px`` (reprojection RMS over all corners), ``sigma`` (parameter name ->
    1-sigma, pixels for fx fy cx cy, unitless for distortion), ``per_view_px`` (RMS per used view), ``views``
    (names of the views used), ``skipped`` (name -> reason)."""

    camera: CameraModel
    rms_px: float
    sigma: dict
    per_view_px: dict
    views: tuple[str, ...]
    skipped: dict = field(default_factory=dict)


def find_corners(gray: np.ndarray, board: BoardSpec) -> np.ndarray | None:
    """(cols*rows, 2) pixel corners of the board in ``gray`` (``lidarcam.rig.detect.find_chessboard``), or None."""
    return find_chessboard(gray, board)


def calibrate_intrinsics(images: dict[str, np.ndarray], board: BoardSpec, fix_k3: bool = True,
                         zero_tangent: bool = False, corners: dict[str, np.ndarray] | None = None) -> IntrinsicsFit:
    """Fit K and the distortion (k1 k2 p1 p2 [k3]) to the boards found in ``images`` (name -> 8-bit grayscale).

    ``corners`` (name -> (N,2)) may pass detections made already. Raises DatasetError when fewer than
    ``MIN_VIEWS`` boards are found or the images differ in size.
    """
    import cv2

    sizes = {im.shape[:2] for im in images.values()}
    if len(sizes) != 1:
        raise DatasetError(f"images of different sizes {sorted(sizes)}: cannot fit one camera")
    h, w = sizes.pop()
    obj, img, names, skipped = [], [], [], {}
    for name, gray in images.items():
        c = corners.get(name) if corners else None
        c = find_corners(gray, board) if c is None else np.asarray(c, np.float32)
        if c is None:
            skipped[name] = f"checkerboard with {board.cols}x{board.rows} inner corners not found"
            continue
        obj.append(board.corners.astype(np.float32))
        img.append(c.reshape(-1, 1, 2))
        names.append(name)
    if len(names) < MIN_VIEWS:
        raise DatasetError(f"intrinsics need at least {MIN_VIEWS} detected boards, found {len(names)}")
    flags = (cv2.CALIB_FIX_K3 if fix_k3 else 0) | (cv2.CALIB_ZERO_TANGENT_DIST if zero_tangent else 0)
    rms, K, dist, _, _, std_in, _, per_view = cv2.calibrateCameraExtended(obj, img, (w, h), None, None,
                                                                           flags=flags)
    std = std_in.ravel()
    sigma = {n: float(std[i]) for i, n in enumerate(PARAM_NAMES)}
    if fix_k3:
        sigma["k3"] = 0.0
    dist = np.asarray(dist, float).ravel()[:5]
    cam = CameraModel(int(w), int(h), np.asarray(K, float), dist, np.array([sigma[n] for n in PARAM_NAMES]))
    return IntrinsicsFit(cam, float(rms), sigma, {n: float(e) for n, e in zip(names, per_view.ravel(), strict=True)},
                         tuple(names), skipped)


REFIT_MODELS = {"pinhole-radtan": "cv2.calibrateCameraExtended", "pinhole-equidistant": "cv2.fisheye.calibrate"}
"""The camera models ``--refit-intrinsics`` refits, and by what."""
EQUIDISTANT_NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4")


def calibrate_equidistant(corners: dict[str, np.ndarray], board: BoardSpec, start: CameraModel) -> IntrinsicsFit:
    """Fit K and the equidistant coefficients k1..k4 (``cv2.fisheye.calibrate``, from ``start``'s values, no skew)
    to the corners (name -> (N,2) pixels, canonical order as ``board.corners``) of at least ``MIN_VIEWS`` views.
    The 1-sigma of each intrinsic is from the Gauss-Newton covariance of the pixel residuals over the intrinsics
    and every view's pose (``calib_core``'s Jacobians of the model), scaled by the residuals' variance."""
    import cv2

    names = [n for n, c in corners.items() if c is not None and len(c)]
    if len(names) < MIN_VIEWS:
        raise DatasetError(f"intrinsics need at least {MIN_VIEWS} detected boards, found {len(names)}")
    obj = [board.corners.reshape(1, -1, 3).astype(np.float64) for _ in names]
    img = [np.asarray(corners[n], np.float64).reshape(1, -1, 2) for n in names]
    flags = cv2.fisheye.CALIB_USE_INTRINSIC_GUESS | cv2.fisheye.CALIB_RECOMPUTE_EXTRINSIC | cv2.fisheye.CALIB_FIX_SKEW
    d0 = np.r_[np.asarray(start.dist, float), np.zeros(4)][:4].reshape(4, 1)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    try:
        _, K, D, rvecs, tvecs = cv2.fisheye.calibrate(obj, img, (start.width, start.height), start.K.copy(), d0,
                                                      flags=flags, criteria=crit)
    except cv2.error as exc:
        raise DatasetError(f"cv2.fisheye.calibrate failed on {len(names)} boards ({exc.err})") from None
    lens = lens_camera("pinhole", "equidistant", K, np.asarray(D, float).ravel(), start.width, start.height).core()
    res, J_k, J_pose = [], [], []
    for rv, tv, n in zip(rvecs, tvecs, names, strict=True):
        R = cv2.Rodrigues(np.asarray(rv, float))[0]
        RP = board.corners @ R.T
        P = RP + np.asarray(tv, float).ravel()
        uv, Jp = lens.project(P, jacobian=True)
        res.append((uv - np.asarray(corners[n], float)).ravel())
        J_k.append(lens.intrinsics_jacobian(P).reshape(-1, 8))
        sk = np.zeros((len(RP), 3, 3))
        sk[:, 0, 1], sk[:, 0, 2], sk[:, 1, 2] = -RP[:, 2], RP[:, 1], -RP[:, 0]
        sk[:, 1, 0], sk[:, 2, 0], sk[:, 2, 1] = RP[:, 2], -RP[:, 1], RP[:, 0]
        J_pose.append(np.concatenate([Jp @ -sk, Jp], axis=2).reshape(-1, 6))
    r = np.concatenate(res)
    J = np.zeros((len(r), 8 + 6 * len(names)))
    row = 0
    for i, (jk, jp) in enumerate(zip(J_k, J_pose, strict=True)):
        J[row:row + len(jk), :8] = jk
        J[row:row + len(jk), 8 + 6 * i:14 + 6 * i] = jp
        row += len(jk)
    dof = max(len(r) - J.shape[1], 1)
    s2 = float(r @ r) / dof
    cov = np.linalg.pinv(J.T @ J) * s2
    std = np.sqrt(np.clip(np.diag(cov)[:8], 0.0, None))
    per_view = {n: float(np.sqrt(np.mean(e.reshape(-1, 2) ** 2) * 2)) for n, e in zip(names, res, strict=True)}
    cam = lens_camera("pinhole", "equidistant", lens.K, lens.dist, lens.width, lens.height, std=std)
    return IntrinsicsFit(cam, float(np.sqrt(np.mean(r.reshape(-1, 2) ** 2) * 2)),
                         dict(zip(EQUIDISTANT_NAMES, std.tolist(), strict=True)), per_view, tuple(names))


def format_intrinsics(fit: IntrinsicsFit) -> list[str]:
    """Markdown lines: the fitted parameters with their 1-sigma, the RMS and the views used."""
    K, d = fit.camera.K, fit.camera.dist
    names = PARAM_NAMES if fit.camera.is_opencv_pinhole else EQUIDISTANT_NAMES
    vals = dict(zip(names, [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *d], strict=False))
    rows = [[n, f"{vals[n]:.4f}", f"{fit.sigma.get(n, math.nan):.4f}"] for n in names if n in vals]
    how = REFIT_MODELS.get(fit.camera.name, "")
    return [f"`{how}` on {len(fit.views)} detected boards: reprojection RMS "
            f"{fit.rms_px:.3f} px (per view {min(fit.per_view_px.values()):.3f}-{max(fit.per_view_px.values()):.3f}"
            " px).", ""] + md_table(["parameter", "value", "1-sigma"], rows, "lrr")


def with_corners(dataset: Dataset) -> tuple[Dataset, dict[str, np.ndarray | None]]:
    """The dataset with every pose's detector corners found once (``Pose.corners``; an empty array where the board
    was not found, so extraction does not search again), and pose name -> corners (None: not found)."""
    poses, corners = [], {}
    for p in dataset.poses:
        c = None if p.error else find_corners(p.read_image(), dataset.board)
        corners[p.name] = c
        poses.append(replace(p, corners=np.zeros((0, 2)) if c is None else c))
    return replace(dataset, poses=tuple(poses)), corners


def refit_camera(dataset: Dataset) -> tuple[Dataset, IntrinsicsFit]:
    """The dataset with its camera refitted from its own images (``calibrate_intrinsics`` on every detected board;
    the corners found are kept on the poses) and the fit."""
    if dataset.camera.name not in REFIT_MODELS:
        raise DatasetError(f"--refit-intrinsics refits {' and '.join(REFIT_MODELS)} cameras, not "
                           f"{dataset.camera.name}: give the camera's intrinsics in camera.yaml (a Kalibr camchain)",
                           file=dataset.root / "camera.yaml")
    ds, corners = with_corners(dataset)
    found = {k: v for k, v in corners.items() if v is not None}
    if not dataset.camera.is_opencv_pinhole:
        fit = calibrate_equidistant(found, ds.board, dataset.camera)
        return replace(ds, camera=fit.camera), fit
    fit = calibrate_intrinsics({p.name: p.read_image() for p in ds.poses if p.name in found}, ds.board,
                               corners=found)
    return replace(ds, camera=fit.camera), fit
