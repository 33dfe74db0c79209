"""Calibrating only what the data determine: mounting parameters (geometry.mounting), calibration with some of
them fixed (calib_core.refine.partial via calibrate(..., fixed=...)) and the CLI's --fix."""

import json

import numpy as np
import pytest
from rigs import VERTICAL_OPTIONS, general_rig, vertical_rig, with_range_noise

from calib_core import calibrate
from calib_core.data.io import save_observations
from calib_core.errors import CalibrationError
from calib_core.geometry.mounting import PARAMS, T_from_params, params_from_T, params_jacobian, parse_fixed
from calib_core.geometry.transforms import rotvec_to_matrix
from calib_core.model.residuals import perturb, range_residuals
from lidarcam.cli import main
from simulate import SimOptions

NOISE_FREE = SimOptions(**{**VERTICAL_OPTIONS.to_dict(), "noise_mm": 0.0})


def _given(theta, names=("roll", "pitch", "z")):
    return {("%s_deg" if PARAMS.index(n) < 3 else "%s_m") % n: float(np.degrees(theta[PARAMS.index(n)])
            if PARAMS.index(n) < 3 else theta[PARAMS.index(n)]) for n in names}


def test_mounting_parameters_round_trip(rng):
    for _ in range(50):
        theta = np.r_[rng.uniform(-np.pi, np.pi), rng.uniform(-1.4, 1.4), rng.uniform(-np.pi, np.pi),
                      rng.normal(size=3)]
        T = T_from_params(theta)
        np.testing.assert_allclose(params_from_T(T), theta, atol=1e-10)
        np.testing.assert_allclose(T_from_params(params_from_T(T)), T, atol=1e-12)
    # all zero: the camera looks along the lidar's x axis, image rows level (camera x -> lidar -y, y -> -z)
    np.testing.assert_allclose(T_from_params(np.zeros(6))[:3, :3], [[0, 0, 1], [-1, 0, 0], [0, -1, 0]])
    # positive yaw turns the optical axis to the left (towards lidar +y); positive pitch looks down
    assert T_from_params(np.r_[0, 0, 0.1, 0, 0, 0])[1, 2] > 0
    assert T_from_params(np.r_[0, 0.1, 0, 0, 0, 0])[2, 2] < 0


def test_params_jacobian_matches_finite_differences(rng):
    obs = general_rig(4)
    for _ in range(5):
        theta = params_from_T(obs.T_lidar_cam_true) + rng.normal(scale=0.05, size=6)
        T = T_from_params(theta)
        _, J = range_residuals(T, obs.scan_data, jacobian=True)
        Jt = J @ params_jacobian(theta)
        h = 1e-7
        for k in range(6):
            d = np.zeros(6)
            d[k] = h
            fd = (range_residuals(T_from_params(theta + d), obs.scan_data)
                  - range_residuals(T_from_params(theta - d), obs.scan_data)) / (2 * h)
            np.testing.assert_allclose(Jt[:, k], fd, rtol=1e-5, atol=1e-6)
        # and the (w, dt) it maps to is the left perturbation of calib_core.model.residuals
        w = params_jacobian(theta) @ d
        np.testing.assert_allclose(perturb(T, w * 1e3)[:3, :3], rotvec_to_matrix(w[:3] * 1e3) @ T[:3, :3])


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("method", ["lidarcam", "vasconcelos+ml"])
def test_planar_calibration_recovers_the_free_parameters_exactly(seed, method):
    obs = vertical_rig(seed, NOISE_FREE)
    truth = params_from_T(obs.T_lidar_cam_true)
    r = calibrate(obs, method, fixed=_given(truth), range_sigma_m=0.005)
    assert r.ok, r.reason
    theta = params_from_T(r.T_lidar_cam)
    np.testing.assert_allclose(theta, truth, atol=1e-9)
    assert r.info["free"] == ["yaw", "x", "y"] and set(r.info["fixed"]) == {"roll_deg", "pitch_deg", "z_m"}
    C = r.info["covariance_mounting"]
    assert np.all(C[[0, 1, 5]] == 0) and np.all(C[:, [0, 1, 5]] == 0) and np.all(np.diag(C)[[2, 3, 4]] > 0)
    assert np.linalg.matrix_rank(r.covariance, tol=1e-12 * np.abs(r.covariance).max()) == 3
    d = r.to_dict()
    assert set(d["mounting_sigma"]) == {"yaw_deg", "x_m", "y_m"} and "not estimated" in d["note"]
    json.dumps(d)


def test_the_given_height_does_not_move_the_planar_part():
    """Vertical boards do not see the height at all: another given z changes nothing else."""
    obs = vertical_rig(3, NOISE_FREE)
    truth = params_from_T(obs.T_lidar_cam_true)
    given = _given(truth)
    a = params_from_T(calibrate(obs, "lidarcam", fixed=given).T_lidar_cam)
    b = params_from_T(calibrate(obs, "lidarcam", fixed={**given, "z_m": given["z_m"] + 0.25}).T_lidar_cam)
    np.testing.assert_allclose(b[:5], a[:5], atol=1e-9)
    assert b[5] == pytest.approx(truth[5] + 0.25)


@pytest.mark.parametrize("seed", range(3))
def test_fixing_other_parameters_on_a_general_rig_recovers_the_rest_exactly(seed):
    obs = general_rig(seed, noise_mm=0.0)
    truth = params_from_T(obs.T_lidar_cam_true)
    r = calibrate(obs, "lidarcam", fixed=_given(truth, ("yaw", "x")), range_sigma_m=0.01)
    assert r.ok, r.reason
    np.testing.assert_allclose(params_from_T(r.T_lidar_cam), truth, atol=1e-8)
    assert r.info["free"] == ["roll", "pitch", "y", "z"]


def test_planar_covariance_matches_the_monte_carlo_spread():
    rng = np.random.default_rng(2024)
    clean = vertical_rig(7, NOISE_FREE)
    truth = params_from_T(clean.T_lidar_cam_true)
    sigma = 0.005
    est, pred = [], None
    for _ in range(200):
        r = calibrate(with_range_noise(clean, sigma, rng), "lidarcam", fixed=_given(truth), range_sigma_m=sigma)
        assert r.ok
        est.append(params_from_T(r.T_lidar_cam)[2:5])
        pred = r.info["covariance_mounting"][2:5, 2:5]
    E = np.array(est) - truth[2:5]
    ratio = np.sqrt(np.diag(np.cov(E.T)) / np.diag(pred))
    assert np.all(np.abs(ratio - 1) < 0.2), ratio                    # 200 draws: the std of a std is ~5 %
    assert np.all(np.abs(E.mean(axis=0)) < 4 * np.sqrt(np.diag(pred) / len(E)))
    nees = np.mean(np.einsum("ij,jk,ik->i", E, np.linalg.inv(pred), E))
    assert 3 * 0.85 < nees < 3 * 1.15


def test_bad_fixed_options_are_one_line_errors():
    with pytest.raises(CalibrationError, match="unknown parameter 'height'"):
        parse_fixed({"height": 0.1})
    with pytest.raises(CalibrationError, match="nothing is left"):
        parse_fixed({k: 0.0 for k in ("roll_deg", "pitch_deg", "yaw_deg", "x_m", "y_m", "z_m")})
    with pytest.raises(CalibrationError, match="must be a number"):
        parse_fixed({"z_m": "high"})
    obs = vertical_rig(0)
    with pytest.raises(CalibrationError, match="fixed"):
        calibrate(obs, "zhang_pless", fixed={"z_m": 0.1})


def test_cli_fix(tmp_path, capsys):
    obs = vertical_rig(4)
    path = tmp_path / "vertical.json"
    save_observations(obs, path)
    assert main(["calibrate", str(path)]) == 1
    assert "not determined" in capsys.readouterr().out
    theta = params_from_T(obs.T_lidar_cam_true)
    fix = f"z={theta[5]:.6f},roll={np.degrees(theta[0]):.6f},pitch_deg={np.degrees(theta[1]):.6f}"
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "--fix", fix, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "z_m" in text and "(fixed, given)" in text and "yaw_deg" in text and "1-sigma" in text
    d = json.loads(out.read_text())
    assert d["ok"] and d["fixed"]["z_m"] == pytest.approx(theta[5], abs=1e-6)
    assert abs(d["mounting"]["yaw_deg"] - np.degrees(theta[2])) < 5 * d["mounting_sigma"]["yaw_deg"]
    assert main(["calibrate", str(path), "--fix", "height=0.1"]) == 2
    assert "--fix" in capsys.readouterr().err
