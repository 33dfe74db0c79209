"""The camera side's error of the board planes (calib_core.refine.camera_side) and the verdict that models it: the
intrinsics' part of a board pose's covariance against finite differences of the pose fit, the predicted spread
against the boards' actual plane errors on simulated rigs, the move's closed form against the explicit
Mahalanobis statistic, and the verdict on rig-like data: a board plane within its camera-side uncertainty does
not condemn the truth, one beyond it does, and answers 10 deg / 100 mm off are refused."""

from dataclasses import replace

import numpy as np
import pytest
from rigs import RIG_LIKE as RIG
from scipy.optimize import least_squares

from calib_core.checks.verdict import check, effective_sigma, measured_points
from calib_core.data.observations import MIN_RANGE_M
from calib_core.geometry.transforms import rotvec_to_matrix
from calib_core.model.corners import board_poses, corner_residuals, joint_range_residuals
from calib_core.model.intrinsics import IntrinsicsPrior
from calib_core.model.residuals import range_residuals
from calib_core.refine.camera_side import board_pose_covariances, corner_noise_px, pose_covariances, pose_explained
from simulate import SimOptions, generate


def rig(n_boards, trial, seed=11):
    return generate(SimOptions(n_boards=n_boards, **RIG), seed, trial)


def _moved(T, x):
    out = T.copy()
    out[:3, :3] = rotvec_to_matrix(x[:3]) @ T[:3, :3]
    out[:3, 3] += x[3:]
    return out


def _exact_corners(obs):
    """``obs`` with every board's corners replaced by their projection at its observed pose through the file's
    camera: the observed poses are then the exact fits of their corners."""
    proj = corner_residuals(obs, board_poses(obs)) + np.concatenate([b.corners_px for b in obs.boards])
    cut = np.cumsum([len(b.corners_px) for b in obs.boards])[:-1]
    return replace(obs, boards=tuple(replace(b, corners_px=p) for b, p in zip(obs.boards, np.split(proj, cut),
                                                                                strict=True)))


def test_intrinsics_part_is_the_pose_fits_response_to_an_intrinsics_error():
    """A (6,m), the response of each board's fitted pose to its intrinsics, against re-fitting the pose to its
    corners with the intrinsics moved (central differences, corners the exact projections so the fit's second
    order terms vanish): the covariance's intrinsics part is ``A C_k A^T``."""
    for trial in range(3):
        obs = _exact_corners(rig(3, trial))
        prior = IntrinsicsPrior.of(obs.camera)
        full, corners_only = board_pose_covariances(obs, 0.5), board_pose_covariances(obs, 0.5, intrinsics=False)
        for i in range(obs.n_boards):
            o1 = obs.subset([i])
            T0 = board_poses(o1)

            def fit(k, o1=o1, T0=T0, prior=prior):
                cam = prior.camera_at(k)
                return least_squares(lambda x: corner_residuals(o1, _moved(T0[0], x)[None], camera=cam).ravel(),
                                     np.zeros(6), xtol=1e-15, ftol=1e-15, gtol=1e-15).x

            A = np.zeros((6, prior.size))
            for j in range(prior.size):
                h = 1e-3 * prior.std[j]
                kp, km = prior.k0.copy(), prior.k0.copy()
                kp[j] += h
                km[j] -= h
                A[:, j] = (fit(kp) - fit(km)) / (2 * h)
            want = corners_only[i] + A @ np.diag(prior.std**2) @ A.T
            np.testing.assert_allclose(full[i], want, rtol=1e-4, atol=1e-6 * np.abs(want).max())


def test_predicted_plane_spread_matches_the_boards_actual_plane_errors():
    """Over seeded rig-like trials, each board's plane error at its scan points (the observed pose against the
    true one, along the beams) in units of its predicted spread ``sqrt(J_b C_b J_b^T)`` has RMS near 1; with the
    corners' part alone (intrinsics taken as exact) it is well above 1."""
    z, z_corners = [], []
    for trial in range(40):
        obs = rig(6, trial)
        T = obs.T_lidar_cam_true
        true_poses = np.array(obs.meta["T_cam_board_true"])
        e_obs, _, Jb = joint_range_residuals(obs, T, board_poses(obs), jacobian=True)
        err = e_obs - joint_range_residuals(obs, T, true_poses)
        board = obs.scan_data.board
        sigma = corner_noise_px(obs)
        for C, out in ((board_pose_covariances(obs, sigma), z),
                       (board_pose_covariances(obs, sigma, intrinsics=False), z_corners)):
            var = np.einsum("ka,kab,kb->k", Jb, C[board], Jb)
            for i in range(obs.n_boards):
                s = board == i
                out.append(np.sqrt(np.mean(err[s] ** 2) / np.mean(var[s])))
    assert 0.8 < np.sqrt(np.mean(np.square(z))) < 1.25
    assert np.sqrt(np.mean(np.square(z_corners))) > 1.5


def test_pose_explained_is_the_mahalanobis_statistic_of_each_board():
    for trial in range(4):
        obs = rig(4, trial)
        T = _moved(obs.T_lidar_cam_true, np.r_[0.02, -0.01, 0.015, 0.03, 0.0, -0.02])
        data = measured_points(obs)
        keep = np.linalg.norm(obs.scan_data.points, axis=1) > MIN_RANGE_M
        sigma = effective_sigma(obs)
        r = range_residuals(T, data)
        rest, cost = pose_explained(obs, T, r, keep, sigma)
        _, _, Jb = joint_range_residuals(obs, T, board_poses(obs), jacobian=True)
        C = pose_covariances(obs)
        for i in range(obs.n_boards):
            s = data.board == i
            S = sigma**2 * np.eye(s.sum()) + Jb[s] @ C[i] @ Jb[s].T
            want = r[s] @ np.linalg.solve(S, r[s])
            assert np.sum(rest[s] ** 2) / sigma**2 + cost[i] == pytest.approx(want, rel=1e-9)
            assert cost[i] >= 0


def _ranges_off(obs, i, metres):
    """``obs`` with board ``i``'s scan ranges all longer by ``metres`` (its plane seen farther by the lidar)."""
    b = obs.boards[i]
    scan = b.scan * (1 + metres / np.linalg.norm(b.scan, axis=1))[:, None]
    return replace(obs, boards=tuple(replace(bb, scan=scan) if j == i else bb for j, bb in enumerate(obs.boards)))


def test_a_board_plane_off_within_its_camera_side_uncertainty_does_not_condemn_the_truth():
    """The farthest board's ranges off by 3 of its camera-side 1-sigma along the beams (its plane's predicted
    spread from its corners and the stated intrinsics, ``sqrt(J_b C_b J_b^T)``): the truth stands; by 12 of them
    plus 4 range-noise stds: that board is named."""
    for trial in range(6):
        obs = rig(4, trial)
        T = obs.T_lidar_cam_true
        i = int(np.argmax([np.linalg.norm(b.T_cam_board[:3, 3]) for b in obs.boards]))
        _, _, Jb = joint_range_residuals(obs, T, board_poses(obs), jacobian=True)
        s = obs.scan_data.board == i
        sd = float(np.sqrt(np.mean(np.einsum("ka,ab,kb->k", Jb[s], pose_covariances(obs)[i], Jb[s]))))
        assert sd > 0.005
        assert check(_ranges_off(obs, i, 3 * sd), T).consistent
        far = check(_ranges_off(obs, i, 12 * sd + 0.08), T)
        assert not far.consistent and f"board {i}:" in far.reason


@pytest.mark.parametrize("n_boards", [3, 4, 6])
def test_the_truth_stands_and_answers_10_deg_off_are_refused_on_rig_like_data(n_boards):
    rng = np.random.default_rng(n_boards)
    refused_truth, accepted_wrong = 0, 0
    for trial in range(25):
        obs = rig(n_boards, trial)
        refused_truth += not check(obs, obs.T_lidar_cam_true).consistent
        w = rng.normal(size=3)
        d = rng.normal(size=3)
        x = np.r_[np.deg2rad(10) * w / np.linalg.norm(w), 0.1 * d / np.linalg.norm(d)]
        accepted_wrong += check(obs, _moved(obs.T_lidar_cam_true, x)).consistent
    assert refused_truth == 0
    assert accepted_wrong <= 2
