"""The optional ``board_range_sigma_m`` of an observation file: kept on a round trip and in a subset; a negative,
NaN, absurd (over a metre) or non-numeric value is one line naming the file and the field."""

import json
import subprocess
import sys

import pytest

from calib_core.data.io import load_observations, observations_to_dict, save_observations
from calib_core.errors import ObservationError
from simulate import SimOptions, generate


@pytest.fixture
def obs_dict():
    return observations_to_dict(generate(SimOptions(n_boards=4, pose_mode="exact"), seed=2))


def test_round_trip_and_absent_means_unstated(tmp_path, obs_dict):
    p = tmp_path / "a.json"
    obs_dict["board_range_sigma_m"] = 0.0035
    p.write_text(json.dumps(obs_dict))
    obs = load_observations(p)
    assert obs.board_range_sigma_m == 0.0035 and obs.subset([1, 2]).board_range_sigma_m == 0.0035
    save_observations(obs, tmp_path / "b.json")
    assert json.loads((tmp_path / "b.json").read_text())["board_range_sigma_m"] == 0.0035
    del obs_dict["board_range_sigma_m"]
    p.write_text(json.dumps(obs_dict))
    assert load_observations(p).board_range_sigma_m is None
    assert "board_range_sigma_m" not in observations_to_dict(load_observations(p))


@pytest.mark.parametrize("bad", ["-0.001", "NaN", "1.5", "\"5 mm\"", "true", "[0.1]"])
def test_bad_scale_names_file_and_field(tmp_path, obs_dict, bad):
    p = tmp_path / "bad.json"
    p.write_text(json.dumps(obs_dict)[:-1] + f', "board_range_sigma_m": {bad}}}')
    with pytest.raises(ObservationError, match="board_range_sigma_m") as err:
        load_observations(p)
    assert "bad.json" in str(err.value)
    r = subprocess.run([sys.executable, "-m", "lidarcam.cli", "calibrate", str(p)], capture_output=True, text=True)
    assert r.returncode == 2 and "board_range_sigma_m" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
