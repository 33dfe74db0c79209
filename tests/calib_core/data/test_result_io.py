"""``CalibrationResult.load`` reads back what ``save`` wrote (``load_result`` still gives the dict), and
``to_yaml`` is the one content of ``lidarcam calibrate --yaml`` and the report's ``extrinsic.yaml``."""

from __future__ import annotations

import json

import pytest

import calib_core
from calib_core import load_result
from calib_core.data.io import save_observations
from calib_core.data.result import CalibrationResult
from lidarcam.cli import main
from simulate import SimOptions, generate


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("result")
    obs = generate(SimOptions(n_boards=6), seed=3)
    res = calib_core.calibrate(obs)
    assert res.ok and res.covariance is not None
    save_observations(obs, tmp / "obs.json")
    return tmp, obs, res


@pytest.mark.parametrize("method", ["lidarcam", "peng2022", "zhang_pless_linear"])
def test_load_reads_back_what_save_wrote(method, solved, tmp_path):
    _, obs, _ = solved
    res = calib_core.calibrate(obs, method=method)
    res.save(tmp_path / "r.json")
    back = CalibrationResult.load(tmp_path / "r.json")
    assert isinstance(back, CalibrationResult)
    assert back.to_dict() == json.loads(json.dumps(res.to_dict()))
    assert back.summary_lines()[1:] == res.summary_lines()[1:]  # the first line holds the timing, kept too
    if res.ok:
        assert back.to_yaml() == res.to_yaml()
    d = load_result(tmp_path / "r.json")  # the dict form stays for compatibility
    assert isinstance(d, dict) and d["method"] == res.method


def test_calibrate_yaml_and_report_extrinsic_yaml_are_the_same_file(solved):
    tmp, _, res = solved
    obs_file = tmp / "obs.json"
    assert main(["calibrate", str(obs_file), "--out", str(tmp / "r.json"), "--yaml", str(tmp / "e.yaml")]) == 0
    assert main(["report", str(obs_file), str(tmp / "r.json"), "--out", str(tmp / "rep")]) == 0
    cli, rep = (tmp / "e.yaml").read_text(), (tmp / "rep" / "extrinsic.yaml").read_text()
    assert "sigma_rot_deg" in cli and "conditioning" in cli
    assert rep == cli


def test_to_yaml_of_a_failed_result_is_an_error():
    res = CalibrationResult(method="m", ok=False, reason="too few boards")
    with pytest.raises(ValueError, match="too few boards"):
        res.to_yaml()
