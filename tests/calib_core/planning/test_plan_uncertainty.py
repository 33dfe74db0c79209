"""The plan speaks with the calibration's own uncertainty: ``lidarcam plan --from``, the capture verdict of
``extract``/``bag`` and the report's all predict with the calibration's noise model (the per-board systematic error
included: stated, estimated or the prior), start from the covariance the calibration reports and add proposed
boards under the same model."""

import re
from dataclasses import replace

import numpy as np
import pytest

from calib_core import calibrate
from calib_core.data.io import save_observations
from calib_core.geometry.metrics import sigma_rot_deg, sigma_trans_m
from calib_core.planning.capture import predict, set_informations
from calib_core.planning.observed import calibration_widening, plan_from_observations
from simulate import SimOptions, generate

# boards whose planes each carry an error of their own (a range offset per board): the dispersion test widens
SPREAD = SimOptions(n_boards=12, pose_mode="pixel", pixel_noise_px=0.1, noise_mm=5.0, dist_min_m=1.5, dist_max_m=4.0,
                    lidar_board_offset_mm=20.0)


@pytest.fixture(scope="module")
def widened():
    for seed in range(6):
        obs = generate(SPREAD, seed)
        res = calibrate(obs)
        if res.ok and res.info.get("board_dispersion", {}).get("widened"):
            return obs, res
    pytest.fail("no widened calibration in 6 seeds")


def test_the_plan_starts_from_the_calibrations_covariance(widened):
    obs, res = widened
    p = plan_from_observations(obs, res.T_lidar_cam, 3, covariance=res.covariance, info=res.info)
    assert p.plan.current.rot_sigma_deg == pytest.approx(sigma_rot_deg(res.covariance), rel=1e-6)
    assert p.plan.current.trans_sigma_mm == pytest.approx(1000 * sigma_trans_m(res.covariance), rel=1e-6)
    model = plan_from_observations(obs, res.T_lidar_cam, 3, info=res.info)
    assert model.widening == 1.0
    # the model holds the boards' own error (the file's per-board offset): little is left for the widening
    assert model.board_error.offset_m == pytest.approx(obs.board_range_sigma_m)
    assert p.widening < 1.3
    # a proposed board counts for what a captured one did: at the noise stds and scale times the widening
    assert p.range_sigma_m == pytest.approx(model.range_sigma_m * p.widening)
    assert p.board_error.offset_m == pytest.approx(model.board_error.offset_m * p.widening)
    assert p.plan.after[-1].rot_sigma_deg < p.plan.current.rot_sigma_deg


def _unstated(obs):
    return replace(obs, board_range_sigma_m=None)


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("options, unstate, source", [
    (SimOptions(n_boards=10, pose_mode="pixel", noise_mm=10.0, lidar_board_offset_mm=5.0), False, "stated"),
    (SimOptions(n_boards=4, pose_mode="pixel", noise_mm=10.0), True, "prior"),
    (SimOptions(n_boards=8, pose_mode="pixel", noise_mm=10.0, lidar_board_offset_mm=5.0), True, "estimated")])
def test_the_models_prediction_at_the_captured_boards_is_the_calibrations(options, unstate, source, seed):
    """Without the calibration's covariance, the plan's own model (noise and per-board systematic scale from the
    result) predicts the calibration's reported 1-sigma at the boards captured."""
    obs = generate(options, seed)
    obs = _unstated(obs) if unstate else obs
    res = calibrate(obs)
    assert res.ok and res.info["board_error"]["source"] == source
    p = plan_from_observations(obs, res.T_lidar_cam, 2, info=res.info)
    assert p.widening == 1.0 and p.board_error.active
    assert p.plan.current.rot_sigma_deg == pytest.approx(sigma_rot_deg(res.covariance), rel=0.03)
    assert p.plan.current.trans_sigma_mm == pytest.approx(1000 * sigma_trans_m(res.covariance), rel=0.03)
    # without the term the same model would claim a smaller 1-sigma: the term is what the match rests on
    used = obs.subset(res.info.get("boards_used") or range(obs.n_boards))
    bare = predict(set_informations(used, res.T_lidar_cam, p.range_sigma_m, p.corner_sigma_px).sum(axis=0))
    assert bare.rot_sigma_deg < 0.97 * p.plan.current.rot_sigma_deg


def test_widening_is_one_for_the_models_own_covariance_and_scales_as_the_noise(rng):
    A = rng.normal(size=(6, 6))
    S = A @ A.T + np.eye(6)
    assert calibration_widening(S, np.linalg.inv(S)) == pytest.approx(1.0)
    assert calibration_widening(S, 4.0 * np.linalg.inv(S)) == pytest.approx(2.0)
    assert calibration_widening(S, None) == 1.0 and calibration_widening(S, np.full((6, 6), np.nan)) == 1.0
    p = predict(S / 4.0)                                         # the information at twice the noise
    assert p.rot_sigma_deg == pytest.approx(2 * predict(S).rot_sigma_deg)


def test_every_verb_quotes_one_number(widened, tmp_path, capsys):
    from lidarcam.cli import main
    from lidarcam.rig.report import capture_advice

    obs, res = widened
    save_observations(obs, tmp_path / "obs.json")
    assert main(["plan", "--from", str(tmp_path / "obs.json"), "--next", "2"]) == 0
    text = capsys.readouterr().out
    cli = re.search(r"1-sigma: rotation ([\d.]+) deg, translation ([\d.]+) mm", text)
    extract_line = capture_advice(obs)                          # what extract and bag print
    report_line = capture_advice(obs, res.to_dict())            # what the report writes from a result file
    quoted = [re.search(r"give 1-sigma ([\d.]+) deg, (\d+) mm", t) for t in (extract_line, report_line)]
    assert cli and all(quoted)
    assert float(cli.group(1)) == pytest.approx(sigma_rot_deg(res.covariance), abs=1e-3)
    for q in quoted:
        assert float(q.group(1)) == pytest.approx(sigma_rot_deg(res.covariance), abs=0.006)
        assert float(q.group(2)) == pytest.approx(1000 * sigma_trans_m(res.covariance), abs=0.6)
    assert extract_line.split(". (Assumed")[0] in text


@pytest.mark.parametrize("corner_sigma_px", [0.0, 0.5])
def test_the_plans_systematic_part_is_the_calibrations(corner_sigma_px):
    """``set_systematic``'s per-board parts add up to the covariance the calibration holds: the joint model's
    (``refine.systematic.with_systematic``) with corners, the range model's (``refinement_covariance``) without."""
    from calib_core.model.board_error import BoardErrorScale
    from calib_core.model.corners import board_row_offsets, normalised_rows, scan_data_at
    from calib_core.refine.joint import board_informations
    from calib_core.refine.systematic import with_systematic
    from calib_core.refine.uncertainty import refinement_covariance

    obs = generate(SimOptions(n_boards=6, pose_mode="pixel"), 5)
    T, sr, scale = obs.T_lidar_cam_true, 0.02, BoardErrorScale(0.006, 0.003)
    T_b = np.array([b.T_cam_board for b in obs.boards])
    pairs = set_informations(obs, T, sr, corner_sigma_px, board_error=scale)
    got = predict(pairs.sum(axis=0)).covariance
    if corner_sigma_px == 0:
        want = refinement_covariance(scan_data_at(obs, T_b), T, "range", sr, board_error=scale)
    else:
        lin = normalised_rows(obs, T, T_b, corner_sigma_px, sr, True)
        _, Jc, Je, Jb = lin
        oc, os = board_row_offsets(obs)
        H_bb = np.add.reduceat(np.einsum("ra,rb->rab", Jc, Jc), oc) + \
            np.add.reduceat(np.einsum("ra,rb->rab", Jb, Jb), os)
        H_eb = np.add.reduceat(np.einsum("ra,rb->rab", Je, Jb), os)
        C = np.linalg.inv(board_informations(obs, T, T_b, corner_sigma_px, sr).sum(axis=0))
        want = with_systematic(C, scale, scan_data_at(obs, T_b), T, lin, H_eb, H_bb, sr, os)
    np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-14)
    assert np.trace(got) > 1.05 * np.trace(predict(pairs[:, 0].sum(axis=0)).covariance)
