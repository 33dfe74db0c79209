"""The joint model and the camera side's covariance through the wide-angle camera models: each board's pose
covariance against the spread of poses fitted to noisy corners; lidarcam's joint answer with the intrinsics of a
lens estimated under their stated prior."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from calib_core import calibrate
from calib_core.data.camera import Camera
from calib_core.data.cameras.pose import pose_from_corners
from calib_core.geometry.metrics import nees
from calib_core.geometry.transforms import matrix_to_rotvec
from calib_core.model.intrinsics import ESTIMATED_INTRINSICS
from calib_core.refine.camera_side import board_pose_covariances
from simulate import SimOptions, generate
from simulate.lens import LENSES

WIDE = {"pose_mode": "pixel", "n_boards": 8, "dist_min_m": 1.0, "dist_max_m": 3.0, "bearing_spread_deg": 150.0}


@pytest.mark.parametrize("lens", ["fisheye150", "ds180"])
def test_board_pose_covariance_matches_the_spread_of_fitted_poses(lens):
    obs = generate(SimOptions(**WIDE, **LENSES[lens]), seed=2)
    cam, sigma = obs.camera, 0.5
    C = board_pose_covariances(obs, sigma)
    rng = np.random.default_rng(0)
    for i in (0, 5):
        b, T = obs.boards[i], obs.boards[i].T_cam_board
        clean = cam.project(b.corners_board @ T[:3, :3].T + T[:3, 3])
        d = []
        for _ in range(600):
            F = pose_from_corners(cam, b.corners_board, clean + rng.normal(0, sigma, clean.shape), T0=T)
            d.append(np.r_[matrix_to_rotvec(F[:3, :3] @ T[:3, :3].T), F[:3, 3] - T[:3, 3]])
        d = np.array(d)
        # the empirical covariance's whitened eigenvalues are 1 within sampling error (600 draws: about 0.8-1.2)
        L = np.linalg.cholesky(C[i])
        w = np.linalg.eigvalsh(np.linalg.solve(L, np.linalg.solve(L, np.cov(d.T)).T))
        assert 0.7 < w.min() and w.max() < 1.35, w


@pytest.mark.parametrize("lens", ["fisheye150", "ds180"])
def test_lidarcam_estimates_a_lens_intrinsics_under_their_prior(lens):
    o = SimOptions(**WIDE, **LENSES[lens], focal_error_rel=0.003, principal_point_error_px=2.0)
    obs = generate(o, seed=4)
    r = calibrate(obs, method="lidarcam")
    assert r.ok, r.reason
    assert r.info["intrinsics"] == ESTIMATED_INTRINSICS
    assert nees(r.T_lidar_cam, obs.T_lidar_cam_true, r.covariance) < 25      # chi2(6) 99.9% is 22.5


def test_the_planner_places_boards_beside_a_wide_angle_lens():
    from calib_core.planning.views import feasibility, rig_from_observations
    obs = generate(SimOptions(**WIDE, **LENSES["ds180"]), seed=1)
    rig = rig_from_observations(obs, obs.T_lidar_cam_true, 0.02, 0.5)
    T_cl = rig.T_lidar_cam
    # boards about 2 m from the camera, about 0, 45 and 70 deg off its axis, centred on the scan plane, facing it
    poses = []
    for deg in (0.0, 45.0, 70.0):
        a = np.radians(deg)
        c = T_cl[:3, :3] @ (2.0 * np.array([np.sin(a), 0.0, np.cos(a)])) + T_cl[:3, 3]
        c[2] = 0.0                                                  # on the scan plane
        z = c - T_cl[:3, 3]
        z /= np.linalg.norm(z)
        y = np.array([0.0, 0.0, -1.0])
        x = np.cross(y, z)
        T = np.eye(4)
        T[:3, :3] = np.column_stack([x, y, z])
        T[:3, 3] = c - T[:3, :3] @ np.r_[rig.corners_board[:, :2].mean(0), 0]
        poses.append(T)
    reason, _, _ = feasibility(rig, np.array(poses))
    assert reason.tolist() == [-1, -1, -1]
    pinhole = replace(rig, camera=Camera(obs.camera.K, [], obs.camera.width, obs.camera.height))
    assert feasibility(pinhole, np.array(poses))[0][2] >= 0       # the same K as a pinhole misses the 70 deg board


def test_boards_beside_and_behind_a_wide_lens_axis_are_used():
    # a double-sphere lens seeing about 200 deg across; boards over 230 deg of bearing, some beyond 90 deg off axis
    o = SimOptions(pose_mode="pixel", n_boards=8, dist_min_m=1.0, dist_max_m=2.0, bearing_spread_deg=230.0,
                   lidar_fov_deg=270.0, cam_model="ds", cam_params="-0.2,0.6", focal_px=250.0, cam_width=1280,
                   cam_height=1024, max_attempts=5000)
    for trial in (2, 4):
        obs = generate(o, seed=1, trial=trial)
        T = np.asarray(obs.meta["T_cam_board_true"])
        centre_z = [(t[:3, :3] @ b.corners_board.mean(0) + t[:3, 3])[2] for t, b in zip(T, obs.boards, strict=True)]
        assert min(centre_z) < -0.2                                   # a board centre behind the camera's plane
        r = calibrate(obs, method="lidarcam")
        assert r.ok and len(r.boards_used) == 8, r.warnings
        assert nees(r.T_lidar_cam, obs.T_lidar_cam_true, r.covariance) < 25
