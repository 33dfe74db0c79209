"""Held-out scores beyond point-to-plane (calib_core.evaluate.held_out): residuals in units of their predicted spread
hold on simulated rigs whose board poses come from noisy corners, the factor on the board poses' sigmas is recovered
when the poses carry extra error, and the joint held-out residual re-estimates the board pose exactly."""

from dataclasses import replace

import numpy as np
import pytest

from calib_core.evaluate.crossval import leave_one_out
from calib_core.evaluate.held_out import held_out_joint, held_out_spread, spread_summary
from calib_core.geometry.transforms import rotvec_to_matrix
from calib_core.refine.camera_side import board_pose_covariances
from simulate import SimOptions, generate


def pixel_problem(trial, n_boards=8, px=0.5, noise_mm=20.0):
    return generate(SimOptions(n_boards=n_boards, pose_mode="pixel", pixel_noise_px=px, noise_mm=noise_mm), 3, trial)


def test_held_out_residuals_match_their_predicted_spread_with_the_board_pose_term():
    with_b, without_b = [], []
    for trial in range(4):
        obs = pixel_problem(trial)
        cv = leave_one_out(obs, "lidarcam")
        assert cv.n_ok == obs.n_boards and cv.spread is not None
        with_b.append(cv.spread.chi2_per_point)
        # the same folds with the board poses taken as exact: the residuals exceed that spread
        parts = [held_out_spread(obs, i, cv.T_lidar_cam[i], np.zeros((6, 6)), 0.02, None) for i in range(obs.n_boards)]
        without_b.append(spread_summary(parts).chi2_per_point)
    assert 0.8 < np.mean(with_b) < 1.25
    assert np.mean(without_b) > 1.5 * np.mean(with_b)


def _shaken(obs, factor, rng):
    """``obs`` with each board pose moved by a draw of ``factor^2`` times its corners' pose covariance."""
    boards = []
    for b, C in zip(obs.boards, board_pose_covariances(obs, 0.5), strict=True):
        x = rng.multivariate_normal(np.zeros(6), factor**2 * C)
        T = b.T_cam_board.copy()
        T[:3, :3] = rotvec_to_matrix(x[:3]) @ T[:3, :3]
        T[:3, 3] += x[3:]
        boards.append(replace(b, T_cam_board=T))
    return replace(obs, boards=tuple(boards))


@pytest.mark.parametrize("factor", [1.0, 6.0])
def test_board_factor_recovers_extra_board_pose_error(factor):
    rng = np.random.default_rng(1)
    parts = []
    for trial in range(6):
        obs = _shaken(pixel_problem(trial, n_boards=10), factor, rng)
        parts += [held_out_spread(obs, i, obs.T_lidar_cam_true, np.zeros((6, 6)), 0.02, 0.5)
                  for i in range(obs.n_boards)]
    s = spread_summary(parts)
    total = np.sqrt(1 + factor**2)   # the PnP poses' own error plus the planted one
    assert s.board_factor == pytest.approx(total, rel=0.25)


def test_joint_held_out_residual_reestimates_the_board_pose_exactly():
    obs = pixel_problem(0, n_boards=6, px=0.0, noise_mm=0.0)
    i = 2
    b = obs.boards[i]
    T = b.T_cam_board.copy()
    T[:3, :3] = rotvec_to_matrix(np.array([0.02, -0.01, 0.015])) @ T[:3, :3]
    T[:3, 3] += [0.01, -0.02, 0.03]
    moved = replace(obs, boards=tuple(replace(x, T_cam_board=T) if k == i else x for k, x in enumerate(obs.boards)))
    ec, er = held_out_joint(moved, i, obs.T_lidar_cam_true, 0.5, 0.02)
    assert np.abs(ec).max() < 1e-6 and np.abs(er).max() < 1e-6
    # a wrong extrinsic leaves residuals the board pose cannot absorb
    T_bad = obs.T_lidar_cam_true.copy()
    T_bad[:3, 3] += [0.05, 0.0, 0.0]
    ec, er = held_out_joint(obs, i, T_bad, 0.5, 0.02)
    assert np.sqrt(np.mean(np.r_[ec.ravel() / 0.5, er / 0.02] ** 2)) > 0.1
