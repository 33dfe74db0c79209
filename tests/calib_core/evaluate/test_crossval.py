"""Leave-one-pose-out cross-validation (calib_core.evaluate.crossval)."""

import json

import numpy as np
from rigs import general_rig, vertical_rig

from calib_core.data.observations import BoardObservation, Observations
from calib_core.evaluate.crossval import held_out_residuals, leave_one_out
from calib_core.geometry.mounting import params_from_T
from calib_core.geometry.transforms import make_T


def test_clean_rig_held_out_rms_is_the_noise():
    obs = general_rig(1, n_boards=7, noise_mm=10.0)
    cv = leave_one_out(obs, "lidarcam", range_sigma_m=0.01)
    assert cv.n_ok == 7 and all(r is None for r in cv.reasons)
    assert 0.9 < cv.overall_rms_sigmas < 1.2
    assert np.all((cv.rms_sigmas > 0.6) & (cv.rms_sigmas < 1.6))
    # in mm: the point-to-plane noise of these beams, sigma |m . b|, at the truth
    f = np.concatenate([held_out_residuals(obs, i, obs.T_lidar_cam_true)[1] for i in range(obs.n_boards)])
    assert cv.overall_rms_mm == __import__("pytest").approx(10.0 * np.sqrt(np.mean(f**2)), rel=0.2)
    # the unit defaults to the noise estimated from the scan lines
    assert abs(leave_one_out(obs, "lidarcam+ml").range_sigma_m - 0.01) < 0.002
    d = cv.to_dict()
    json.dumps(d)
    assert d["n_ok"] == 7 and len(d["poses"]) == 7 and d["range_sigma_mm"] == 10.0


def test_noise_free_rig_has_zero_held_out_residual():
    obs = general_rig(2, n_boards=5, noise_mm=0.0)
    cv = leave_one_out(obs, "lidarcam", range_sigma_m=0.01)
    assert cv.n_ok == 5 and cv.overall_rms_mm < 1e-6


def test_a_pose_whose_camera_plane_is_off_shows():
    obs = general_rig(3, n_boards=7, noise_mm=10.0)
    b = obs.boards[2]
    shifted = BoardObservation(b.T_cam_board @ make_T(np.eye(3), [0.0, 0.0, 0.08]), b.outline, b.scan)
    bad = Observations(obs.boards[:2] + (shifted,) + obs.boards[3:], obs.T_lidar_cam_true)
    clean = leave_one_out(obs, "lidarcam", range_sigma_m=0.01)
    cv = leave_one_out(bad, "lidarcam", range_sigma_m=0.01)
    # held out, the shifted board sits off its plane by a bias; trained on, it spoils the other folds too
    assert cv.rms_sigmas[2] > 4 and abs(cv.mean_mm[2]) > 30 and abs(clean.mean_mm[2]) < 10
    assert cv.overall_rms_sigmas > 3 * clean.overall_rms_sigmas


def test_failed_folds_are_recorded_with_their_reason():
    obs = general_rig(4, n_boards=5, noise_mm=10.0)
    cv = leave_one_out(obs, "zhang_pless")
    assert cv.n_ok == 0 and all("at least 5 boards" in r for r in cv.reasons)
    assert np.isnan(cv.overall_rms_mm) and json.dumps(cv.to_dict())


def test_options_reach_every_fold():
    obs = vertical_rig(2)
    assert leave_one_out(obs, "lidarcam").n_ok == 0
    theta = params_from_T(obs.T_lidar_cam_true)
    fixed = {"roll_deg": np.degrees(theta[0]), "pitch_deg": np.degrees(theta[1]), "z_m": theta[5]}
    cv = leave_one_out(obs, "lidarcam", fixed=fixed)
    assert cv.n_ok == obs.n_boards and 0.7 < cv.overall_rms_sigmas < 1.4 and cv.options == {"fixed": fixed}
