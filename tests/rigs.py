"""Simulated rigs for the degeneracy, partial-calibration and cross-validation tests, built from the simulator's
pieces (``simulate.scene.sample_extrinsic``, ``simulate.lidar.cast_scan``, the board of ``SimOptions``): boards
standing vertical in front of the lidar (every normal in the scan plane: the rig of a ground robot with boards
on the floor), optionally leaning back by a few degrees, and general rigs from ``simulate.generate``."""

import numpy as np

from calib_core.data.observations import BoardObservation, Observations
from calib_core.geometry.transforms import invert_T, make_T, rotvec_to_matrix
from simulate import SimOptions, generate
from simulate.camera import BoardSpec
from simulate.lidar import beam_bearings, cast_scan
from simulate.scene import sample_extrinsic

RIG_LIKE = dict(pose_mode="pixel", pixel_noise_px=0.5, noise_mm=20.0, dist_min_m=1.0, dist_max_m=4.0,
                board_margin_min_m=0.01, board_margin_max_m=0.05, focal_error_rel=0.003,
                principal_point_error_px=2.0, distortion_error=0.002, std_intrinsics_known=True)
"""The rig-like preset's values (conf/preset/rig-like.yaml) without its per-board systematic error."""
RIG_SYSTEMATIC = dict(lidar_board_offset_mm=5.0, lidar_dark_offset_mm=20.0, board_bow_mm=3.0)
"""The preset's per-board systematic range error (conf/systematic/rig.yaml); ``RIG_LIKE | RIG_SYSTEMATIC`` is the
preset as ``make rig-like`` runs it."""

VERTICAL_OPTIONS = SimOptions(n_boards=5, board_size_m=0.8, checker_square_m=0.1, dist_min_m=1.0, dist_max_m=3.0,
                              noise_mm=5.0, lidar_res_deg=0.5)


def facing_board(centre: np.ndarray, normal: np.ndarray, size_m: float) -> np.ndarray:
    """``T_lidar_board`` of a square board of side ``size_m`` centred at ``centre`` with unit ``normal`` (board z,
    away from the sensors), its x axis horizontal."""
    z = np.asarray(normal, float) / np.linalg.norm(normal)
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(z, x), z])
    return make_T(R, np.asarray(centre, float) - R[:, 0] * size_m / 2 - R[:, 1] * size_m / 2)


def vertical_board(rng, options: SimOptions, lean_deg: float = 0.0) -> np.ndarray:
    """``T_lidar_board`` of a board standing on the floor ahead of the lidar: centre near the scan plane at
    ``dist_min_m..dist_max_m`` and bearing within +-``bearing_spread_deg``/2, turned by up to 40 deg about the
    vertical from facing the lidar, then leaning back by ``lean_deg`` about its horizontal axis."""
    o = options
    bearing = np.radians(rng.uniform(-o.bearing_spread_deg / 2, o.bearing_spread_deg / 2))
    centre = rng.uniform(o.dist_min_m, o.dist_max_m) * np.array([np.cos(bearing), np.sin(bearing), 0.0])
    turn = bearing + np.radians(rng.uniform(-40, 40))
    z = np.array([np.cos(turn), np.sin(turn), 0.0])
    z = rotvec_to_matrix(np.cross([0.0, 0.0, 1.0], z) * np.radians(lean_deg)) @ z
    return facing_board(centre + np.array([0, 0, rng.uniform(-0.2, 0.2)]), z, o.board_size_m)


def rig_from_boards(T_lidar_cam: np.ndarray, boards: list[np.ndarray], options: SimOptions, rng) -> Observations:
    """Observations of the given ``T_lidar_board`` poses: exact camera poses, scans cast by the simulator's lidar
    with range noise ``options.noise_mm``; boards the lidar hits with too few points or that are behind the
    camera are left out."""
    outline = BoardSpec.of(options).outline()
    bearings = beam_bearings(options.lidar_fov_deg, options.lidar_res_deg)
    out = []
    for Tb in boards:
        T_cam_board = invert_T(T_lidar_cam) @ Tb
        scan = cast_scan(bearings, Tb[None], outline, options.lidar_max_range_m, options.noise_mm / 1000, rng)[0]
        if len(scan) >= options.min_points_per_board and T_cam_board[2, 3] > options.min_depth_m:
            out.append(BoardObservation(T_cam_board, outline, scan))
    return Observations(tuple(out), T_lidar_cam)


def vertical_rig(seed: int, options: SimOptions = VERTICAL_OPTIONS, lean_deg: float = 0.0,
                 T_lidar_cam: np.ndarray | None = None) -> Observations:
    """A rig of ``options.n_boards`` vertical boards (each leaning back by up to ``lean_deg``), exact camera poses,
    range noise ``options.noise_mm``; the extrinsic is drawn by the simulator unless given."""
    rng = np.random.default_rng(seed)
    T = sample_extrinsic(options, rng) if T_lidar_cam is None else np.asarray(T_lidar_cam, float)
    boards: list = []
    while len(boards) < options.n_boards:
        obs = rig_from_boards(T, [vertical_board(rng, options, rng.uniform(0, lean_deg))], options, rng)
        boards += obs.boards
    return Observations(tuple(boards), T)


def with_range_noise(obs: Observations, sigma_m: float, rng) -> Observations:
    """``obs`` with zero-mean Gaussian noise of std ``sigma_m`` added to every range (along each beam)."""
    boards = []
    for b in obs.boards:
        r = np.linalg.norm(b.scan, axis=1, keepdims=True)
        boards.append(BoardObservation(b.T_cam_board, b.outline,
                                       b.scan * (1 + rng.normal(0, sigma_m, (len(r), 1)) / r)))
    return Observations(tuple(boards), obs.T_lidar_cam_true, dict(obs.meta))


def general_rig(seed: int, **changes) -> Observations:
    """A rig from ``simulate.generate`` with the default options changed by ``changes``."""
    return generate(SimOptions(**changes), seed=seed)
