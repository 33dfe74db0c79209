"""Camera intrinsics from the calibration images themselves (``cv2.calibrateCameraExtended``; for an equidistant
camera ``cv2.fisheye.calibrate``; for omni, ds and eucm cameras the project's least squares, ``REFIT_MODELS``).

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


REFIT_MODELS = {"pinhole-radtan": "cv2.calibrateCameraExtended", "pinhole-equidistant": "cv2.fisheye.calibrate",
                "omni-radtan": "least squares (scipy)", "ds": "least squares (scipy)", "eucm": "least squares (scipy)"}
"""The camera models ``--refit-intrinsics`` refits, and by what."""
LENS_DIST_FITTED = {"pinhole-equidistant": 4, "omni-radtan": 4, "ds": 0, "eucm": 0}
"""Distortion coefficients refitted per model (Kalibr's: k1..k4; omni's radtan k1, k2, p1, p2)."""
PARAM_BOUNDS = {"ds": {"xi": (-1 + 1e-6, np.inf), "alpha": (0.0, 1 - 1e-6)}, "omni-radtan": {"xi": (0.0, np.inf)},
                "eucm": {"alpha": (0.0, 1 - 1e-6), "beta": (1e-6, np.inf)}}
"""Each model's domain of its own parameters (``calib_core.data.cameras``' checks), the least squares' bounds."""


def _skew_rows(v: np.ndarray) -> np.ndarray:
    """(N,3,3) cross-product matrices of the rows of ``v`` (N,3)."""
    s = np.zeros((len(v), 3, 3))
    s[:, 0, 1], s[:, 0, 2], s[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    s[:, 1, 0], s[:, 2, 0], s[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return s


def _view(board: BoardSpec, c) -> tuple[np.ndarray, np.ndarray]:
    """(board points (N,3) m, pixels (N,2)) of one view's corners ``c``: the whole grid in ``board.corners``' order
    (N,2), or pixels with each corner's identity, an index of ``board.corners`` (N,3)."""
    c = np.asarray(c, float)
    if c.shape[1] == 3:
        return board.corners[c[:, 2].astype(int)], c[:, :2]
    return board.corners, c


def _residuals(lens, board: BoardSpec, uv: dict, poses: dict, n_fit: int, jacobian: bool = True):
    """Pixel residuals (stacked per view, ``poses``' order) of the board's corners through ``lens`` at ``poses``
    (name -> (R, t) of ``T_cam_board``), and their Jacobian in the first ``n_fit`` intrinsics and each view's
    pose (left rotation increment, then translation; 6 columns per view)."""
    res, rows = [], []
    for n, (R, t) in poses.items():
        X, px = _view(board, uv[n])
        RP = X @ R.T
        P = RP + t
        with np.errstate(all="ignore"):
            if jacobian:
                pred, Jp = lens.project(P, jacobian=True)
                rows.append((lens.intrinsics_jacobian(P).reshape(-1, lens.intrinsics.size)[:, :n_fit],
                             np.concatenate([Jp @ -_skew_rows(RP), Jp], axis=2).reshape(-1, 6)))
            else:
                pred = lens.project(P)
        e = (pred - px).ravel()
        res.append(np.where(np.isfinite(e) & lens.valid(P).repeat(2), e, 1e3))
    r = np.concatenate(res)
    if not jacobian:
        return r, None
    J = np.zeros((len(r), n_fit + 6 * len(poses)))
    row = 0
    for i, (jk, jp) in enumerate(rows):
        J[row:row + len(jk), :n_fit] = np.nan_to_num(jk)
        J[row:row + len(jk), n_fit + 6 * i:n_fit + 6 * i + 6] = np.nan_to_num(jp)
        row += len(jk)
    return r, J


def _fit(lens, board: BoardSpec, uv: dict, poses: dict, n_fit: int, name: str) -> IntrinsicsFit:
    """The IntrinsicsFit of ``lens`` at ``poses``: 1-sigma of its first ``n_fit`` intrinsics from the Gauss-Newton
    covariance of the pixel residuals over them and every view's pose, scaled by the residuals' variance."""
    r, J = _residuals(lens, board, uv, poses, n_fit)
    s2 = float(r @ r) / max(len(r) - J.shape[1], 1)
    std = np.sqrt(np.clip(np.diag(np.linalg.pinv(J.T @ J))[:n_fit] * s2, 0.0, None))
    n_dist = LENS_DIST_FITTED[name]
    cam = lens_camera(lens.camera_model, lens.distortion_model, lens.K, lens.dist[:n_dist], lens.width,
                      lens.height, tuple(lens.params), std=std)
    ends = np.cumsum([2 * len(_view(board, uv[n])[1]) for n in poses])
    per_view = {n: float(np.sqrt(np.mean(e ** 2) * 2)) for n, e in zip(poses, np.split(r, ends[:-1]), strict=True)}
    return IntrinsicsFit(cam, float(np.sqrt(np.mean(r ** 2) * 2)),
                         dict(zip(lens.intrinsic_names[:n_fit], std.tolist(), strict=True)), per_view, tuple(poses))


def _views(corners: dict[str, np.ndarray]) -> list[str]:
    names = [n for n, c in corners.items() if c is not None and len(c)]
    if len(names) < MIN_VIEWS:
        raise DatasetError(f"intrinsics need at least {MIN_VIEWS} detected boards, found {len(names)}")
    return names


def calibrate_equidistant(corners: dict[str, np.ndarray], board: BoardSpec, start: CameraModel) -> IntrinsicsFit:
    """Fit K and the equidistant coefficients k1..k4 (``cv2.fisheye.calibrate``, from ``start``'s values, no skew)
    to the corners (name -> (N,2) pixels in ``board.corners``' order, or (N,3) pixels and each corner's index of
    ``board.corners``) of at least ``MIN_VIEWS`` views. The 1-sigma of each intrinsic is from the Gauss-Newton
    covariance of the pixel residuals over the intrinsics and every view's pose (``calib_core``'s Jacobians of the
    model), scaled by the residuals' variance."""
    import cv2

    names = _views(corners)
    views = [_view(board, corners[n]) for n in names]
    obj = [X.reshape(1, -1, 3).astype(np.float64) for X, _ in views]
    img = [px.reshape(1, -1, 2).astype(np.float64) for _, px in views]
    flags = cv2.fisheye.CALIB_USE_INTRINSIC_GUESS | cv2.fisheye.CALIB_RECOMPUTE_EXTRINSIC | cv2.fisheye.CALIB_FIX_SKEW
    d0 = np.r_[np.asarray(start.dist, float), np.zeros(4)][:4].reshape(4, 1)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    try:
        _, K, D, rvecs, tvecs = cv2.fisheye.calibrate(obj, img, (start.width, start.height), start.K.copy(), d0,
                                                      flags=flags, criteria=crit)
    except cv2.error as exc:
        raise DatasetError(f"cv2.fisheye.calibrate failed on {len(names)} boards ({exc.err})") from None
    lens = lens_camera("pinhole", "equidistant", K, np.asarray(D, float).ravel(), start.width, start.height).core()
    poses = {n: (cv2.Rodrigues(np.asarray(rv, float))[0], np.asarray(tv, float).ravel())
             for n, rv, tv in zip(names, rvecs, tvecs, strict=True)}
    return _fit(lens, board, corners, poses, 8, lens.name)


def calibrate_lens(corners: dict[str, np.ndarray], board: BoardSpec, start: CameraModel) -> IntrinsicsFit:
    """Fit the intrinsics of an ``omni-radtan``, ``ds`` or ``eucm`` camera (fx, fy, cx, cy, the model's own
    parameters, and omni's k1, k2, p1, p2) and every view's pose to the corners (as ``calibrate_equidistant``'s) of
    at least ``MIN_VIEWS`` views: ``scipy.optimize.least_squares`` (trust region,
    the model's parameters bounded to its domain, ``calib_core``'s analytic Jacobians) from ``start``'s
    intrinsics and each view's pose through them (``calib_core.data.cameras.pose.pose_from_corners``; a view
    without one is skipped). 1-sigma as ``calibrate_equidistant``'s."""
    from scipy.optimize import least_squares

    from calib_core.data.cameras.pose import pose_from_corners
    from calib_core.errors import ObservationError
    from calib_core.geometry.transforms import rotvec_to_matrix

    lens = start.core()
    name = lens.name
    n_fit = lens.n_core + LENS_DIST_FITTED[name]
    poses, skipped = {}, {}
    for n in _views(corners):
        try:
            T = pose_from_corners(lens, *_view(board, corners[n]))
            poses[n] = (T[:3, :3], T[:3, 3])
        except ObservationError as err:
            skipped[n] = f"no pose through the starting {name} camera: {err.message}"
    if len(poses) < MIN_VIEWS:
        raise DatasetError(f"intrinsics need at least {MIN_VIEWS} boards with a pose through the {name} camera, "
                           f"found {len(poses)}")
    bounds = PARAM_BOUNDS.get(name, {})
    lo = np.full(n_fit + 6 * len(poses), -np.inf)
    hi = np.full_like(lo, np.inf)
    lo[:2] = 1e-6
    for k, p in enumerate(lens.param_names):
        lo[4 + k], hi[4 + k] = bounds.get(p, (-np.inf, np.inf))
    for _ in range(2):       # the second pass re-linearises the rotations at the first one's answer
        x0 = np.r_[lens.intrinsics[:n_fit], np.zeros(6 * len(poses))]
        x0[:n_fit] = np.clip(x0[:n_fit], lo[:n_fit] + 1e-12, hi[:n_fit] - 1e-12)
        base = dict(poses)

        def at(x, base=base, cur=lens):
            moved = {n: (rotvec_to_matrix(x[n_fit + 6 * i:n_fit + 6 * i + 3]) @ R,
                         t + x[n_fit + 6 * i + 3:n_fit + 6 * i + 6]) for i, (n, (R, t)) in enumerate(base.items())}
            return cur.with_intrinsics(x[:n_fit]), moved

        def fun(x, at=at):
            return _residuals(*at(x)[:1], board, corners, at(x)[1], n_fit, jacobian=False)[0]

        def jac(x, at=at):
            return _residuals(*at(x)[:1], board, corners, at(x)[1], n_fit)[1]

        x = least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac", xtol=1e-12,
                          ftol=1e-12).x
        lens, poses = at(x)
    fit = _fit(lens, board, corners, poses, n_fit, name)
    return IntrinsicsFit(fit.camera, fit.rms_px, fit.sigma, fit.per_view_px, fit.views, skipped)


def format_intrinsics(fit: IntrinsicsFit) -> list[str]:
    """Markdown lines: the fitted parameters with their 1-sigma, the RMS and the views used."""
    if fit.camera.is_opencv_pinhole:
        K, d = fit.camera.K, fit.camera.dist
        names = PARAM_NAMES
        vals = dict(zip(names, [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *d], strict=False))
    else:
        lens = fit.camera.core()
        names = tuple(fit.sigma)
        vals = dict(zip(lens.intrinsic_names, lens.intrinsics, strict=True))
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
        raise DatasetError(f"--refit-intrinsics refits {', '.join(REFIT_MODELS)} cameras, not "
                           f"{dataset.camera.name}: give the camera's intrinsics in camera.yaml (a Kalibr camchain)",
                           file=dataset.root / "camera.yaml")
    ds, corners = with_corners(dataset)
    found = {k: v for k, v in corners.items() if v is not None}
    if not dataset.camera.is_opencv_pinhole:
        refit = calibrate_equidistant if dataset.camera.name == "pinhole-equidistant" else calibrate_lens
        fit = refit(found, ds.board, dataset.camera)
        return replace(ds, camera=fit.camera), fit
    fit = calibrate_intrinsics({p.name: p.read_image() for p in ds.poses if p.name in found}, ds.board,
                               corners=found)
    return replace(ds, camera=fit.camera), fit
