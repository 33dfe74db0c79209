"""The lidarcam CLI verbs: simulate -> calibrate round trip, result JSON contract, bad input exits 2."""

import json

import numpy as np
import pytest

from calib_core import load_result
from lidarcam_cli import main


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
