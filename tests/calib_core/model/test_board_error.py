"""The per-board systematic error's term (model.board_error): its columns against finite differences of the range
residuals."""

import numpy as np
from scenes import make_observations

from calib_core.data.observations import ScanData
from calib_core.geometry.transforms import rotvec_to_matrix
from calib_core.model.board_error import BoardErrorScale, systematic_basis
from calib_core.model.residuals import range_residuals


def _lidar_normals(data: ScanData, T: np.ndarray) -> np.ndarray:
    return data.normals @ T[:3, :3].T


def test_offset_column_is_the_range_change_of_a_range_offset(rng):
    obs = make_observations(rng, 6, 0.0)
    data, T = obs.scan_data, obs.T_lidar_cam_true
    B = systematic_basis(data, _lidar_normals(data, T))
    u = 1e-3
    moved = ScanData(data.points * (1 + u / np.linalg.norm(data.points, axis=1))[:, None], data.board, data.normals,
                     data.offsets)
    np.testing.assert_allclose(range_residuals(T, moved) - range_residuals(T, data), u * B[:, 0], atol=1e-12)


def test_tilt_column_matches_finite_differences_of_a_tilted_plane(rng):
    """Tilting board i's plane by a small angle about the in-plane axis across its scan line, through its points'
    centroid, changes its range residuals by (angle * R_i) times the tilt column (up to sign), to first order."""
    obs = make_observations(rng, 6, 0.0)
    data, T = obs.scan_data, obs.T_lidar_cam_true
    R, t = T[:3, :3], T[:3, 3]
    B = systematic_basis(data, _lidar_normals(data, T))
    e0 = range_residuals(T, data)
    for i in range(obs.n_boards):
        on = data.board == i
        P = data.points[on]
        c = P.mean(axis=0)
        v = np.linalg.svd(P - c)[2][0]                         # the scan line's direction (lidar frame)
        m = R @ data.normals[i]
        axis = np.cross(m, v)
        axis /= np.linalg.norm(axis)
        Rt = np.sqrt(np.mean(((P - c) @ v) ** 2))
        a = 1e-6
        m2 = rotvec_to_matrix(a * axis) @ m
        normals, offsets = data.normals.copy(), data.offsets.copy()
        normals[i] = R.T @ m2
        offsets[i] = m2 @ c - m2 @ t                              # the tilted plane through the centroid
        e1 = range_residuals(T, ScanData(data.points, data.board, normals, offsets))
        d = (e1 - e0)[on] / (a * Rt)
        s = np.sign(d @ B[on, 1])
        np.testing.assert_allclose(s * d, B[on, 1], rtol=1e-4, atol=1e-4 * np.abs(B[on, 1]).max())
        np.testing.assert_allclose((e1 - e0)[~on], 0.0, atol=1e-15)


def test_scale_is_active_when_either_part_is_nonzero():
    assert not BoardErrorScale().active and BoardErrorScale(0.0, 1e-4).active and BoardErrorScale(1e-4).active
