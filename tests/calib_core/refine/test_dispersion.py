"""The boards' dispersion test and the widened covariance (calib_core.refine.dispersion): the statistic's law
under the model on many seeded linear instances, the one-step jackknife against explicit leave-one-out refits,
the Loewner maximum's properties, and on simulated rigs whose boards carry error the model does not hold, a
covariance that holds the empirical spread where the model's does not."""

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from calib_core import calibrate
from calib_core.data.observations import Observations
from calib_core.methods.last_steps import widened_range_covariance
from calib_core.refine.dispersion import (
    DISPERSION_ALPHA,
    dispersion,
    jackknife_covariance,
    loewner_max,
    widened_covariance,
)
from simulate import SimOptions, generate


def linear_boards(rng, n_boards, board_sigma=0.0, points=30):
    """A linear model with boards as clusters: board i sees x (6,) through a rank-2 design ``A_i = B_i C_i``
    (a scan line on a plane constrains two directions), unit noise per row, and a per-board error of std
    ``board_sigma`` along its two directions. Returns (designs, data, truth)."""
    x = rng.normal(size=6)
    A, y = [], []
    for _ in range(n_boards):
        Ai = rng.normal(size=(points, 2)) @ rng.normal(size=(2, 6))
        bias = Ai @ np.linalg.pinv(Ai) @ (Ai @ rng.normal(0, board_sigma, 6)) if board_sigma else 0.0
        A.append(Ai)
        y.append(Ai @ x + rng.normal(size=points) + bias)
    return A, y, x


def scores(A, y):
    """LS answer, the boards' scores at it and their informations."""
    xh = np.linalg.lstsq(np.vstack(A), np.concatenate(y), rcond=None)[0]
    g = np.array([Ai.T @ (Ai @ xh - yi) for Ai, yi in zip(A, y, strict=True)])
    S_i = np.array([Ai.T @ Ai for Ai in A])
    return xh, g, S_i


def test_statistic_is_chi_square_under_the_model(rng):
    ratios, alarms = [], 0
    n = 1500
    for _ in range(n):
        _, g, S_i = scores(*linear_boards(rng, 8)[:2])
        d = dispersion(g, S_i)
        assert d.dof == 2 * 8 - 6
        ratios.append(d.ratio)
        alarms += d.widened
    assert abs(np.mean(ratios) - 1.0) < 0.05
    # false alarms at the stated rate: within a 5-sigma binomial band
    assert abs(alarms / n - DISPERSION_ALPHA) < 5 * np.sqrt(DISPERSION_ALPHA * (1 - DISPERSION_ALPHA) / n)


def test_three_boards_are_not_testable(rng):
    _, g, S_i = scores(*linear_boards(rng, 3)[:2])
    d = dispersion(g, S_i)
    assert d.dof == 0 and not d.widened and d.p_value == 1.0
    cov = np.eye(6)
    assert widened_covariance(cov, g, S_i)[0] is cov


def test_one_step_jackknife_is_exact_leave_one_out_for_a_linear_model(rng):
    for _ in range(20):
        A, y, _ = linear_boards(rng, int(rng.integers(5, 12)), board_sigma=0.5)
        xh, g, S_i = scores(A, y)
        folds = np.array([np.linalg.lstsq(np.vstack(A[:i] + A[i + 1:]), np.concatenate(y[:i] + y[i + 1:]),
                                          rcond=None)[0] for i in range(len(A))])
        d = folds - folds.mean(axis=0)
        expected = (len(A) - 1) / len(A) * d.T @ d
        np.testing.assert_allclose(jackknife_covariance(g, S_i), expected, rtol=1e-8, atol=1e-12)


def random_spd(rng, rank=6):
    M = rng.normal(size=(6, rank)) * 10 ** rng.uniform(-3, 0, rank)
    return M @ M.T


def test_loewner_max_covers_both_and_is_the_least_in_the_whitened_frame(rng):
    for _ in range(200):
        A, B = random_spd(rng) + 1e-9 * np.eye(6), random_spd(rng, int(rng.integers(1, 7)))
        C = loewner_max(A, B)
        scale = np.abs(C).max()
        assert np.linalg.eigvalsh(C - A).min() > -1e-9 * scale
        assert np.linalg.eigvalsh(C - B).min() > -1e-9 * scale
        np.testing.assert_allclose(loewner_max(A, 0.5 * A), A, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(loewner_max(A, 2.0 * A), 2.0 * A, rtol=1e-9, atol=1e-15)


def test_widened_covariance_holds_the_spread_of_board_level_error(rng):
    """Board-level error beyond the model: the model's covariance is far too small (NEES >> 6), the widened
    one holds the spread (NEES median near 6)."""
    model, wide = [], []
    for _ in range(400):
        A, y, x = linear_boards(rng, 12, board_sigma=3.0)
        xh, g, S_i = scores(A, y)
        cov = np.linalg.inv(S_i.sum(axis=0))
        w, d = widened_covariance(cov, g, S_i)
        e = xh - x
        model.append(e @ np.linalg.solve(cov, e))
        wide.append(e @ np.linalg.solve(w, e))
        assert d.widened or d.p_value >= DISPERSION_ALPHA
    assert np.median(model) > 20
    assert 3.5 < np.median(wide) < 8.0


def planes_moved(obs: Observations, rng, rot_deg: float, offset_m: float) -> Observations:
    """Every board's scan turned about its centre in the scan plane by a random angle (std ``rot_deg``) and moved
    along its normal by a random offset (std ``offset_m``): the plane the lidar meets is not where the camera sees
    the board (a bent board, a range bias of its surface), by an error of its own; the scatter within the board does
    not change."""
    boards = []
    for b in obs.boards:
        c = b.scan.mean(axis=0)
        u = np.linalg.svd(b.scan - c)[2][0]
        a = np.radians(rng.normal(0, rot_deg))
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        boards.append(replace(b, scan=(b.scan - c) @ R.T + c + rng.normal(0, offset_m) * np.array([-u[1], u[0]])))
    return replace(obs, boards=tuple(boards))


def nees(res, truth):
    dR = res.T_lidar_cam[:3, :3] @ truth[:3, :3].T
    e = np.r_[Rotation.from_matrix(dR).as_rotvec(), res.T_lidar_cam[:3, 3] - truth[:3, 3]]
    return float(e @ np.linalg.solve(res.covariance, e))


def test_joint_step_widens_on_board_level_error_and_names_it(rng):
    """``zhang_pless+joint`` (no board is left out): planes moved per board, beyond the noise model."""
    opts = SimOptions(n_boards=10, pose_mode="pixel", noise_mm=5.0, dist_min_m=1.0, dist_max_m=3.0)
    model, wide, fired = [], [], 0
    for t in range(30):
        obs = planes_moved(generate(opts, seed=11, trial=t), rng, 0.5, 0.01)
        res = calibrate(obs, "zhang_pless+joint", verdict=False)
        assert res.ok, res.reason
        disp = res.info["board_dispersion"]
        fired += disp["widened"]
        if disp["widened"]:
            assert any("boards disagree beyond the noise model" in w and "board " in w for w in res.warnings)
        wide.append(nees(res, obs.T_lidar_cam_true))
        model.append(nees(calibrate(obs, "zhang_pless+joint", widen=False, verdict=False), obs.T_lidar_cam_true))
    assert fired >= 27
    assert np.median(model) > 30
    assert 2.0 < np.median(wide) < 12.0


def test_lidarcam_keeps_the_model_covariance_when_the_boards_agree():
    opts = SimOptions(n_boards=6, pose_mode="pixel")
    fired = 0
    for t in range(20):
        obs = generate(opts, seed=3, trial=t)
        res = calibrate(obs, "lidarcam")
        d = res.info["board_dispersion"]
        fired += d["widened"]
        if not d["widened"]:
            np.testing.assert_array_equal(res.covariance, calibrate(obs, "lidarcam", widen=False).covariance)
    assert fired <= 2


def test_range_model_widens_on_board_level_error(rng):
    """The range model's covariance (board poses taken as exact) through the same test, on ``zhang_pless+ml``."""
    opts = SimOptions(n_boards=10, noise_mm=5.0, dist_min_m=1.0, dist_max_m=3.0)
    model, wide, fired = [], [], 0
    for t in range(30):
        obs = planes_moved(generate(opts, seed=5, trial=t), rng, 0.3, 0.005)
        res = calibrate(obs, "zhang_pless+ml", verdict=False)
        cov, disp, _ = widened_range_covariance(obs, res.T_lidar_cam, res.covariance, None)
        fired += disp["widened"]
        model.append(nees(res, obs.T_lidar_cam_true))
        wide.append(nees(replace(res, covariance=cov), obs.T_lidar_cam_true))
    assert fired >= 27
    assert np.median(model) > 30
    assert 2.0 < np.median(wide) < 12.0
    few = generate(SimOptions(n_boards=3), seed=5)
    cov, disp, warnings = widened_range_covariance(few, few.T_lidar_cam_true, np.eye(6), 0.02)
    assert disp is None and warnings == [] and np.array_equal(cov, np.eye(6))
