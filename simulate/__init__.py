"""The benchmark's problem generator: simulated 2D-lidar + camera board views with their ground truth.

``generate(options, seed, trial)`` draws one problem (``calib_core.Observations``) following docs/METHOD.md's
simulation protocol; every assumption is a field of ``SimOptions``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from calib_core.data.camera import Camera
from calib_core.data.observations import BoardObservation, Observations
from calib_core.geometry.transforms import invert_T

from .camera import (
    BoardSpec,
    CameraError,
    camera_matrix,
    checkerboard_corners,
    observe_board,
    pose_from_corners,
    render_board_image,
)
from .lens import is_default, lens_corners, pose_of, true_camera
from .lidar import beam_bearings, board_ranges, cast_scan
from .options import SimOptions, contamination_hash, contamination_on, settings_hash
from .outliers import contaminate, contamination_rng
from .rig import draw_margin, erroneous_camera, file_outline, margins_on, physical_outline, rig_rngs
from .scene import Scene, SceneError, sample_scene

GENERATOR = "lidarcam.simulate/1"


def trial_rngs(options: SimOptions, seed: int, trial: int, stream: int | None = None
               ) -> tuple[np.random.Generator, ...]:
    """Independent generators (geometry, lidar noise, camera noise) of one trial.

    Derived from ``SeedSequence(entropy=seed, spawn_key=(settings_hash(options), trial))``: the stream of a
    trial depends only on the base seed, the settings and the trial index, never on process order. With
    ``stream`` (common random numbers) ``stream`` replaces the settings hash, so trial ``t`` draws the same
    random numbers under every setting and differences between settings are not sampling noise.
    """
    ss = np.random.SeedSequence(entropy=int(seed), spawn_key=(trial_key(options, stream), int(trial)))
    return tuple(np.random.default_rng(s) for s in ss.spawn(3))


def trial_key(options: SimOptions, stream: int | None = None) -> int:
    """The first spawn key of a trial's ``SeedSequence``: ``stream`` when given, else ``settings_hash(options)``."""
    return settings_hash(options) if stream is None else int(stream)


def simulate_trial(options: SimOptions, seed: int = 0, trial: int = 0, stream: int | None = None
                   ) -> tuple[Scene, list[np.ndarray], list[np.ndarray], list[np.ndarray | None]]:
    """One trial's truth and measurements: (scene, scans (per board (K_i,2) in the lidar frame, metres,
    ordered by bearing), camera-estimated ``T_cam_board`` per board (4x4), the image corners (J,2) each pose
    came from (None in ``exact`` mode)).

    Boards are separate captures unless ``shared_scan`` (then one scan, nearest hit wins). In ``image``
    mode a board whose checkerboard is not detected is re-drawn (it counts as a failed attempt). ``stream``:
    see ``trial_rngs``.
    """
    o = options
    rng_geo, rng_lidar, rng_cam = trial_rngs(o, seed, trial, stream)
    rng_margin, rng_intrinsics = rig_rngs(o, seed, trial, stream)
    K = camera_matrix(o.focal_px, o.cam_width, o.cam_height)
    spec = BoardSpec.of(o)
    user_cam = erroneous_camera(o, rng_intrinsics) if o.intrinsics_error_on else None
    lens = None if is_default(o) else true_camera(o)
    bearings = beam_bearings(o.lidar_fov_deg, o.lidar_res_deg)
    P = checkerboard_corners(o)
    cam_poses: list[np.ndarray] = []
    corners: list[np.ndarray | None] = []
    margins: list[float] = []

    def observe(T_lidar_cam, T_lidar_board) -> bool:
        if margins_on(o):  # the physical board drawn for this candidate must give the lidar enough points
            m = draw_margin(o, rng_margin)
            hits = np.isfinite(board_ranges(bearings, T_lidar_board[None], physical_outline(o, m))[0]).sum()
            if hits < o.min_points_per_board:
                return False
        try:
            T, uv = _observed(o, K, lens, invert_T(T_lidar_cam) @ T_lidar_board, spec, P, rng_cam)
            if user_cam is not None:  # the user's pose: PnP with the intrinsics they have
                T = pose_from_corners(user_cam.K, P, uv, user_cam.dist) if lens is None else pose_of(user_cam, P, uv)
        except CameraError:
            return False
        cam_poses.append(T)
        corners.append(uv)
        if margins_on(o):
            margins.append(m)
        return True

    scene = sample_scene(o, rng_geo, accept=observe)
    sigma = o.noise_mm / 1000.0
    if o.shared_scan:
        scans = cast_scan(bearings, scene.T_lidar_board, scene.outline, o.lidar_max_range_m, sigma, rng_lidar)
    elif margins_on(o):
        scene = replace(scene, margins_m=np.array(margins))
        scans = [cast_scan(bearings, T[None], physical_outline(o, m), o.lidar_max_range_m, sigma, rng_lidar)[0]
                 for T, m in zip(scene.T_lidar_board, margins, strict=True)]
    else:
        scans = [cast_scan(bearings, T[None], scene.outline, o.lidar_max_range_m, sigma, rng_lidar)[0]
                 for T in scene.T_lidar_board]
    return scene, scans, cam_poses, corners


def _observed(o: SimOptions, K: np.ndarray, lens, T_cam_board: np.ndarray, spec: BoardSpec, P: np.ndarray,
              rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray | None]:
    """``observe_board`` through the plain pinhole, or through the lens ``lens`` (``simulate.lens``) when given."""
    if lens is None:
        return observe_board(K, T_cam_board, spec, o.pose_mode, o.cam_width, o.cam_height, rng, o.pixel_noise_px,
                             o.image_noise_std, o.render_supersample)
    if o.pose_mode == "exact":
        return np.array(T_cam_board, float), None
    if o.pose_mode == "image":
        from .lens_render import image_corners

        uv = image_corners(lens, T_cam_board, spec, rng, o.image_noise_std, o.render_supersample)
        return pose_of(lens, P, uv), uv
    return lens_corners(lens, T_cam_board, P, o.pixel_noise_px, rng)


def file_camera(options: SimOptions, seed: int = 0, trial: int = 0, stream: int | None = None) -> Camera | None:
    """The camera a trial's file states: None in ``exact`` mode, the erroneous one (``simulate.rig``) with an
    intrinsics error, else the true camera (the pinhole without distortion, or the lens ``cam_model``)."""
    o = options
    if o.pose_mode == "exact":
        return None
    if o.intrinsics_error_on:
        return erroneous_camera(o, rig_rngs(o, seed, trial, stream)[1])
    if not is_default(o):
        return true_camera(o)
    return Camera(camera_matrix(o.focal_px, o.cam_width, o.cam_height), [], o.cam_width, o.cam_height)


def generate(options: SimOptions, seed: int = 0, trial: int = 0, stream: int | None = None) -> Observations:
    """One simulated calibration problem with its ground truth ``T_lidar_cam``.

    ``meta``: generator name, the options as a dict, seed, trial, settings hash, and (when the camera poses
    are estimated, ``pose_mode`` pixel or image) the true ``T_cam_board`` per board. In those modes every board
    also carries its image corners (``corners_px``, ``corners_board``) and the observations the camera
    (pinhole, no distortion). ``stream`` (common random numbers, see ``trial_rngs``) is in ``meta`` when given.
    With contamination on (``simulate.outliers``), ``wrong_boards``: the boards whose scan is another object's
    segment.
    """
    o = options
    scene, scans, cam_poses, corners = simulate_trial(o, seed, trial, stream)
    wrong: list[int] = []
    if contamination_on(o):
        scans, wrong = contaminate(scans, o, contamination_rng(seed, contamination_hash(o), trial))
    P = checkerboard_corners(o)
    if scene.margins_m is None:
        outlines = [(scene.outline, "exact")] * len(cam_poses)
    else:
        outlines = [file_outline(o, m) for m in scene.margins_m]
    boards = tuple(BoardObservation(T, ol, s, uv, None if uv is None else P, outline_kind=kind)
                   for T, s, uv, (ol, kind) in zip(cam_poses, scans, corners, outlines, strict=True))
    camera = file_camera(o, seed, trial, stream)
    meta = {"generator": GENERATOR, "options": options.to_dict(), "seed": int(seed), "trial": int(trial),
            "settings_hash": settings_hash(options)}
    if scene.margins_m is not None:
        meta["board_margin_m"] = scene.margins_m.tolist()
    if o.intrinsics_error_on:
        meta["K_true"] = camera_matrix(o.focal_px, o.cam_width, o.cam_height).tolist()
    if stream is not None:
        meta["stream"] = int(stream)
    if wrong:
        meta["wrong_boards"] = wrong
    if options.pose_mode != "exact":
        meta["T_cam_board_true"] = scene.T_cam_board.tolist()
    return Observations(boards, scene.T_lidar_cam, meta, camera)


def observe_poses(options: SimOptions, T_lidar_cam: np.ndarray, T_lidar_board: np.ndarray, seed: int = 0,
                  trial: int = 0) -> Observations:
    """Fresh measurements of given board poses ``T_lidar_board`` (N,4,4) under ``T_lidar_cam``: each board's own
    scan with range noise and its camera pose (and corners) under ``options.pose_mode`` (the camera and lidar
    streams of ``trial_rngs(options, seed, trial)``), as ``generate`` would give them for that scene, rig
    conditions included (a margin drawn per board, the trial's erroneous camera: ``simulate.rig``).

    Raises CameraError when a board's pose cannot be estimated (e.g. no detection in ``image`` mode)."""
    o = options
    _, rng_lidar, rng_cam = trial_rngs(o, seed, trial)
    rng_margin, _ = rig_rngs(o, seed, trial)
    K = camera_matrix(o.focal_px, o.cam_width, o.cam_height)
    spec = BoardSpec.of(o)
    camera = file_camera(o, seed, trial)
    lens = None if is_default(o) else true_camera(o)
    bearings = beam_bearings(o.lidar_fov_deg, o.lidar_res_deg)
    T_cam = invert_T(np.asarray(T_lidar_cam, float))
    P = checkerboard_corners(o)
    boards, margins = [], []
    for T in np.asarray(T_lidar_board, float).reshape(-1, 4, 4):
        m = draw_margin(o, rng_margin) if margins_on(o) else None
        outline, kind = (spec.outline(), "exact") if m is None else file_outline(o, m)
        seen = spec.outline() if m is None else physical_outline(o, m)
        scan = cast_scan(bearings, T[None], seen, o.lidar_max_range_m, o.noise_mm / 1000.0, rng_lidar)[0]
        T_cb, uv = _observed(o, K, lens, T_cam @ T, spec, P, rng_cam)
        if o.intrinsics_error_on:
            T_cb = pose_from_corners(camera.K, P, uv, camera.dist) if lens is None else pose_of(camera, P, uv)
        boards.append(BoardObservation(T_cb, outline, scan, uv, None if uv is None else P, outline_kind=kind))
        margins.append(m)
    meta = {"generator": GENERATOR, "options": o.to_dict(), "seed": int(seed), "trial": int(trial)}
    if margins_on(o):
        meta["board_margin_m"] = margins
    if o.pose_mode != "exact":
        meta["T_cam_board_true"] = (T_cam[None] @ np.asarray(T_lidar_board, float)).tolist()
    return Observations(tuple(boards), np.asarray(T_lidar_cam, float), meta, camera)


__all__ = [
    "BoardSpec", "CameraError", "GENERATOR", "Scene", "SceneError", "SimOptions", "camera_matrix",
    "checkerboard_corners", "file_camera", "generate", "observe_poses", "render_board_image", "settings_hash",
    "simulate_trial", "trial_key", "trial_rngs",
]
