"""Bouguet's Camera Calibration Toolbox for MATLAB: ``Calib_Results.mat`` (read with ``scipy.io.loadmat``).

Intrinsics ``fc`` (2), ``cc`` (2), ``alpha_c`` (skew, in units of fc[0]), ``kc`` (5: k1 k2 p1 p2 k3, OpenCV's order),
``nx`` / ``ny`` (image size); standard errors ``fc_error``, ``cc_error``, ``kc_error`` when present. Per image
k = 1..n_ima: ``Rc_k`` (3x3) and ``Tc_k`` (3, **mm**) with ``X_cam = Rc_k X_board + Tc_k``, detected corners ``x_k``
(2xN, pixels, 0-based like OpenCV) and the board grid ``X_k`` (3xN, mm, z = 0). An image the toolbox marked
inactive (``active_images``) or whose ``Rc_k`` is NaN is left out. Everything is returned in metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..dataset import CameraModel, DatasetError


@dataclass(frozen=True, eq=False)
class BouguetView:
    """One calibration image: ``index`` k (1-based), ``T_cam_board`` (4x4, metres), ``corners_px`` (N,2),
    ``grid_m`` (N,3) board-frame corners in metres."""

    index: int
    T_cam_board: np.ndarray
    corners_px: np.ndarray
    grid_m: np.ndarray


@dataclass(frozen=True, eq=False)
class BouguetCalibration:
    """A ``Calib_Results.mat``: ``camera``, ``views`` (active images in order), ``square_m`` (dX, when stored),
    ``sigma`` (the toolbox's errors by name: fc, cc, kc, alpha_c, in pixels / unitless, three standard deviations
    each: ``BOUGUET_ERROR_SIGMAS``), ``err_std_px``; ``camera.std_intrinsics`` holds the 1-sigma."""

    camera: CameraModel
    views: tuple[BouguetView, ...]
    square_m: float | None = None
    sigma: dict = field(default_factory=dict)
    err_std_px: np.ndarray | None = None


def _get(mat: dict, key: str, path: Path, size: int | None = None, required: bool = True):
    if key not in mat:
        if required:
            raise DatasetError(f"field {key}: missing", file=path)
        return None
    try:
        a = np.asarray(mat[key], dtype=float).ravel()
    except (TypeError, ValueError):
        raise DatasetError(f"field {key}: not numeric", file=path) from None
    if size is not None and a.size != size:
        raise DatasetError(f"field {key}: expected {size} numbers, got {a.size}", file=path)
    return a


def _view(mat: dict, k: int, path: Path) -> BouguetView | None:
    R = _get(mat, f"Rc_{k}", path, 9)
    T = _get(mat, f"Tc_{k}", path, 3)
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(T))):
        return None
    R = R.reshape(3, 3)
    if abs(np.linalg.det(R) - 1) > 1e-3 or np.abs(R.T @ R - np.eye(3)).max() > 1e-3:
        raise DatasetError(f"field Rc_{k}: not a rotation matrix", file=path)
    x = np.asarray(mat.get(f"x_{k}", np.zeros((2, 0))), float)
    X = np.asarray(mat.get(f"X_{k}", np.zeros((3, 0))), float)
    if x.shape[0] != 2 or X.shape[0] != 3 or x.shape[1] != X.shape[1]:
        raise DatasetError(f"fields x_{k} / X_{k}: expected 2xN and 3xN, got {x.shape} and {X.shape}", file=path)
    Tm = np.eye(4)
    Tm[:3, :3], Tm[:3, 3] = R, T / 1000.0
    return BouguetView(k, Tm, x.T.copy(), X.T / 1000.0)


def read_bouguet(path) -> BouguetCalibration:
    """Read a Bouguet ``Calib_Results.mat``; DatasetError naming the file and field when one is missing or bad."""
    from scipy.io import loadmat
    from scipy.io.matlab import MatReadError

    path = Path(path)
    try:
        mat = loadmat(str(path))
    except (OSError, ValueError, TypeError, NotImplementedError, MatReadError) as exc:
        raise DatasetError(f"not a readable MATLAB file ({exc})", file=path) from None
    fc, cc = _get(mat, "fc", path, 2), _get(mat, "cc", path, 2)
    alpha = _get(mat, "alpha_c", path, 1, required=False)
    kc = _get(mat, "kc", path)
    if kc.size not in (4, 5):
        raise DatasetError(f"field kc: expected 4 or 5 coefficients, got {kc.size}", file=path)
    w, h = int(_get(mat, "nx", path, 1)[0]), int(_get(mat, "ny", path, 1)[0])
    a = 0.0 if alpha is None else float(alpha[0])
    K = np.array([[fc[0], a * fc[0], cc[0]], [0.0, fc[1], cc[1]], [0.0, 0.0, 1.0]])
    n = int(_get(mat, "n_ima", path, 1)[0])
    active = _get(mat, "active_images", path, required=False)
    views = []
    for k in range(1, n + 1):
        if active is not None and k <= active.size and not active[k - 1]:
            continue
        v = _view(mat, k, path)
        if v is not None:
            views.append(v)
    sigma = {key: _get(mat, f"{key}_error", path, required=False) for key in ("fc", "cc", "kc", "alpha_c")}
    dX = _get(mat, "dX", path, 1, required=False)
    return BouguetCalibration(CameraModel(w, h, K, kc.copy(), bouguet_std(sigma, kc.size, path)), tuple(views),
                              None if dX is None else float(dX[0]) / 1000.0,
                              {k: v for k, v in sigma.items() if v is not None},
                              _get(mat, "err_std", path, required=False))


BOUGUET_ERROR_SIGMAS = 3.0
"""Bouguet's ``fc_error``, ``cc_error``, ``kc_error`` are three standard deviations, not one: the toolbox computes
them in ``go_calib_optim_iter.m`` as ``param_error = 3*sqrt(full(diag(JJ2_inv)))*sigma_x`` and its documentation
("Camera Calibration Toolbox for Matlab", first calibration example) says "the numerical errors are approximately
three times the standard deviations". Divide by this for a 1-sigma."""


def bouguet_std(sigma: dict, n_kc: int, path) -> np.ndarray | None:
    """The 1-sigma of fx, fy, cx, cy, k1.. (``CameraModel.std_intrinsics``) from a calibration's errors ``sigma``
    (``fc``, ``cc``, ``kc``: three standard deviations each, ``BOUGUET_ERROR_SIGMAS``); None when ``fc`` or ``cc``
    is missing. ``alpha_c``'s error is ignored (the OpenCV model has no skew); without ``kc_error`` the distortion
    is taken as exact. DatasetError naming the file and field when one is malformed."""
    if sigma.get("fc") is None or sigma.get("cc") is None:
        return None
    parts = [("fc", sigma["fc"], 2), ("cc", sigma["cc"], 2)]
    if sigma.get("kc") is not None:
        parts.append(("kc", sigma["kc"], n_kc))
    out = []
    for name, v, n in parts:
        v = np.asarray(v, float).ravel()
        if v.size != n or not np.all(np.isfinite(v)) or np.any(v < 0):
            raise DatasetError(f"field {name}_error: expected {n} finite non-negative values, got {v.tolist()}",
                               file=path)
        out.append(v)
    return np.concatenate(out) / BOUGUET_ERROR_SIGMAS


def grid_outline(grid_m: np.ndarray, square_m: float) -> np.ndarray:
    """The printed pattern's outline (4,2) in the board frame: one square beyond the extreme inner corners. Use it
    when the physical board's outline is not known (the board may be larger)."""
    lo, hi = grid_m[:, :2].min(axis=0) - square_m, grid_m[:, :2].max(axis=0) + square_m
    return np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
