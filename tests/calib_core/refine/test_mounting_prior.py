"""The mounting prior in the joint model and in the search: its rows' gradient, the posterior's mode between the
data's answer and the prior's pose, at three boards an answer that keeps fitting the data when the guess is rough,
and the guess as a start where the minimal solver finds none."""

from __future__ import annotations

import numpy as np
import pytest

from calib_core import calibrate
from calib_core.geometry.metrics import pose_errors, sigma_rot_deg, sigma_trans_m
from calib_core.geometry.mounting import MountingPrior
from calib_core.model.prior import mounting_cost, with_mounting
from calib_core.model.residuals import perturb
from calib_core.refine.joint import joint_refine
from simulate import SimOptions, generate


@pytest.mark.parametrize("seed", range(5))
def test_mounting_rows_gradient_and_information_match_finite_differences(seed):
    rng = np.random.default_rng(seed)
    T0 = perturb(np.eye(4), rng.normal(scale=[0.5] * 3 + [0.2] * 3))
    T = perturb(T0, rng.normal(scale=[0.3] * 3 + [0.1] * 3))
    prior = MountingPrior(T0, np.radians(rng.uniform(2, 20)), rng.uniform(0.01, 0.1))
    zero = (np.zeros(6), np.zeros((2, 6)), np.zeros((6, 6)), np.zeros((2, 6, 6)), np.eye(6)[None].repeat(2, 0))
    g, _, H, _, _ = with_mounting(zero, prior, T)
    h = 1e-6
    fd = [(mounting_cost(prior, perturb(T, h * e)) - mounting_cost(prior, perturb(T, -h * e))) / (2 * h)
          for e in np.eye(6)]
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-6)
    J = prior.jacobian(T)
    np.testing.assert_allclose(H, J.T @ J)
    assert mounting_cost(None, T) == 0.0 and np.isclose(mounting_cost(prior, T0), 0.0, atol=1e-20)


@pytest.mark.parametrize("trial", range(3))
def test_joint_mode_between_the_data_and_the_prior(trial):
    obs = generate(SimOptions(n_boards=5, pose_mode="pixel"), seed=3, trial=trial)
    T0 = obs.T_lidar_cam_true
    plain = joint_refine(obs, T0)
    away = perturb(plain.T_lidar_cam, np.r_[0.05, -0.03, 0.04, 0.03, -0.02, 0.02])
    weak = joint_refine(obs, T0, mounting=MountingPrior(away, np.radians(90), 100.0))
    e_R, e_t = pose_errors(weak.T_lidar_cam, plain.T_lidar_cam)   # the same optimum, to the solver's tolerance
    assert e_R < 0.05 * sigma_rot_deg(plain.covariance) and e_t < 0.05 * sigma_trans_m(plain.covariance), (e_R, e_t)
    strong = joint_refine(obs, T0, mounting=MountingPrior(away, np.radians(1e-4), 1e-6))
    assert pose_errors(strong.T_lidar_cam, away)[0] < 1e-3 and pose_errors(strong.T_lidar_cam, away)[1] < 1e-5
    mid = joint_refine(obs, T0, mounting=MountingPrior(away, np.radians(0.5), 0.01))
    d_data, d_prior = pose_errors(mid.T_lidar_cam, plain.T_lidar_cam), pose_errors(mid.T_lidar_cam, away)
    total = pose_errors(plain.T_lidar_cam, away)
    assert d_data[0] < total[0] and d_prior[0] < total[0] and d_data[1] < total[1] and d_prior[1] < total[1]


def test_a_rough_guess_at_three_boards_does_not_pull_the_answer_off_the_data():
    """A guess a few of its sigmas off, where three boards leave a direction weak: the answer is the posterior's
    mode, which fits the boards (the verdict finds them consistent), not a linear step towards the guess."""
    refused, off = 0, []
    for trial in range(12):
        obs = generate(SimOptions(n_boards=3, pose_mode="pixel"), seed=21, trial=trial)
        rng = np.random.default_rng(trial)
        guess = perturb(obs.T_lidar_cam_true, np.r_[rng.normal(scale=np.radians(15), size=3),
                                                    rng.normal(scale=0.075, size=3)])
        res = calibrate(obs, "lidarcam", prior=MountingPrior(guess, np.radians(10), 0.05))
        if not res.ok:
            refused += "contradict" in res.reason
            continue
        off.append(pose_errors(res.T_lidar_cam, obs.T_lidar_cam_true)[0])
    assert refused == 0, refused
    assert len(off) >= 7 and np.median(off) < 3.0, off


def test_the_guess_is_a_start_where_the_minimal_solver_has_none():
    from calib_core.robust.hypotheses import hypotheses

    answered = 0
    for trial in (3, 7, 9):  # three boards whose triple has no real solution
        obs = generate(SimOptions(n_boards=3, pose_mode="pixel"), seed=21, trial=trial)
        assert len(hypotheses(obs, 0.01, 0.1).T) == 0
        guess = perturb(obs.T_lidar_cam_true, np.r_[np.radians([6.0, -4.0, 5.0]), 0.04, -0.03, 0.02])
        H = hypotheses(obs, 0.01, 0.1, guess=guess)
        assert len(H.T) == 1 and np.array_equal(H.T[0], guess) and H.within(np.zeros(3, bool))[0]
        assert "no candidate" in calibrate(obs, "lidarcam").reason
        res = calibrate(obs, "lidarcam", prior=MountingPrior(guess, np.radians(10), 0.05))
        if res.ok:
            answered += 1
            # nearer the truth than the guess: the data moved it
            assert pose_errors(res.T_lidar_cam, obs.T_lidar_cam_true)[1] < pose_errors(guess, obs.T_lidar_cam_true)[1]
    assert answered >= 2


@pytest.mark.parametrize("mode", ["exact", "pixel"])
def test_covariance_with_a_prior_holds_the_spread_at_three_boards(mode):
    """Guesses drawn with the stated sigmas around the truth: every three-board trial answered, and the NEES of the
    posterior covariance about chi-square(6) (median 5.35)."""
    from calib_core.geometry.transforms import matrix_to_rotvec

    nees = []
    for t in range(40):
        obs = generate(SimOptions(n_boards=3, pose_mode=mode), seed=5, trial=t)
        rng = np.random.default_rng(1000 + t)
        G = obs.T_lidar_cam_true
        guess = perturb(G, np.r_[rng.normal(scale=np.radians(10), size=3), rng.normal(scale=0.05, size=3)])
        res = calibrate(obs, "lidarcam", prior=MountingPrior(guess, np.radians(10), 0.05))
        assert res.ok, res.reason
        T = res.T_lidar_cam
        d = np.r_[matrix_to_rotvec(G[:3, :3] @ T[:3, :3].T), G[:3, 3] - T[:3, 3]]
        nees.append(d @ np.linalg.solve(res.covariance, d))
    assert 3.5 < np.median(nees) < 8.0, np.median(nees)
    assert np.mean(np.array(nees) > 16.8) < 0.1      # chi-square(6)'s 99% quantile: 1% expected


def test_vertical_boards_with_a_prior_hold_roll_pitch_and_height_at_it():
    """Every board vertical leaves roll, pitch and z free: without a prior ``lidarcam`` refuses
    (tests/calib_core/checks/test_degeneracy.py); with one drawn at its stated sigmas around the truth it holds those
    at the prior's
    values, calibrates the rest, says so, and its covariance carries the prior's uncertainty through the fit
    (NEES median between 1.5 and 9: the free parameters respond to the held ones at second order, not as a Gaussian)."""
    from rigs import vertical_rig

    from calib_core.geometry.metrics import nees

    rng = np.random.default_rng(5)
    s_rot, s_t = np.radians(5.0), 0.03
    values = []
    for seed in range(16):
        obs = vertical_rig(seed)
        T_true = obs.T_lidar_cam_true
        guess = perturb(T_true, np.r_[rng.normal(0, s_rot, 3), rng.normal(0, s_t, 3)])
        r = calibrate(obs, "lidarcam", prior=MountingPrior(guess, s_rot, s_t))
        assert r.ok, r.reason
        assert any("from the mounting prior" in w for w in r.warnings)
        assert sorted(r.info["fixed"]) == ["pitch_deg", "roll_deg", "z_m"]
        assert np.linalg.matrix_rank(r.covariance) == 6
        values.append(nees(r.T_lidar_cam, T_true, r.covariance))
    assert 1.5 < np.median(values) < 9.0


def test_the_summary_says_which_axes_the_prior_holds():
    from rigs import vertical_rig

    obs = vertical_rig(3)
    T = obs.T_lidar_cam_true
    r = calibrate(obs, "lidarcam", prior=MountingPrior(perturb(T, np.r_[0.03, -0.02, 0.01, 0.02, 0.01, -0.02]),
                                                       np.radians(5.0), 0.03))
    lines = r.summary_lines()
    for k in ("roll_deg", "pitch_deg", "z_m"):
        line = next(ln for ln in lines if ln.strip().startswith(k))
        assert "held at the mounting prior's value" in line and "1-sigma" in line
    assert "held" not in next(ln for ln in lines if ln.strip().startswith("yaw_deg"))
