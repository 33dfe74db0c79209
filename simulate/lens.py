"""The simulated camera's lens: one of the camera models of ``calib_core.data.cameras`` (``cam_model``, Kalibr's
names) with its parameters (``cam_params``), on ``camera_matrix``'s K. The default, ``pinhole-radtan`` with no
parameters, is the distortion-free pinhole the simulator always had, and goes down the same code paths.

``cam_params`` lists numbers separated by commas: the model's own parameters (``param_names``: ``xi`` for
``omni-radtan``, ``xi, alpha`` for ``ds``, ``alpha, beta`` for ``eucm``) then its distortion coefficients
(``k1, k2, k3, k4`` for ``pinhole-equidistant``; OpenCV's order for the ``radtan`` models). Frames and units:
camera ``{C}`` (z optical axis, y down), metres, pixels.
"""

from __future__ import annotations

import numpy as np

from calib_core.data.cameras import MODEL_NAMES, camera_class
from calib_core.data.cameras.pose import pose_from_corners as model_pose
from calib_core.errors import ObservationError

from .camera import CameraError, camera_matrix

DEFAULT_MODEL = "pinhole-radtan"

LENSES = {
    "pinhole": {"cam_model": DEFAULT_MODEL, "cam_params": ""},
    "fisheye150": {"cam_model": "pinhole-equidistant", "cam_params": "-0.01,0.02,-0.01,0.002", "focal_px": 388.0,
                   "cam_width": 1024, "cam_height": 768},
    "ds180": {"cam_model": "ds", "cam_params": "-0.2,0.6", "focal_px": 340.0, "cam_width": 1280,
              "cam_height": 1024},
}
"""Lens presets (SimOptions camera fields): ``fisheye150`` an equidistant (Kannala-Brandt) lens seeing 150 deg across
the image's width (1024 x 768); ``ds180`` a double-sphere lens seeing 180 deg across its width (1280 x 1024, the
image circle's edge at about 120 deg from the axis)."""


def is_default(options) -> bool:
    """True for the simulator's plain pinhole (``cam_model`` ``pinhole-radtan`` without parameters)."""
    return options.cam_model == DEFAULT_MODEL and not options.cam_params.strip()


def lens_numbers(text: str) -> list[float]:
    """The numbers of ``cam_params``; ValueError naming the option on anything else."""
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"SimOptions: cam_params must be numbers separated by commas, got {text!r}") from None


def true_camera(options, K: np.ndarray | None = None):
    """The simulated camera (a ``calib_core.data.cameras`` model): ``cam_model`` with ``cam_params`` on ``K``
    (default ``camera_matrix(focal_px, cam_width, cam_height)``). ValueError naming the option when the model or its
    parameters are not valid."""
    o = options
    if o.cam_model not in MODEL_NAMES:
        raise ValueError(f"SimOptions: cam_model must be one of {sorted(MODEL_NAMES)}, got {o.cam_model!r}")
    cls = camera_class(o.cam_model)
    nums = lens_numbers(o.cam_params)
    n = len(cls.param_names)
    if len(nums) < n:
        raise ValueError(f"SimOptions: cam_params: the {o.cam_model} model needs {', '.join(cls.param_names)} first, "
                         f"got {len(nums)} numbers")
    K = camera_matrix(o.focal_px, o.cam_width, o.cam_height) if K is None else K
    try:
        return cls(K, nums[n:], o.cam_width, o.cam_height, **dict(zip(cls.param_names, nums[:n], strict=True)))
    except ObservationError as exc:
        raise ValueError(f"SimOptions: cam_params: {exc}") from None


def in_view(camera, P_cam: np.ndarray, margin_px: float, min_range_m: float) -> np.ndarray:
    """Which point sets (...,M,3) (camera frame, metres) the lens sees whole: every point valid for the model, at
    least ``min_range_m`` away and projected at least ``margin_px`` inside the image. (...,) bool."""
    P = np.asarray(P_cam, float)
    ok = camera.valid(P) & (np.linalg.norm(P, axis=-1) >= min_range_m)
    with np.errstate(all="ignore"):
        uv = camera.project(P)
    inside = ((uv[..., 0] >= margin_px) & (uv[..., 0] <= camera.width - 1 - margin_px)
              & (uv[..., 1] >= margin_px) & (uv[..., 1] <= camera.height - 1 - margin_px))
    return np.all(ok & inside, axis=-1)


def edge_points(outline: np.ndarray, per_edge: int = 16) -> np.ndarray:
    """Points (4 per_edge, 3) along the closed polygon ``outline`` (M,2) on the board plane z = 0, metres."""
    t = np.arange(per_edge) / per_edge
    a, b = outline, np.roll(outline, -1, axis=0)
    xy = (a[:, None] + t[None, :, None] * (b - a)[:, None]).reshape(-1, 2)
    return np.column_stack([xy, np.zeros(len(xy))])


def lens_corners(camera, T_cam_board: np.ndarray, P_board: np.ndarray, noise_px: float,
                 rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """``pixel`` mode through the lens: the corners ``P_board`` (N,3) projected at ``T_cam_board`` plus
    N(0, ``noise_px``) per coordinate, and the pose fitted to them through the model
    (``calib_core.data.cameras.pose``). CameraError when a corner is outside the model or the fit fails."""
    X = P_board @ T_cam_board[:3, :3].T + T_cam_board[:3, 3]
    if not camera.valid(X).all():
        raise CameraError(f"a corner lies outside the {camera.name} lens's field of view")
    uv = camera.project(X) + rng.normal(0.0, noise_px, (len(P_board), 2))
    return pose_of(camera, P_board, uv), uv


def pose_of(camera, P_board: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """The board pose fitted to corners ``uv`` through ``camera``; CameraError when it cannot be."""
    try:
        return model_pose(camera, P_board, uv)
    except ObservationError as exc:
        raise CameraError(f"board pose through the {camera.name} lens: {exc}") from None
