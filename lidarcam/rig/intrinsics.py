"""Camera intrinsics from the calibration images themselves (``cv2.calibrateCameraExtended``).

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
from .detect import check_spread, find_chessboard, find_identified
from .extract_options import ExtractionError
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
    """The board's corners in ``gray``, or None: a checkerboard's (cols*rows, 2) pixels
    (``lidarcam.rig.detect.find_chessboard``); an identified board's (N,3) pixels and identity
    (``lidarcam.rig.detect.find_identified``, when they pass ``check_spread``)."""
    if not board.identified:
        return find_chessboard(gray, board)
    ids, px = find_identified(gray, board)
    try:
        check_spread(board, ids)
    except ExtractionError:
        return None
    return np.column_stack([px, ids])


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
            skipped[name] = f"{board.describe()} not found"
            continue
        grid = board.corners[c[:, 2].astype(int)] if board.identified else board.corners
        obj.append(grid.astype(np.float32))
        img.append(np.ascontiguousarray(c[:, :2] if board.identified else c, np.float32).reshape(-1, 1, 2))
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


def format_intrinsics(fit: IntrinsicsFit) -> list[str]:
    """Markdown lines: the fitted parameters with their 1-sigma, the RMS and the views used."""
    K, d = fit.camera.K, fit.camera.dist
    vals = dict(zip(PARAM_NAMES, [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *d], strict=False))
    rows = [[n, f"{vals[n]:.4f}", f"{fit.sigma.get(n, math.nan):.4f}"] for n in PARAM_NAMES if n in vals]
    return [f"`cv2.calibrateCameraExtended` on {len(fit.views)} detected boards: reprojection RMS "
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
    if dataset.camera.lens is not None:
        raise DatasetError(f"--refit-intrinsics refits the OpenCV pinhole; camera.yaml names the "
                           f"{dataset.camera.lens.name} model", file=dataset.root / "camera.yaml")
    ds, corners = with_corners(dataset)
    found = {k: v for k, v in corners.items() if v is not None}
    fit = calibrate_intrinsics({p.name: p.read_image() for p in ds.poses if p.name in found}, ds.board,
                               corners=found)
    return replace(ds, camera=fit.camera), fit
