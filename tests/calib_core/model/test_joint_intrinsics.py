"""The camera's intrinsics in the joint model (refine.joint_intrinsics): their Jacobian against finite
differences, exact recovery, the covariance against the spread of seeded trials with intrinsics error, the stated
covariance model, and ``camera.std_intrinsics`` in the observation format."""

import json
from dataclasses import replace

import numpy as np
import pytest

from calib_core import calibrate
from calib_core.data.camera import Camera, intrinsics_jacobian, project
from calib_core.data.io import load_observations, observations_to_dict
from calib_core.data.observations import Observations
from calib_core.errors import ObservationError
from calib_core.geometry.transforms import matrix_to_rotvec
from calib_core.model.corners import corner_residuals
from calib_core.model.intrinsics import ESTIMATED_INTRINSICS, EXACT_INTRINSICS
from calib_core.refine.joint import JOINT_INTRINSICS_MODEL, JOINT_MODEL, board_poses, joint_refine
from simulate import SimOptions, generate

RIG = {"pose_mode": "pixel", "n_boards": 6, "dist_min_m": 1.0, "dist_max_m": 4.0, "focal_error_rel": 0.003,
       "principal_point_error_px": 2.0}


def with_camera(obs, camera):
    return Observations(obs.boards, obs.T_lidar_cam_true, obs.meta, camera, obs.board_range_sigma_m)


def error_vector(T, T_true):
    return np.r_[matrix_to_rotvec(T[:3, :3] @ T_true[:3, :3].T), T[:3, 3] - T_true[:3, 3]]


@pytest.mark.parametrize("seed", range(4))
def test_intrinsics_jacobian_matches_finite_differences(seed):
    rng = np.random.default_rng(seed)
    dist = np.r_[rng.normal(0, 0.05, 8), rng.normal(0, 0.01, 4)]
    cam = Camera([[800.0, 0, 401.0], [0, 790.0, 298.0], [0, 0, 1]], dist, 800, 600)
    P = np.column_stack([rng.uniform(-1.5, 1.5, (30, 2)), rng.uniform(2.0, 6.0, 30)])
    J = intrinsics_jacobian(cam, P)
    k, h = cam.intrinsics, 1e-6
    for i in range(16):
        dk = h * np.eye(16)[i] * (1e3 if i < 4 else 1.0)
        fd = (project(cam.with_intrinsics(k + dk), P) - project(cam.with_intrinsics(k - dk), P)) / (2 * dk[i])
        np.testing.assert_allclose(J[..., i], fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max() + 1e-9)
    # and through the joint model's corner residuals, for a subset of free intrinsics
    obs = generate(SimOptions(**RIG), seed, 0)
    free = np.array([0, 1, 2, 3, 4, 6])
    _, _, Jk = corner_residuals(obs, board_poses(obs), jacobian=True, free=free)
    k0 = obs.camera.intrinsics
    for c, i in enumerate(free):
        dk = (1e-3 if i < 4 else 1e-7) * np.eye(16)[i]
        fd = (corner_residuals(obs, board_poses(obs), camera=obs.camera.with_intrinsics(k0 + dk))
              - corner_residuals(obs, board_poses(obs), camera=obs.camera.with_intrinsics(k0 - dk))) / (2 * dk[i])
        np.testing.assert_allclose(Jk[..., c], fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


@pytest.mark.parametrize("trial, distortion", [(0, 0.0), (1, 0.0), (2, 0.01), (3, 0.01)])
def test_exact_recovery_of_extrinsic_and_intrinsics_from_noise_free_data(trial, distortion):
    # corners from the true camera (no distortion), the file's camera off by the drawn error with a loose prior:
    # the noise-free views determine the intrinsics, so the joint solve returns the truth (the prior's pull is
    # negligible)
    obs = generate(SimOptions(**{**RIG, "pixel_noise_px": 0.0, "noise_mm": 0.0, "distortion_error": distortion}),
                   5, trial)
    c = obs.camera
    loose = Camera(c.K, c.to_dict()["dist"], c.width, c.height, 1e4 * c.std_intrinsics)
    j = joint_refine(with_camera(obs, loose), obs.T_lidar_cam_true)
    np.testing.assert_allclose(j.T_lidar_cam, obs.T_lidar_cam_true, atol=1e-7)
    k_true = np.r_[np.diag(obs.meta["K_true"])[:2], np.asarray(obs.meta["K_true"])[:2, 2], np.zeros(12)]
    np.testing.assert_allclose(j.camera.intrinsics, k_true, atol=1e-5)
    np.testing.assert_allclose(j.T_cam_board, obs.meta["T_cam_board_true"], atol=1e-7)


def test_covariance_with_intrinsics_holds_the_spread_of_trials_with_intrinsics_error():
    # 100 seeded trials, each with its own intrinsics error (0.3 % focal, 2 px principal point): with the stated
    # std_intrinsics the NEES of the joint answer averages 6 (band: 4 standard errors of a chi-square-6 mean plus
    # 0.5 for the estimated noise stds); with the intrinsics taken as exact it is far above
    n = 100
    nees, nees_exact = [], []
    for t in range(n):
        obs = generate(SimOptions(**RIG), 21, t)
        j = joint_refine(obs, obs.T_lidar_cam_true)
        e = error_vector(j.T_lidar_cam, obs.T_lidar_cam_true)
        nees.append(e @ np.linalg.solve(j.covariance, e))
        if t < 15:
            jx = joint_refine(obs, obs.T_lidar_cam_true, intrinsics=False)
            e = error_vector(jx.T_lidar_cam, obs.T_lidar_cam_true)
            nees_exact.append(e @ np.linalg.solve(jx.covariance, e))
    assert abs(np.mean(nees) - 6) < 4 * np.sqrt(12 / n) + 0.5
    assert np.mean(nees_exact) > 12


def test_without_std_intrinsics_the_joint_answer_is_unchanged():
    obs = generate(SimOptions(**{**RIG, "std_intrinsics_known": False}), 3, 0)
    assert obs.camera.std_intrinsics is None
    a = joint_refine(obs, obs.T_lidar_cam_true)
    b = joint_refine(obs, obs.T_lidar_cam_true, intrinsics=False)
    np.testing.assert_array_equal(a.T_lidar_cam, b.T_lidar_cam)
    np.testing.assert_array_equal(a.covariance, b.covariance)
    assert a.camera is None
    zero = with_camera(obs, replace(obs.camera, std_intrinsics=np.zeros(4)))  # every intrinsic fixed: exact
    np.testing.assert_array_equal(joint_refine(zero, obs.T_lidar_cam_true).T_lidar_cam, a.T_lidar_cam)


def test_results_say_how_the_intrinsics_were_treated():
    obs = generate(SimOptions(**RIG), 4, 0)
    res = calibrate(obs, method="lidarcam")
    assert res.ok and res.info["covariance_model"] == JOINT_INTRINSICS_MODEL
    assert res.info["intrinsics"] == ESTIMATED_INTRINSICS and res.to_dict()["intrinsics"] == ESTIMATED_INTRINSICS
    assert any(ESTIMATED_INTRINSICS in line for line in res.summary_lines())
    exact = calibrate(with_camera(obs, replace(obs.camera, std_intrinsics=None)), method="lidarcam")
    assert exact.info["covariance_model"] == JOINT_MODEL and exact.to_dict()["intrinsics"] == EXACT_INTRINSICS
    # more camera-side uncertainty, a larger 1-sigma
    assert res.sigma_rot_deg > exact.sigma_rot_deg and res.sigma_trans_mm > exact.sigma_trans_mm
    suffixed = calibrate(obs, method="peng2022+joint")
    assert suffixed.ok and suffixed.info["covariance_model"] == JOINT_INTRINSICS_MODEL
    ranges = calibrate(generate(SimOptions(n_boards=6), 4, 0), method="lidarcam")
    assert "board poses taken as exact" in ranges.to_dict()["intrinsics"]


def test_std_intrinsics_round_trips_and_is_validated(tmp_path):
    obs = generate(SimOptions(**{**RIG, "distortion_error": 0.01}), 1, 0)
    d = observations_to_dict(obs)
    assert len(d["camera"]["std_intrinsics"]) == 4 + len(d["camera"]["dist"])
    p = tmp_path / "obs.json"
    p.write_text(json.dumps(d))
    np.testing.assert_array_equal(load_observations(p).camera.std_intrinsics, obs.camera.std_intrinsics)
    four = dict(d, camera={**d["camera"], "std_intrinsics": [1.0, 1.0, 2.0, 2.0]})
    p.write_text(json.dumps(four))
    assert len(load_observations(p).camera.std_intrinsics) == 4
    for bad, msg in (([1.0, 1.0, 2.0], "length 3"), ([1.0, -1.0, 2.0, 2.0], "negative"),
                     ([1.0, float("nan"), 2.0, 2.0], "NaN"), ("abc", "not a numeric array")):
        p.write_text(json.dumps(dict(d, camera={**d["camera"], "std_intrinsics": bad})))
        with pytest.raises(ObservationError, match=msg) as err:
            load_observations(p)
        text = str(err.value)
        assert "obs.json" in text and "camera.std_intrinsics" in text and "\n" not in text


@pytest.mark.slow
def test_lidarcam_nees_on_rig_like_trials_holds_with_std_intrinsics():
    # lidarcam end to end on 150 rig-like trials (6 boards, 1-4 m, 20 mm, pixel corners, 0-5 cm margins with
    # lower-bound outlines, 0.3 % focal and 2 px principal point error): NEES median within 4-9 with the stated
    # std_intrinsics (a chi-square-6 median is 5.35), above 9 with the intrinsics taken as exact
    o = SimOptions(**RIG, board_margin_max_m=0.05)
    with_std, without = [], []
    for t in range(150):
        obs = generate(o, 41, t)
        for out, ob in ((with_std, obs), (without, with_camera(obs, replace(obs.camera, std_intrinsics=None)))):
            r = calibrate(ob, method="lidarcam")
            if r.ok and r.covariance is not None:
                e = error_vector(r.T_lidar_cam, obs.T_lidar_cam_true)
                out.append(e @ np.linalg.solve(r.covariance, e))
    assert len(with_std) >= 140 and 4 < np.median(with_std) < 9
    assert np.median(without) > 9
