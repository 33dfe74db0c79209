"""Rig conditions the ideal simulator leaves out: a physical board larger than its printed pattern (a margin drawn
per board, the file's outline then a lower bound) and a camera whose intrinsics are off by a typical calibration's
error (drawn once per trial; the file's camera is the erroneous one, with the error's 1-sigma stated).

Board frame as in ``simulate.camera`` (the pattern placed as on a ``board_size_m`` square). Units: metres, pixels.
Each condition draws from its own random stream (``rig_rngs``), never from the geometry or noise streams.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from calib_core.data.camera import Camera

from .camera import BoardSpec, camera_matrix
from .lens import is_default, true_camera
from .options import SimOptions

RIG_STREAMS = (3, 4)
"""Child indices of a trial's ``SeedSequence`` (``simulate.trial_rngs`` spawns 0-2) of the margin and the intrinsics
streams."""
DISTORTION_TERMS = 4
"""Distortion coefficients drawn by ``distortion_error``: k1, k2, p1, p2 (OpenCV order)."""


def rig_rngs(options: SimOptions, seed: int, trial: int, stream: int | None = None
             ) -> tuple[np.random.Generator, np.random.Generator]:
    """The (margin, intrinsics) generators of one trial: children ``RIG_STREAMS`` of the trial's ``SeedSequence``
    (``simulate.trial_rngs``), so they never shift the geometry and noise streams."""
    from . import trial_key

    ss = np.random.SeedSequence(entropy=int(seed), spawn_key=(trial_key(options, stream), int(trial)))
    kids = ss.spawn(max(RIG_STREAMS) + 1)
    return tuple(np.random.default_rng(kids[i]) for i in RIG_STREAMS)


def refuse_rig_conditions(options: SimOptions, who: str) -> None:
    """ValueError when ``options`` ask for rig conditions that ``who`` (a writer of images and raw scans, whose
    board and camera are the nominal ones) does not simulate."""
    if margins_on(options) or options.intrinsics_error_on:
        raise ValueError(f"{who}: board margins and intrinsics error are simulated by simulate.generate only; "
                         "set board_margin_max_m, focal_error_rel, principal_point_error_px, distortion_error to 0")


def margins_on(options: SimOptions) -> bool:
    """True when the physical board is drawn larger than its printed pattern."""
    return options.board_margin_max_m > 0


def pattern_outline(options: SimOptions) -> np.ndarray:
    """The printed checkerboard's outline (4,2) in the board frame (metres): its outer squares' edges."""
    spec = BoardSpec.of(options)
    lo = spec.pattern_origin
    hi = lo + np.array([spec.squares_x, spec.squares_y]) * spec.square_m
    return np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])


def physical_outline(options: SimOptions, margin_m: float) -> np.ndarray:
    """The physical board's outline (4,2): the printed pattern grown by ``margin_m`` on every side (metres)."""
    return pattern_outline(options) + margin_m * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])


def draw_margin(options: SimOptions, rng: np.random.Generator) -> float:
    """One board's margin (metres), uniform in [``board_margin_min_m``, ``board_margin_max_m``]."""
    return float(rng.uniform(options.board_margin_min_m, options.board_margin_max_m))


def file_outline(options: SimOptions, margin_m: float) -> tuple[np.ndarray, str]:
    """The outline a file states for a board of margin ``margin_m``, and its ``outline_kind``: the physical one
    (``exact``) with ``outline_known``, else the printed pattern's (``lower_bound``)."""
    if options.outline_known:
        return physical_outline(options, margin_m), "exact"
    return pattern_outline(options), "lower_bound"


def intrinsics_std(options: SimOptions) -> np.ndarray:
    """The 1-sigma (``Camera.std_intrinsics`` order: fx, fy, cx, cy in pixels, then k1 k2 p1 p2 when
    ``distortion_error > 0``) of the error ``erroneous_camera`` draws."""
    f = options.focal_error_rel * options.focal_px
    pp = options.principal_point_error_px
    d = [options.distortion_error] * DISTORTION_TERMS if options.distortion_error > 0 else []
    return np.array([f, f, pp, pp, *d])


def erroneous_camera(options: SimOptions, rng: np.random.Generator) -> Camera:
    """The camera a user has: the true pinhole (``camera_matrix``) with fx, fy, cx, cy and (with
    ``distortion_error``) k1 k2 p1 p2 each off by one Gaussian draw of ``intrinsics_std``; with
    ``std_intrinsics_known`` it states that 1-sigma. Drawn once per trial, in that order."""
    o = options
    std = intrinsics_std(o)
    K = camera_matrix(o.focal_px, o.cam_width, o.cam_height)
    err = rng.normal(0.0, 1.0, len(std)) * std
    K_err = np.array([[K[0, 0] + err[0], 0.0, K[0, 2] + err[2]], [0.0, K[1, 1] + err[1], K[1, 2] + err[3]],
                      [0.0, 0.0, 1.0]])
    if not is_default(o):
        return _erroneous_lens(o, K_err, err[4:], std)
    return Camera(K_err, err[4:], o.cam_width, o.cam_height, std if o.std_intrinsics_known else None)


def _erroneous_lens(o: SimOptions, K_err: np.ndarray, dist_err: np.ndarray, std: np.ndarray):
    """``erroneous_camera`` for a lens (``simulate.lens``): its parameters exact, the drawn error on K and (OpenCV
    lenses) the first four coefficients; the stated 1-sigma has a 0 for every value drawn without error."""
    cam = true_camera(o, K_err)
    if len(dist_err):
        k = cam.intrinsics
        k[cam.n_core:cam.n_core + len(dist_err)] += dist_err
        cam = cam.with_intrinsics(k)
    if not o.std_intrinsics_known:
        return cam
    n_dist = len(cam.to_dict()["dist"]) if len(dist_err) else 0
    full = np.zeros(cam.n_core + n_dist)
    full[:4] = std[:4]
    full[cam.n_core:cam.n_core + len(std) - 4] = std[4:]
    return replace(cam, dist=cam.to_dict()["dist"], std_intrinsics=full)
