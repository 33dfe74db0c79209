"""A small self-contained scene generator for the uncertainty and lidarcam tests (independent of ``simulate``,
so these tests pin the library alone): square 1 m boards at 3-6 m, a 0.25 deg lidar, range noise along the
beam, exact camera-side board poses."""

import numpy as np

from calib_core.data.observations import BoardObservation, Observations
from calib_core.geometry.transforms import invert_T, make_T, matrix_to_rotvec, rotvec_to_matrix

# camera z -> lidar x, camera x -> lidar -y, camera y -> lidar -z
R_NOMINAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
OUTLINE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


def random_extrinsic(rng) -> np.ndarray:
    w = rng.normal(size=3)
    w *= np.radians(rng.uniform(0, 5)) / np.linalg.norm(w)
    t = rng.normal(size=3)
    t *= rng.uniform(0.05, 0.3) / np.linalg.norm(t)
    return make_T(rotvec_to_matrix(w) @ R_NOMINAL, t)


def board_pose(rng, max_tilt_deg=45.0) -> np.ndarray:
    """T_lidar_board of a board whose centre is ahead of the lidar and whose normal faces it within the tilt."""
    bearing = np.radians(rng.uniform(-30, 30))
    c = rng.uniform(3, 6) * np.array([np.cos(bearing), np.sin(bearing), 0.0]) + [0, 0, rng.uniform(-0.3, 0.3)]
    z = -c / np.linalg.norm(c)                                 # normal towards the sensor
    axis = np.cross(z, rng.normal(size=3))
    axis /= np.linalg.norm(axis)
    z = rotvec_to_matrix(axis * np.radians(rng.uniform(0, max_tilt_deg))) @ z
    x = np.cross([0.0, 0.0, 1.0], z)
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(z, x), z])
    R = R @ rotvec_to_matrix(np.array([0, 0, rng.uniform(-np.pi, np.pi)]))
    return make_T(R, c - R @ np.array([0.5, 0.5, 0.0]))


def scan_board(T_lidar_board, res_deg=0.25):
    """(K,) true ranges and (K,3) beams of the lidar beams that hit the board."""
    bearings = np.radians(np.arange(-90, 90 + 1e-9, res_deg))
    u = np.column_stack([np.cos(bearings), np.sin(bearings), np.zeros_like(bearings)])
    n, o = T_lidar_board[:3, 2], T_lidar_board[:3, 3]
    with np.errstate(divide="ignore"):
        r = (n @ o) / (u @ n)
    P = r[:, None] * u
    xy = (P - o) @ T_lidar_board[:3, :2]
    hit = (r > 0) & np.all((xy > 0) & (xy < 1), axis=1)
    return r[hit], u[hit]


def make_observations(rng, n_boards=6, range_sigma_m=0.02, T_lidar_cam=None, poses=None, min_points=15) -> Observations:
    """Observations with ground truth; ``poses`` (list of T_lidar_board) overrides the random boards. A clean
    simulation: no per-board systematic error, stated as ``board_range_sigma_m = 0`` as the simulator states it."""
    T = random_extrinsic(rng) if T_lidar_cam is None else T_lidar_cam
    T_cam_lidar = invert_T(T)
    boards = []
    while len(boards) < (n_boards if poses is None else len(poses)):
        Tb = board_pose(rng) if poses is None else poses[len(boards)]
        r, u = scan_board(Tb)
        T_cam_board = T_cam_lidar @ Tb
        if len(r) < min_points or T_cam_board[2, 3] < 1.0:
            if poses is not None:
                raise ValueError("a given pose is not seen")
            continue
        P = (r + rng.normal(scale=range_sigma_m, size=len(r)))[:, None] * u
        boards.append(BoardObservation(T_cam_board, OUTLINE, P[:, :2]))
    return Observations(tuple(boards), T, board_range_sigma_m=0.0)


def vertical_board_poses(n):
    """Boards whose normals all lie in the scan plane: nothing fixes the extrinsic's height (degenerate)."""
    poses = []
    for k in range(n):
        bearing = np.radians(-25 + 50 * k / max(n - 1, 1))
        c = 4.0 * np.array([np.cos(bearing), np.sin(bearing), 0.0])
        yaw = bearing + np.radians(30 * (-1) ** k)
        z = -np.array([np.cos(yaw), np.sin(yaw), 0.0])
        x = np.cross([0.0, 0.0, 1.0], z)
        R = np.column_stack([x, np.cross(z, x), z])
        poses.append(make_T(R, c - R @ np.array([0.5, 0.5, 0.0])))
    return poses


def error_vector(T, T_true):
    """(rotation-vector error in the lidar frame, translation error): the parameters of calib_core.model.residuals."""
    return np.r_[matrix_to_rotvec(T[:3, :3] @ T_true[:3, :3].T), T[:3, 3] - T_true[:3, 3]]
