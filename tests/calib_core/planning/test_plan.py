"""The capture planner (calib_core.planning.capture and views; lidarcam.rig.plan_rig; lidarcam plan): per-board
information
against the dense joint information, noise-free views against the simulator, the prediction's handling of
singular sets, the greedy design against random designs, the vertical-boards verdict, the rig YAML and the CLI."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from calib_core.data.io import save_observations
from calib_core.geometry.beams import points_in_polygon
from calib_core.geometry.mounting import T_from_params
from calib_core.geometry.transforms import invert_T
from calib_core.model.board_error import BoardErrorScale
from calib_core.model.corners import normalised_rows
from calib_core.model.residuals import range_residuals
from calib_core.planning.capture import PlanError, greedy, plan_capture, plan_summary, plan_to_dict, pool, predict
from calib_core.planning.views import PlanRig, Workspace, board_poses_lidar, feasibility, noise_free_views
from calib_core.refine.joint import board_informations, joint_crlb
from calib_core.refine.uncertainty import fisher_information
from experiments.suites.plan_check import rig_of
from lidarcam.rig.dataset import DatasetError
from lidarcam.rig.plan_rig import load_plan_rig
from simulate import SimOptions, generate, observe_poses

ROOT = Path(__file__).resolve().parents[3]
RIG_YAML = ROOT / "lidarcam" / "rig" / "plan_template.yaml"
SMALL = Workspace(steps=(2, 5, 1, 3, 3, 1))


MOUNTING = T_from_params(np.r_[np.radians([1.0, 2.0, -1.0]), 0.05, -0.10, 0.12])


def sim_rig(corner_sigma_px: float = 0.5, workspace: Workspace = SMALL) -> PlanRig:
    """The planner's rig of the simulator's defaults (corner noise ``corner_sigma_px``; 0: exact poses)."""
    o = SimOptions(pose_mode="pixel" if corner_sigma_px > 0 else "exact", pixel_noise_px=corner_sigma_px or 0.5)
    return rig_of(o, MOUNTING, workspace)


def test_board_informations_add_up_to_the_dense_joint_information():
    obs = generate(SimOptions(n_boards=5, pose_mode="pixel"), 3, 0)
    T_b = np.array(obs.meta["T_cam_board_true"])
    _, Jc, Je, Jb = normalised_rows(obs, obs.T_lidar_cam_true, T_b, 0.7, 0.02, True)
    N = obs.n_boards
    J = np.zeros((len(Jc) + len(Je), 6 + 6 * N))
    rows_c = np.repeat([i for i, b in enumerate(obs.boards) for _ in range(len(b.corners_px))], 2)
    rows_s = obs.scan_data.board
    for i in range(N):
        J[:len(Jc)][rows_c == i, 6 + 6 * i:12 + 6 * i] = Jc[rows_c == i]
        J[len(Jc):][rows_s == i, 6 + 6 * i:12 + 6 * i] = Jb[rows_s == i]
    J[len(Jc):, :6] = Je
    dense = np.linalg.inv(J.T @ J)[:6, :6]
    S = board_informations(obs, obs.T_lidar_cam_true, T_b, 0.7, 0.02).sum(axis=0)
    np.testing.assert_allclose(np.linalg.inv(S), dense, rtol=1e-6, atol=1e-14)
    np.testing.assert_allclose(np.linalg.inv(S), joint_crlb(obs, 0.02, 0.7, T_cam_board=T_b).cov, rtol=1e-9)


def test_range_only_board_informations_add_up_to_the_fisher_information():
    obs = generate(SimOptions(n_boards=6), 5, 1)
    S = board_informations(obs, obs.T_lidar_cam_true, np.array([b.T_cam_board for b in obs.boards]), 0.0, 0.03)
    np.testing.assert_allclose(S.sum(axis=0), fisher_information(obs, obs.T_lidar_cam_true, 0.03), rtol=1e-10)


def test_board_pose_parameters_place_and_tilt_the_board(rng):
    rig = sim_rig()
    for _ in range(20):
        p = np.r_[rng.uniform(3, 6), rng.uniform(-30, 30), rng.uniform(-0.2, 0.2), rng.uniform(-40, 40, 3)]
        T = board_poses_lidar(rig, p)[0]
        c = T[:3, :3] @ np.r_[rig.outline.mean(axis=0), 0.0] + T[:3, 3]
        assert np.linalg.norm(c) == pytest.approx(p[0])
        assert np.degrees(np.arctan2(c[1], c[0])) == pytest.approx(p[1])
        assert c[2] == pytest.approx(p[2])
        n = T[:3, 2]
        assert n[2] == pytest.approx(-np.sin(np.radians(p[4])), abs=1e-12)   # top away: the back faces down
        np.testing.assert_allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12)
    flat = board_poses_lidar(rig, [[4.0, 10.0, 0.0, 0.0, 0.0, 0.0]])[0]
    los = flat[:3, :3] @ np.r_[rig.outline.mean(axis=0), 0.0] + flat[:3, 3] - rig.T_lidar_cam[:3, 3]
    los[2] = 0.0
    np.testing.assert_allclose(flat[:3, 2], los / np.linalg.norm(los), atol=1e-12)


def test_noise_free_views_lie_on_their_boards_and_match_the_simulator(rng):
    rig = sim_rig()
    grid = rig.workspace.grid()
    reason, ranges, bearings = feasibility(rig, board_poses_lidar(rig, grid))
    ok = np.flatnonzero(reason < 0)[:12]
    T_lb = board_poses_lidar(rig, grid[ok])
    views = noise_free_views(rig, T_lb, ranges[ok], bearings)
    e = range_residuals(rig.T_lidar_cam, views.scan_data)
    assert np.abs(e).max() < 1e-9
    for b, T in zip(views.boards, T_lb, strict=True):
        xy = (invert_T(T)[:3, :3] @ b.scan_3d.T + invert_T(T)[:3, 3:]).T[:, :2]
        assert points_in_polygon(xy, rig.outline).all()
    o = SimOptions(pose_mode="pixel", pixel_noise_px=0.0, noise_mm=0.0)
    sim = observe_poses(o, rig.T_lidar_cam, T_lb, 1, 0)
    for a, b in zip(views.boards, sim.boards, strict=True):
        np.testing.assert_allclose(a.scan, b.scan, atol=1e-9)
        np.testing.assert_allclose(a.corners_px, b.corners_px, atol=1e-9)


def test_feasibility_names_what_fails():
    rig = sim_rig()
    T = board_poses_lidar(rig, [[4.0, 0.0, 0.0, 0.0, 0.0, 0.0], [4.0, 45.0, 0.0, 0.0, 0.0, 0.0],
                                [0.4, 0.0, 0.0, 0.0, 0.0, 0.0], [5.0, 0.0, 0.9, 0.0, 0.0, 0.0]])
    reason = feasibility(rig, T)[0]
    assert reason.tolist() == [-1, 1, 0, 2]
    with pytest.raises(PlanError, match="no board pose"):
        pool(sim_rig(workspace=Workspace(bearing_deg=(70.0, 80.0))))


def test_prediction_inverts_the_information_and_names_what_a_singular_one_leaves_free(rng):
    for _ in range(10):
        A = rng.normal(size=(6, 6))
        F = A @ A.T + 0.1 * np.eye(6)
        p = predict(F)
        np.testing.assert_allclose(p.sigma, np.sqrt(np.diag(np.linalg.inv(F))), rtol=1e-9)
        assert p.rot_sigma_deg == pytest.approx(np.degrees(np.sqrt(np.trace(np.linalg.inv(F)[:3, :3]))))
        # a null direction mixing roll and z: both undetermined, the rest the variance of estimable quantities
        v = np.zeros(6)
        v[[0, 5]] = [0.6, 0.8]
        P = np.eye(6) - np.outer(v, v)
        q = predict(P @ F @ P)
        assert np.isinf(q.sigma[[0, 5]]).all() and np.isfinite(q.sigma[1:5]).all()
        np.testing.assert_allclose(q.sigma[1:5], np.sqrt(np.diag(np.linalg.pinv(P @ F @ P)))[1:5], rtol=1e-6)
        assert q.sigma_dict()["roll_deg"] is None and np.isinf(q.rot_sigma_deg)
    assert np.isinf(predict(np.zeros((6, 6))).sigma).all()


def _d(pair):
    """Minus the log-determinant of a set's covariance (``capture.sandwich`` of its pair ``(H, M)``)."""
    sign, logdet = np.linalg.slogdet(pair[0])
    return 2 * logdet - np.linalg.slogdet(pair[0] + pair[1])[1] if sign > 0 else -np.inf


@pytest.mark.parametrize("offset_mm", [0.0, 5.0])
def test_greedy_d_optimal_design_beats_random_designs(rng, offset_mm):
    rig = replace(sim_rig(), board_error=BoardErrorScale(offset_mm / 1000.0, 0.002 * (offset_mm > 0)))
    _, C = pool(rig)
    assert C.shape[1:] == (2, 6, 6) and bool(C[:, 1].any()) == (offset_mm > 0)
    for k in (3, 5, 8):
        chosen = greedy(np.zeros((6, 6)), C, k)
        assert len(set(chosen)) == k
        best = _d(C[chosen].sum(axis=0))
        rand = [_d(C[rng.choice(len(C), k, replace=False)].sum(axis=0)) for _ in range(200)]
        assert best > np.max(rand)
    S = C[greedy(np.zeros((6, 6)), C, 4)].sum(axis=0)
    z = greedy(S, C, 1, "z")[0]
    var = [predict(S + c).covariance[5, 5] for c in C]
    assert var[z] == pytest.approx(min(var), rel=1e-3)


def test_a_vertical_boards_plan_is_named_degenerate_before_any_data():
    plan = plan_capture(sim_rig(workspace=Workspace(lean_deg=(0.0, 0.0), steps=(2, 5, 1, 5, 1, 1))), 6)
    assert plan.undetermined == ("roll", "pitch", "yaw", "x", "y", "z")
    assert plan.plan_undetermined == ("roll", "pitch", "z")
    assert "not determined" in plan.plan_message and "vertical" in plan.plan_message
    assert plan.after[-1].sigma_dict()["roll_deg"] is None and plan.after[-1].sigma_dict()["yaw_deg"] is not None


def test_plan_predicts_the_joint_bound_of_the_simulated_boards():
    rig = sim_rig()
    plan = plan_capture(rig, 5, target=(0.5, 30.0))
    obs = observe_poses(SimOptions(pose_mode="pixel", pixel_noise_px=0.0, noise_mm=0.0), rig.T_lidar_cam,
                        plan.T_lidar_board, 0, 0)
    bound = joint_crlb(obs, rig.range_sigma_m, rig.corner_sigma_px, T_cam_board=np.array(obs.meta["T_cam_board_true"]))
    assert plan.after[-1].rot_sigma_deg == pytest.approx(bound.rot_rms_deg, rel=1e-6)
    assert plan.after[-1].trans_sigma_mm == pytest.approx(1000 * bound.trans_rms_m, rel=1e-6)
    sig = [p.trans_sigma_mm for p in plan.after + plan.extension if np.isfinite(p.trans_sigma_mm)]
    assert np.all(np.diff(sig) <= 1e-9)                     # each board adds information
    n = plan.to_target
    assert n is not None and (plan.after + plan.extension)[n - 1].meets((0.5, 30.0))
    assert not (plan.after + plan.extension)[n - 2].meets((0.5, 30.0))
    d = plan_to_dict(plan)
    assert set(d["current"]) == {"rot_sigma_deg", "trans_sigma_mm", "sigma", "undetermined"}
    assert len(d["next"]) == 5 and d["next"][-1]["rot_sigma_deg"] == pytest.approx(plan.after[-1].rot_sigma_deg)
    assert f"add {n} boards" in plan_summary(plan)  # no boards yet: the count to the target is n


def test_rig_yaml_reads_and_bad_fields_are_one_line_errors(tmp_path):
    rig = load_plan_rig(RIG_YAML)
    assert rig.range_sigma_m == pytest.approx(0.02) and rig.corner_sigma_px == pytest.approx(0.5)
    assert rig.workspace.lean_deg == (-40.0, 40.0) and rig.corners_board.shape == (30, 3)
    text = RIG_YAML.read_text()
    for old, new, what in (("range_sigma_mm: 20.0", "range_sigma_mm: fast", "lidar.range_sigma_mm"),
                           ("distance_m: [3.0, 6.0]", "distance_m: [6.0, 3.0]", "workspace.distance_m"),
                           ("z_m: 0.12", "height_m: 0.12", "mounting"), ("cols: 6", "cols: x", "cols")):
        bad = tmp_path / "bad.yaml"
        bad.write_text(text.replace(old, new))
        with pytest.raises(DatasetError, match=what) as err:
            load_plan_rig(bad)
        assert str(bad) in str(err.value) and "\n" not in str(err.value)


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "lidarcam.cli", *args], capture_output=True, text=True, cwd=cwd)


def test_cli_plans_from_a_rig_and_from_observations(tmp_path):
    out = tmp_path / "plan.json"
    r = _cli("plan", str(RIG_YAML), "--next", "3", "--json", str(out), "--figure", str(tmp_path / "p.png"),
             cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    d = json.loads(out.read_text())
    assert d["current"]["undetermined"] == ["roll", "pitch", "yaw", "x", "y", "z"] and len(d["next"]) == 3
    assert "checklist" in r.stdout and (tmp_path / "p.png").stat().st_size > 10_000
    obs = tmp_path / "obs.json"
    save_observations(generate(SimOptions(n_boards=6, pose_mode="pixel"), 2, 0), obs)
    r = _cli("plan", "--from", str(obs), "--next", "2", "--json", str(out), "--criterion", "height", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    d = json.loads(out.read_text())
    assert d["current"]["undetermined"] == [] and d["current"]["sigma"]["z_mm"] > 0 and len(d["next"]) == 2
    assert d["next"][1]["sigma"]["z_mm"] < d["current"]["sigma"]["z_mm"]
    bad = tmp_path / "bad.yaml"
    bad.write_text(RIG_YAML.read_text().replace("fov_deg: 180.0", "fov_deg: -3"))
    r = _cli("plan", str(bad), cwd=tmp_path)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "bad.yaml" in r.stderr


@pytest.mark.slow
def test_predicted_sigma_matches_the_spread_of_the_calibration():
    from calib_core import calibrate
    from calib_core.geometry.metrics import pose_errors

    rig = sim_rig(corner_sigma_px=0.0)
    plan = plan_capture(rig, 8)
    o = SimOptions(pose_mode="exact")
    e = np.array([pose_errors(calibrate(observe_poses(o, rig.T_lidar_cam, plan.T_lidar_board, 7, r)).T_lidar_cam,
                              rig.T_lidar_cam) for r in range(60)])
    rms_deg, rms_mm = np.sqrt(np.mean(e[:, 0] ** 2)), 1000 * np.sqrt(np.mean(e[:, 1] ** 2))
    assert rms_deg / plan.after[-1].rot_sigma_deg == pytest.approx(1.0, abs=0.3)
    assert rms_mm / plan.after[-1].trans_sigma_mm == pytest.approx(1.0, abs=0.3)


def test_the_calibration_report_ends_with_the_planners_verdict(tmp_path):
    from calib_core import calibrate
    from lidarcam.rig.report import write_report

    obs = generate(SimOptions(n_boards=5, pose_mode="pixel"), 4, 0)
    md = write_report(None, obs, calibrate(obs), tmp_path).markdown.read_text()
    tail = md[md.index("## Capture plan"):]
    assert "5 boards give 1-sigma" in tail and "the weakest is" in tail
    m = re.search(r"add (\d+) boards?[^(]*\((\d+) boards in all", tail)
    assert (m and int(m.group(2)) == 5 + int(m.group(1))) or "is not reached within" in tail, tail


def test_plan_check_removes_cells_of_other_code_and_keys_on_the_code(tmp_path, monkeypatch):
    import json

    from experiments.suites import plan_check

    cells = tmp_path / "cells"
    cells.mkdir()
    (cells / "old.json").write_text(json.dumps({"key": "old", "rot_err": [1.0]}) + "\n")  # before fingerprints
    (cells / "other.json").write_text(json.dumps({"key": "other", "code": "x+y"}) + "\n")
    (cells / "torn.json").write_text('{"key": "to')
    (cells / "same.json").write_text(json.dumps({"key": "same", "code": plan_check._code()}) + "\n")
    assert plan_check._drop_stale(cells) == 3
    assert [f.name for f in cells.iterdir()] == ["same.json"]
    task = {"part": "prediction", "mode": "planned", "boards": 4, "set": 0}
    key = plan_check._key(task)
    assert key != plan_check._key({**task, "boards": 8})
    monkeypatch.setattr(plan_check, "_code", lambda: "edited+code")
    assert plan_check._key(task) != key  # the same settings under other code: another cell


@pytest.mark.parametrize("k", [1, 2, 6])
@pytest.mark.parametrize("given", [0, 12])
@pytest.mark.parametrize("target", [(0.1, 5.0), (0.5, 20.0), (0.01, 0.5)])
def test_the_verdict_adds_as_many_boards_as_the_plan_needs(k, given, target):
    """"add N boards" is the plan's own count to the target, "M boards in all" is the current boards plus N, and
    the poses named are the plan's first ones."""
    from calib_core.planning.capture import boards_to_add, describe_pose

    rig = load_plan_rig(RIG_YAML)
    from calib_core.planning.capture import set_informations

    current = generate(SimOptions(n_boards=given), seed=2) if given else None
    info = set_informations(current, rig.T_lidar_cam, rig.range_sigma_m, 0.0) if given else None
    plan = plan_capture(rig, k, current=current, current_info=info, target=target)
    if plan.current.meets(target):
        pytest.skip("the given boards meet this target")
    text = plan_summary(plan)
    need = boards_to_add(plan)
    if need is None:  # out of reach: the sentence says so and names the proposed poses, adding no count
        said = "limited by the per-board systematic error" if plan.limited_by_systematic else "is not reached within"
        assert said in text and "add " not in text, text
        assert all(describe_pose(q) in text for q in plan.poses)
        return
    m = re.search(r"add (\d+) boards?", text)
    assert m and need >= 1 and int(m.group(1)) == need, text
    assert f"({plan.current_n + need} boards in all" in text
    named = [describe_pose(q) for q in plan.poses[:need]]
    assert all(d in text for d in named) and len(named) == min(k, need)
    ahead = [p.meets(target) for p in plan.after]
    if need <= k:  # the table shows it: the need-th proposed board is the first that meets the target
        assert ahead.index(True) == need - 1


def test_plan_figure_labels_do_not_overlap():
    """Boards proposed at one place with different tilts share one label; every board is numbered once."""
    from lidarcam.rig.plan_figure import LABEL_MERGE_M, _board_xy, label_groups

    rig = load_plan_rig(RIG_YAML)
    plan = plan_capture(rig, 25)  # more boards than distinct places in the workspace: some share one
    centres = _board_xy(plan.T_lidar_board, rig.outline)[:, :-1].mean(axis=1)
    d = np.linalg.norm(centres[:, None] - centres[None], axis=-1)[np.triu_indices(len(centres), 1)]
    assert d.min() < LABEL_MERGE_M  # this plan has boards at one place: one label each would overlap
    labels = label_groups(centres)
    numbers = [int(n) for _, text in labels for n in text.split(", ")]
    assert sorted(numbers) == list(range(1, len(centres) + 1))
    pos = np.array([p for p, _ in labels])
    apart = np.linalg.norm(pos[:, None] - pos[None], axis=-1)[np.triu_indices(len(pos), 1)]
    assert (apart >= LABEL_MERGE_M).all()


def test_one_noise_rule_for_the_cli_plan_and_the_capture_verdict(tmp_path, capsys):
    """``lidarcam plan --from`` and the capture verdict of extract/bag/report assume the same noise
    (``calib_core.planning.observed.observation_noise``) and give the same verdict."""
    from calib_core import calibrate
    from calib_core.planning.observed import DEFAULT_CORNER_SIGMA_PX, observation_noise
    from lidarcam.cli import main
    from lidarcam.rig.report import capture_advice

    obs = generate(SimOptions(n_boards=6, pose_mode="pixel"), 1, 0)
    res = calibrate(obs)
    assert res.ok and res.info.get("corner_sigma_px")
    sr, sc, source = observation_noise(obs, res.info)
    assert sc == pytest.approx(res.info["corner_sigma_px"]) and "calibration" in source
    save_observations(obs, tmp_path / "obs.json")
    assert main(["plan", "--from", str(tmp_path / "obs.json"), "--next", "2"]) == 0
    text = capsys.readouterr().out
    cli = re.search(r"range noise ([\d.]+) mm, corner noise ([\d.]+) px", text)
    rig = re.search(r"Assumed noise: range ([\d.]+) mm, corners ([\d.]+) px", capture_advice(obs))
    assert cli and rig and cli.groups() == rig.groups(), (cli.groups(), rig.groups())
    assert capture_advice(obs).split(". (Assumed")[0] in text  # the same verdict
    bare = type(obs)(obs.boards, obs.T_lidar_cam_true, {}, obs.camera)  # no calibration, no reprojection RMS
    assert observation_noise(bare)[1] == DEFAULT_CORNER_SIGMA_PX


def test_summary_lines_have_a_row_per_proposed_pose_and_the_verdict():
    from calib_core.planning.capture import describe_pose

    rig = load_plan_rig(RIG_YAML)
    plan = plan_capture(rig, 3)
    lines = plan.summary_lines(rig)
    rows = [ln for ln in lines if re.match(r"^\s*\d+\s+[\d.]+\s+-?[\d.]+", ln)]
    assert len(rows) == 3
    assert lines[-1] == f"verdict: {plan_summary(plan)}"
    assert all(any(describe_pose(q) in ln for ln in lines) for q in plan.poses)
