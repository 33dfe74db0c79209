"""The joint model and the camera side's covariance through the wide-angle camera models: each board's pose
covariance against the spread of poses fitted to noisy corners; lidarcam's joint answer with the intrinsics of a
lens estimated under their stated prior."""

from __future__ import annotations

import numpy as np
import pytest

from calib_core import calibrate
from calib_core.data.cameras.pose import pose_from_corners
from calib_core.geometry.metrics import nees
from calib_core.geometry.transforms import matrix_to_rotvec
from calib_core.refine.camera_side import board_pose_covariances
from calib_core.refine.joint_intrinsics import ESTIMATED_INTRINSICS
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
