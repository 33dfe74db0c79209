"""The lower-bound outline's rows in the joint model (calib_core.model.joint_outline): the same residuals as the
polish's at the file's board poses, Jacobians in the extrinsic and in each board's pose against finite differences,
the Gauss-Newton blocks against the dense normal equations, and exact recovery on noise-free rig-like data."""

import numpy as np
import pytest

from calib_core.model.corners import board_poses, board_row_offsets, normalised_rows
from calib_core.model.joint_outline import outline_cost, outline_residuals, outline_rows, with_outline
from calib_core.model.lower_bound import CHORD_CAP, MARGIN_CAP, lower_bound_rows
from calib_core.model.residuals import board_frames, perturb
from calib_core.refine.joint import _blocks, joint_refine
from simulate import SimOptions, generate

RIG = dict(pose_mode="pixel", dist_min_m=1.0, dist_max_m=4.0, board_margin_min_m=0.01, board_margin_max_m=0.08)


def rig(trial, **kw):
    return generate(SimOptions(n_boards=5, **{**RIG, **kw}), seed=21, trial=trial)


def off_caps(r, n):
    """Rows strictly inside their cost caps (chord rows first, then margin rows)."""
    top = np.r_[np.full(2 * n, np.sqrt(2 * CHORD_CAP)), np.full(2 * n, np.sqrt(2 * MARGIN_CAP))]
    return (np.abs(r) < top - 1e-3)


@pytest.mark.parametrize("trial", range(4))
def test_rows_at_the_file_poses_are_the_polishs(trial):
    obs = rig(trial)
    rng = np.random.default_rng(trial)
    T = perturb(obs.T_lidar_cam_true, rng.normal(0, 0.02, 6))
    r, Je, _, _ = outline_rows(obs, T, board_poses(obs))
    rc, Jc, rm, Jm = lower_bound_rows(obs, T, board_frames(obs, T[None]))
    np.testing.assert_allclose(r, np.r_[rc, rm], atol=1e-12)
    np.testing.assert_allclose(Je, np.r_[Jc, Jm], atol=1e-9)


@pytest.mark.parametrize("trial", range(6))
def test_jacobians_match_finite_differences(trial):
    obs = rig(trial)
    rng = np.random.default_rng(50 + trial)
    n = obs.n_boards
    T_e = perturb(obs.T_lidar_cam_true, rng.normal(0, 0.03, 6))
    T_b = board_poses(obs, rng.normal(0, 0.02, (n, 6)))
    r, Je, Jb, board = outline_rows(obs, T_e, T_b)
    assert len(r) == 4 * n and (r != 0).any()
    h = 1e-7
    for k in range(6):
        dx = h * np.eye(6)[k]
        rp, rm = outline_residuals(obs, perturb(T_e, dx), T_b), outline_residuals(obs, perturb(T_e, -dx), T_b)
        ok = off_caps(r, n) & off_caps(rp, n) & off_caps(rm, n)
        np.testing.assert_allclose(Je[ok, k], ((rp - rm) / (2 * h))[ok], rtol=1e-4, atol=1e-4)
        for i in range(n):
            xb = np.zeros((n, 6))
            xb[i] = dx
            rp = outline_residuals(obs, T_e, board_poses(obs, xb, T_b))
            rm = outline_residuals(obs, T_e, board_poses(obs, -xb, T_b))
            ok = off_caps(r, n) & off_caps(rp, n) & off_caps(rm, n)
            np.testing.assert_allclose(np.where(board == i, Jb[:, k], 0.0)[ok], ((rp - rm) / (2 * h))[ok],
                                       rtol=1e-4, atol=1e-4)


def test_blocks_match_the_dense_normal_equations(rng):
    obs = rig(1)
    n = obs.n_boards
    T_e = perturb(obs.T_lidar_cam_true, rng.normal(0, 0.03, 6))
    T_b = board_poses(obs, rng.normal(0, 0.02, (n, 6)))
    lin = normalised_rows(obs, T_e, T_b, 0.5, 0.02, True)
    base = _blocks(obs, board_row_offsets(obs), lin, np.ones(len(lin[0])), None, None)
    g_e, g_b, H_ee, H_eb, H_bb = with_outline(base, obs, T_e, T_b)
    r, Je, Jb, board = outline_rows(obs, T_e, T_b)
    J = np.zeros((len(r), 6 + 6 * n))
    J[:, :6] = Je
    for k, i in enumerate(board):
        J[k, 6 + 6 * i: 12 + 6 * i] = Jb[k]
    H, g = J.T @ J, J.T @ r
    np.testing.assert_allclose(g_e - base[0], g[:6], atol=1e-9)
    np.testing.assert_allclose(H_ee - base[2], H[:6, :6], atol=1e-9)
    for i in range(n):
        s = slice(6 + 6 * i, 12 + 6 * i)
        np.testing.assert_allclose(g_b[i] - base[1][i], g[s], atol=1e-9)
        np.testing.assert_allclose(H_eb[i] - base[3][i], H[:6, s], atol=1e-9)
        np.testing.assert_allclose(H_bb[i] - base[4][i], H[s, s], atol=1e-9)


def test_no_lower_bound_boards_no_rows():
    obs = generate(SimOptions(n_boards=4, pose_mode="pixel"), seed=2)
    assert outline_cost(obs, obs.T_lidar_cam_true, board_poses(obs)) == 0.0
    assert outline_rows(obs, obs.T_lidar_cam_true, board_poses(obs))[0].shape == (0,)


@pytest.mark.parametrize("trial", range(4))
def test_exact_recovery_with_the_outline_terms(trial):
    """Noise-free corners and ranges, a 1-deg / 2-cm start: the truth back, the margin prior's pull notwithstanding
    (the noise stds fall to their floors, where the outline's few rows weigh next to nothing)."""
    obs = rig(trial, noise_mm=0.0, pixel_noise_px=0.0)
    rng = np.random.default_rng(300 + trial)
    j = joint_refine(obs, perturb(obs.T_lidar_cam_true, rng.normal(0, 0.02, 6)), outline=True)
    assert outline_cost(obs, obs.T_lidar_cam_true, board_poses(obs)) > 0  # the terms are there
    np.testing.assert_allclose(j.T_lidar_cam, obs.T_lidar_cam_true, atol=2e-6)
    np.testing.assert_allclose(j.T_cam_board, board_poses(obs), atol=2e-6)
    assert j.converged
