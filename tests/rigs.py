"""Simulated rigs for the degeneracy, partial-calibration and cross-validation tests, built from the simulator's
pieces (``simulate.scene.sample_extrinsic``, ``simulate.lidar.cast_scan``, the board of ``SimOptions``): boards
standing vertical in front of the lidar (every normal in the scan plane: the rig of a ground robot with boards
on the floor), optionally leaning back by a few degrees, and general rigs from ``simulate.generate``."""

import numpy as np

from calib_core.observations import BoardObservation, Observations
from calib_core.transforms import invert_T, make_T, rotvec_to_matrix
from simulate import SimOptions, generate
from simulate.camera import BoardSpec
from simulate.lidar import beam_bearings, cast_scan
from simulate.scene import sample_extrinsic

VERTICAL_OPTIONS = SimOptions(n_boards=5, board_size_m=0.8, checker_square_m=0.1, dist_min_m=1.0, dist_max_m=3.0,
                              noise_mm=5.0, lidar_res_deg=0.5)


def vertical_board(rng, options: SimOptions, lean_deg: float = 0.0) -> np.ndarray:
    """``T_lidar_board`` of a board standing on the floor ahead of the lidar: centre in the scan plane at
    ``dist_min_m..dist_max_m`` and bearing within +-``bearing_spread_deg``/2, turned by up to 40 deg about the
    vertical from facing the lidar, then leaning back by ``lean_deg`` about its horizontal axis."""
    o = options
    bearing = np.radians(rng.uniform(-o.bearing_spread_deg / 2, o.bearing_spread_deg / 2))
    centre = rng.uniform(o.dist_min_m, o.dist_max_m) * np.array([np.cos(bearing), np.sin(bearing), 0.0])
    turn = bearing + np.radians(rng.uniform(-40, 40))
    z = np.array([np.cos(turn), np.sin(turn), 0.0])                     # away from the sensors
    x = np.cross([0.0, 0.0, 1.0], z)
    R = np.column_stack([x, np.cross(z, x), z])
    R = rotvec_to_matrix(x * np.radians(lean_deg)) @ R
    half = o.board_size_m / 2
    return make_T(R, centre + np.array([0, 0, rng.uniform(-0.2, 0.2)]) - R[:, 0] * half - R[:, 1] * half)


def vertical_rig(seed: int, options: SimOptions = VERTICAL_OPTIONS, lean_deg: float = 0.0,
                 T_lidar_cam: np.ndarray | None = None) -> Observations:
    """A rig of ``options.n_boards`` vertical boards (leaning back by up to ``lean_deg``), exact camera poses,
    range noise ``options.noise_mm``; the extrinsic is drawn by the simulator unless given."""
    rng = np.random.default_rng(seed)
    T = sample_extrinsic(options, rng) if T_lidar_cam is None else np.asarray(T_lidar_cam, float)
    outline = BoardSpec.of(options).outline()
    bearings = beam_bearings(options.lidar_fov_deg, options.lidar_res_deg)
    boards = []
    while len(boards) < options.n_boards:
        Tb = vertical_board(rng, options, rng.uniform(0, lean_deg))
        T_cam_board = invert_T(T) @ Tb
        scan = cast_scan(bearings, Tb[None], outline, options.lidar_max_range_m, options.noise_mm / 1000, rng)[0]
        if len(scan) >= options.min_points_per_board and T_cam_board[2, 3] > options.min_depth_m:
            boards.append(BoardObservation(T_cam_board, outline, scan))
    return Observations(tuple(boards), T)


def general_rig(seed: int, **changes) -> Observations:
    """A rig from ``simulate.generate`` with the default options changed by ``changes``."""
    return generate(SimOptions(**changes), seed=seed)
