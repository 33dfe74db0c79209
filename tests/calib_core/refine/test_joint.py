"""The joint model over image corners and lidar ranges (data.camera, refine.joint): projection against
OpenCV, Jacobians against finite differences, exact recovery, covariance against the Monte-Carlo spread."""

from dataclasses import replace

import cv2
import numpy as np
import pytest

from calib_core import calibrate
from calib_core.data.camera import Camera, project
from calib_core.data.observations import Observations
from calib_core.geometry.transforms import matrix_to_rotvec, rotvec_to_matrix
from calib_core.model.residuals import perturb
from calib_core.refine.joint import (
    JOINT_MODEL,
    RANGE_ONLY_MODEL,
    board_poses,
    corner_residuals,
    joint_crlb,
    joint_range_residuals,
    joint_refine,
)
from simulate import SimOptions, generate

K = [[800.0, 0.0, 399.5], [0.0, 790.0, 299.5], [0.0, 0.0, 1.0]]


def random_dist(rng, n):
    d = rng.normal(0.0, 0.05, n)
    if n == 14:
        d[12:] = 0.0
    return d


@pytest.mark.parametrize("n_dist", [0, 4, 5, 8, 12, 14])
def test_projection_matches_opencv_and_its_jacobian_finite_differences(rng, n_dist):
    for _ in range(5):
        dist = random_dist(rng, n_dist)
        cam = Camera(K, dist, 800, 600)
        P = np.column_stack([rng.uniform(-1.5, 1.5, (40, 2)), rng.uniform(2.0, 6.0, 40)])
        uv, J = project(cam, P, jacobian=True)
        ref = cv2.projectPoints(P, np.zeros(3), np.zeros(3), np.asarray(K), dist if n_dist else None)[0]
        np.testing.assert_allclose(uv, ref.reshape(-1, 2), atol=1e-8)
        h = 1e-6
        Jn = np.stack([(project(cam, P + h * e) - project(cam, P - h * e)) / (2 * h) for e in np.eye(3)], axis=-1)
        np.testing.assert_allclose(J, Jn, atol=1e-5 * np.abs(Jn).max())


def pixel_problem(seed=0, trial=0, n_boards=6, px=0.5, noise_mm=20.0):
    return generate(SimOptions(n_boards=n_boards, pose_mode="pixel", pixel_noise_px=px, noise_mm=noise_mm), seed, trial)


def with_distortion(obs, dist):
    """The same problem seen through a distorting camera: corners re-projected through ``dist``."""
    cam = Camera(obs.camera.K, dist, obs.camera.width, obs.camera.height)
    boards = []
    for b in obs.boards:
        X = b.corners_board @ b.T_cam_board[:3, :3].T + b.T_cam_board[:3, 3]
        boards.append(replace(b, corners_px=project(cam, X)))
    return Observations(tuple(boards), obs.T_lidar_cam_true, obs.meta, cam)


@pytest.mark.parametrize("trial", range(3))
def test_joint_jacobians_match_finite_differences(trial):
    rng = np.random.default_rng(trial)
    obs = with_distortion(pixel_problem(trial=trial), random_dist(rng, 8))
    T_e = perturb(obs.T_lidar_cam_true, rng.normal(0, 0.01, 6))
    T_b = board_poses(obs, rng.normal(0, 0.01, (obs.n_boards, 6)))
    ec, Jc = corner_residuals(obs, T_b, jacobian=True)
    er, Je, Jb = joint_range_residuals(obs, T_e, T_b, jacobian=True)
    h = 1e-7
    cidx = np.concatenate([np.full(len(b.corners_px), i) for i, b in enumerate(obs.boards)])
    sidx = obs.scan_data.board
    for k in range(6):
        dx = h * np.eye(6)[k]
        Je_n = (joint_range_residuals(obs, perturb(T_e, dx), T_b) - joint_range_residuals(obs, perturb(T_e, -dx), T_b))
        np.testing.assert_allclose(Je[:, k], Je_n / (2 * h), rtol=1e-5, atol=1e-6)
        for i in range(obs.n_boards):
            xb = np.zeros((obs.n_boards, 6))
            xb[i] = dx
            Tp, Tm = board_poses(obs, xb, T_b), board_poses(obs, -xb, T_b)
            dc = (corner_residuals(obs, Tp) - corner_residuals(obs, Tm)) / (2 * h)
            np.testing.assert_allclose(np.where((cidx == i)[:, None], Jc[:, :, k], 0.0), dc, rtol=1e-5, atol=1e-4)
            dr = (joint_range_residuals(obs, T_e, Tp) - joint_range_residuals(obs, T_e, Tm)) / (2 * h)
            np.testing.assert_allclose(np.where(sidx == i, Jb[:, k], 0.0), dr, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("trial", range(4))
def test_exact_recovery_from_noise_free_corners_and_ranges(trial):
    rng = np.random.default_rng(100 + trial)
    obs = with_distortion(pixel_problem(trial=trial, px=0.0, noise_mm=0.0), random_dist(rng, 5))
    truth_b = board_poses(obs)
    moved = tuple(replace(b, T_cam_board=T) for b, T in zip(obs.boards, board_poses(
        obs, rng.normal(0, 0.02, (obs.n_boards, 6))), strict=True))
    start = Observations(moved, obs.T_lidar_cam_true, obs.meta, obs.camera)
    j = joint_refine(start, perturb(obs.T_lidar_cam_true, rng.normal(0, 0.03, 6)))
    np.testing.assert_allclose(j.T_lidar_cam, obs.T_lidar_cam_true, atol=1e-8)
    np.testing.assert_allclose(j.T_cam_board, truth_b, atol=1e-8)
    assert j.corner_rms_px < 1e-6 and j.range_rms_m < 1e-8 and j.converged


def error_vector(T, T_true):
    return np.r_[matrix_to_rotvec(T[:3, :3] @ T_true[:3, :3].T), T[:3, 3] - T_true[:3, 3]]


def noisy_copy(obs, rng, px, sigma_m):
    boards = []
    for b in obs.boards:
        r = np.linalg.norm(b.scan, axis=1, keepdims=True)
        scan = b.scan * (1 + rng.normal(0, sigma_m, r.shape) / r)
        boards.append(replace(b, scan=scan, corners_px=b.corners_px + rng.normal(0, px, b.corners_px.shape)))
    return Observations(tuple(boards), obs.T_lidar_cam_true, obs.meta, obs.camera, obs.board_range_sigma_m)


def test_covariance_matches_the_monte_carlo_spread():
    # one scene, 150 draws of corner and range noise: the joint estimate's spread is the marginal covariance
    # (NEES mean 6 +- 4 standard errors, each variance within 30%), with the noise stds given or estimated
    px, sigma = 0.7, 0.02
    obs = pixel_problem(seed=3, trial=1, px=0.0, noise_mm=0.0)
    bound = joint_crlb(obs, sigma, px).cov
    rng = np.random.default_rng(7)
    err, nees_est = [], []
    for _ in range(150):
        j = joint_refine(noisy_copy(obs, rng, px, sigma), obs.T_lidar_cam_true)
        e = error_vector(j.T_lidar_cam, obs.T_lidar_cam_true)
        err.append(e)
        nees_est.append(e @ np.linalg.solve(j.covariance, e))
    err = np.array(err)
    nees = np.einsum("ka,ab,kb->k", err, np.linalg.inv(bound), err)
    assert abs(nees.mean() - 6) < 4 * np.sqrt(12 / len(nees))
    assert abs(np.mean(nees_est) - 6) < 4 * np.sqrt(12 / len(nees)) + 0.5
    np.testing.assert_allclose(np.diag(np.cov(err.T)), np.diag(bound), rtol=0.3)
    # the camera's noise matters here: the bound is well above the range-only bound
    assert np.trace(bound[:3, :3]) > 1.5 * np.trace(joint_crlb(obs, sigma, 0.0).cov[:3, :3])


def test_lidarcam_uses_the_joint_model_when_corners_are_present():
    obs = pixel_problem(trial=2, n_boards=8)
    res = calibrate(obs, "lidarcam")
    assert res.ok and res.info["covariance_model"] == JOINT_MODEL
    assert res.to_dict()["covariance_model"] == JOINT_MODEL
    assert 0.3 < res.info["corner_sigma_px"] < 0.7
    exact = generate(SimOptions(n_boards=8), 0, 2)
    res = calibrate(exact, "lidarcam")
    assert res.ok and res.info["covariance_model"] == RANGE_ONLY_MODEL
    assert res.to_dict()["covariance_model"] == RANGE_ONLY_MODEL
    off = calibrate(obs, "lidarcam", use_corners=False)
    assert off.info["covariance_model"] == RANGE_ONLY_MODEL


def test_x_joint_refines_any_method_and_says_when_it_cannot():
    obs = pixel_problem(trial=4, n_boards=6)
    for m in ("zhang_pless_linear+joint", "vasconcelos+joint", "peng2022+joint"):
        res = calibrate(obs, m)
        assert res.ok and res.info["covariance_model"] == JOINT_MODEL
        assert np.allclose(res.T_lidar_cam, calibrate(obs, "lidarcam").T_lidar_cam, atol=1e-6)
    exact = generate(SimOptions(n_boards=6), 0, 4)
    res = calibrate(exact, "peng2022+joint")
    assert res.ok and res.info["covariance_model"] == RANGE_ONLY_MODEL
    assert any("no image corners" in w for w in res.info["warnings"])


def test_joint_crlb_reduces_to_the_range_bound_without_corner_noise():
    from calib_core.refine.uncertainty import crlb

    obs = pixel_problem(px=0.0)
    np.testing.assert_allclose(joint_crlb(obs, 0.02, 0.0).cov, crlb(obs, 0.02).cov, rtol=1e-8)
    np.testing.assert_allclose(joint_crlb(obs, 0.02, 1e-5).cov, crlb(obs, 0.02).cov, rtol=1e-3)


def test_rotating_the_whole_problem_rotates_the_joint_answer(rng):
    # invariance: a change of the lidar frame about its z axis maps the answer the same way
    obs = pixel_problem(trial=5)
    res = joint_refine(obs, calibrate(obs, "lidarcam", use_corners=False).T_lidar_cam)
    Rz = rotvec_to_matrix(np.array([0, 0, 0.3]))
    boards = tuple(replace(b, scan=b.scan @ Rz[:2, :2].T) for b in obs.boards)
    T_true = obs.T_lidar_cam_true.copy()
    T_true[:3] = Rz @ T_true[:3]
    rot = Observations(boards, T_true, obs.meta, obs.camera)
    T0 = res.T_lidar_cam.copy()
    T0[:3] = Rz @ T0[:3]
    res2 = joint_refine(rot, T0)
    np.testing.assert_allclose(res2.T_lidar_cam[:3], Rz @ res.T_lidar_cam[:3], atol=1e-7)


def test_robust_loss_resists_a_false_corner():
    obs = pixel_problem(trial=6, px=0.3)
    T0 = calibrate(obs, "lidarcam", use_corners=False).T_lidar_cam
    clean = joint_refine(obs, T0, corner_sigma_px=0.3, range_sigma_m=0.02)
    bad_px = obs.boards[2].corners_px.copy()
    bad_px[[0, 7]] += [40.0, -30.0]
    bad = Observations(tuple(replace(b, corners_px=bad_px) if i == 2 else b for i, b in enumerate(obs.boards)),
                       obs.T_lidar_cam_true, obs.meta, obs.camera)
    plain = joint_refine(bad, T0, corner_sigma_px=0.3, range_sigma_m=0.02)
    robust = joint_refine(bad, T0, corner_sigma_px=0.3, range_sigma_m=0.02, loss="cauchy")
    d_plain = np.linalg.norm(error_vector(plain.T_lidar_cam, clean.T_lidar_cam))
    d_robust = np.linalg.norm(error_vector(robust.T_lidar_cam, clean.T_lidar_cam))
    assert d_robust < 0.2 * d_plain
