"""The lidarcam CLI verbs: simulate -> calibrate round trip, result JSON contract, bad input exits 2."""

import json

import numpy as np
import pytest

from calib_core import load_result
from lidarcam.cli import main


@pytest.fixture
def obs_file(tmp_path):
    path = tmp_path / "obs.json"
    assert main(["simulate", "--boards", "6", "--noise-mm", "20", "--seed", "1", "--out", str(path)]) == 0
    return path


def test_calibrate_writes_the_result_contract_and_prints_errors_against_ground_truth(obs_file, tmp_path, capsys):
    out, yml = tmp_path / "r.json", tmp_path / "r.yaml"
    assert main(["calibrate", str(obs_file), "--method", "peng2022", "--out", str(out), "--yaml", str(yml)]) == 0
    text = capsys.readouterr().out
    assert "e_R =" in text and "e_t =" in text
    d = json.loads(out.read_text())
    assert d["schema"] == "lidarcam.result/1" and d["method"] == "peng2022" and d["ok"] is True
    assert {"reason", "T_lidar_cam", "T_cam_lidar", "n_candidates", "seconds"} <= set(d)
    T, Ti = np.array(d["T_lidar_cam"]), np.array(d["T_cam_lidar"])
    np.testing.assert_allclose(T @ Ti, np.eye(4), atol=1e-12)
    r = load_result(out)
    np.testing.assert_array_equal(r["T_lidar_cam"], T)
    y = yml.read_text()
    assert "quaternion_xyzw" in y and "maps camera points into the lidar frame" in y


def test_methods_lists_the_registry(capsys):
    assert main(["methods"]) == 0
    text = capsys.readouterr().out
    for name in ("zhang_pless", "zhang_pless_linear", "vasconcelos", "peng2022"):
        assert name in text


def test_a_method_that_cannot_solve_exits_1_with_its_reason(tmp_path, capsys):
    path = tmp_path / "obs.json"
    main(["simulate", "--boards", "3", "--noise-mm", "0", "--out", str(path)])
    assert main(["calibrate", str(path), "--method", "zhang_pless", "--out", str(tmp_path / "r.json")]) == 1
    assert "needs at least 5 boards" in capsys.readouterr().out
    assert json.loads((tmp_path / "r.json").read_text())["ok"] is False


@pytest.mark.parametrize("mutate,needle", [
    (lambda d: d["boards"][1].pop("scan"), "board 1: field 'scan': missing key"),
    (lambda d: d["boards"][2]["T_cam_board"][0].__setitem__(0, 2.0), "board 2: field 'T_cam_board'"),
    (lambda d: d.__setitem__("schema", "other/1"), "field 'schema'"),
])
def test_bad_input_exits_2_with_one_line_naming_file_board_and_field(obs_file, capsys, mutate, needle):
    d = json.loads(obs_file.read_text())
    mutate(d)
    obs_file.write_text(json.dumps(d))
    assert main(["calibrate", str(obs_file)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(obs_file) in err and needle in err, err


def test_missing_file_exits_2(tmp_path, capsys):
    assert main(["calibrate", str(tmp_path / "nope.json")]) == 2
    assert "nope.json" in capsys.readouterr().err


@pytest.mark.parametrize("method", ["lidarcam+ml", "zhang_pless+ml", "vasconcelos+plane", "peng2022/equal",
                                    "zhang_pless_linear+joint"])
def test_every_name_the_registry_accepts_works_on_the_command_line(obs_file, capsys, method):
    assert main(["calibrate", str(obs_file), "--method", method]) in (0, 1)
    assert capsys.readouterr().out.splitlines()[-1] != ""


@pytest.mark.parametrize("argv, needle", [
    (["calibrate", "OBS", "--method", "pengg2022"], "did you mean 'peng2022'?"),
    (["calibrate", "OBS", "--method", "lidarcam+mll"], "did you mean 'lidarcam+ml'?"),
    (["calibrat", "OBS"], "unknown verb 'calibrat'; did you mean 'calibrate'?"),
    (["calibrate", "OBS", "--parent-sensor", "camra"], "did you mean 'camera'?"),
])
def test_a_mistyped_name_is_one_line_with_the_closest_name(obs_file, capsys, argv, needle):
    argv = [str(obs_file) if a == "OBS" else a for a in argv]
    try:
        code = main(argv)
    except SystemExit as exc:   # argparse's own errors leave through exit()
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and needle in err, err


def test_a_contradicted_answer_prints_its_warning_before_ok(tmp_path, capsys):
    path = tmp_path / "obs.json"
    main(["simulate", "--boards", "6", "--noise-mm", "20", "--seed", "1", "--out", str(path)])
    capsys.readouterr()
    assert main(["calibrate", str(path), "--method", "zhang_pless_linear"]) == 0
    out = capsys.readouterr().out.splitlines()
    warn = next(i for i, ln in enumerate(out) if ln.startswith("warning: the data contradict this answer"))
    assert warn < next(i for i, ln in enumerate(out) if ": ok," in ln)


def test_exit_codes_are_in_the_help(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "0 an answer" in text and "1 no answer" in text and "2 bad input" in text and "130 interrupted" in text


def test_ctrl_c_is_one_line_and_exit_130(obs_file, capsys, monkeypatch):
    import calib_core

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(calib_core, "calibrate", interrupted)
    assert main(["calibrate", str(obs_file)]) == 130
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "interrupted" in err


@pytest.mark.parametrize("flag, expect", [("0.3%,2px", [2.4, 2.4, 2.0, 2.0]), ("1,1.5,2,2", [1, 1.5, 2, 2])])
def test_std_intrinsics_flag_makes_the_joint_model_hold_the_intrinsics(tmp_path, capsys, flag, expect):
    from calib_core.data.io import save_observations
    from lidarcam.cli.intrinsics_flag import parse_std_intrinsics
    from simulate import SimOptions, generate

    path = tmp_path / "obs.json"
    save_observations(generate(SimOptions(n_boards=6, pose_mode="pixel", dist_min_m=1.0, dist_max_m=4.0), 2, 0), path)
    np.testing.assert_allclose(parse_std_intrinsics(flag, np.diag([800.0, 800.0, 1.0])), expect)
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "--std-intrinsics", flag, "--out", str(out)]) == 0
    assert "camera intrinsics: estimated" in capsys.readouterr().out
    assert load_result(out)["covariance_model"] == "joint, intrinsics uncertain"
    assert main(["calibrate", str(path), "--out", str(out)]) == 0
    assert "camera intrinsics: taken as exact" in capsys.readouterr().out
    assert main(["calibrate", str(path), "--std-intrinsics", "1,2,3"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--std-intrinsics" in err and "3 values" in err and "\n" not in err
