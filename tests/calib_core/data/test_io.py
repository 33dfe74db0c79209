"""Observation JSON (``lidarcam.observations/1``): exact round trip, and a clear named error per bad file."""

from __future__ import annotations

import copy
import json
import zlib

import numpy as np
import pytest

from calib_core.data.io import OBS_SCHEMA, load_observations, observations_to_dict, save_observations
from calib_core.data.observations import BoardObservation, Observations
from calib_core.errors import ObservationError
from calib_core.geometry.transforms import make_T, rotvec_to_matrix


def rng_for(name: str) -> np.random.Generator:
    return np.random.default_rng(zlib.crc32(name.encode()))


def random_observations(rng, n=3) -> Observations:
    boards = []
    for _ in range(n):
        T = make_T(rotvec_to_matrix(rng.normal(size=3)), rng.normal(size=3) * 3)
        scan = rng.normal(size=(int(rng.integers(2, 40)), 2))
        boards.append(BoardObservation(T, [[0, 0], [1, 0], [1, 1], [0, 1]], scan))
    T_true = make_T(rotvec_to_matrix(rng.normal(size=3)), rng.normal(size=3))
    return Observations(tuple(boards), T_true, {"seed": 3, "note": "random", "nested": {"x": [1.5, 2]}})


def test_json_round_trip_is_exact(tmp_path):
    obs = random_observations(rng_for("test_json_round_trip_is_exact"), n=4)
    path = tmp_path / "obs.json"
    save_observations(obs, path)
    back = load_observations(path)
    assert back.n_boards == obs.n_boards
    assert np.array_equal(back.T_lidar_cam_true, obs.T_lidar_cam_true)
    for a, b in zip(obs.boards, back.boards, strict=True):
        for f in ("T_cam_board", "outline", "scan"):
            assert np.array_equal(getattr(a, f), getattr(b, f)), f
    assert back.meta == obs.meta


def test_simulated_observations_round_trip(tmp_path):
    from simulate import SimOptions, generate

    obs = generate(SimOptions(n_boards=3, pose_mode="pixel"), seed=1)
    save_observations(obs, tmp_path / "sim.json")
    back = load_observations(tmp_path / "sim.json")
    assert all(np.array_equal(a.scan, b.scan) for a, b in zip(obs.boards, back.boards, strict=True))
    assert back.meta == obs.meta


@pytest.fixture
def good_dict():
    return observations_to_dict(random_observations(rng_for("good_dict"), n=3))


def write(tmp_path, d, raw: str | None = None):
    path = tmp_path / "bad.json"
    path.write_text(raw if raw is not None else json.dumps(d))
    return path


def expect_error(path, board, field, match):
    with pytest.raises(ObservationError, match=match) as info:
        load_observations(path)
    err = info.value
    assert err.file == str(path)
    assert err.board == board
    assert err.field == field
    text = str(err)
    assert str(path) in text and f"field '{field}'" in text
    if board is not None:
        assert f"board {board}" in text


@pytest.mark.parametrize("key", ["T_cam_board", "outline", "scan"])
def test_missing_board_key(tmp_path, good_dict, key):
    del good_dict["boards"][1][key]
    expect_error(write(tmp_path, good_dict), 1, key, "missing key")


@pytest.mark.parametrize("key", ["schema", "boards"])
def test_missing_top_level_key(tmp_path, good_dict, key):
    del good_dict[key]
    expect_error(write(tmp_path, good_dict), None, key, "missing key")


def test_wrong_schema(tmp_path, good_dict):
    good_dict["schema"] = "lidarcam.observations/99"
    expect_error(write(tmp_path, good_dict), None, "schema", "unsupported schema")
    assert OBS_SCHEMA == "lidarcam.observations/1"


@pytest.mark.parametrize("field,value", [
    ("T_cam_board", np.eye(4)[:3].tolist()),
    ("outline", [[0, 0, 0], [1, 0, 0], [1, 1, 0]]),
    ("scan", [[1.0, 2.0, 0.0], [1.0, 2.1, 0.0]]),
    ("scan", [1.0, 2.0, 3.0]),
])
def test_wrong_shapes(tmp_path, good_dict, field, value):
    good_dict["boards"][2][field] = value
    expect_error(write(tmp_path, good_dict), 2, field, "expected shape")


@pytest.mark.parametrize("field", ["T_cam_board", "outline", "scan"])
@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity"])
def test_nan_and_inf(tmp_path, good_dict, field, literal):
    good_dict["boards"][1][field][0][1] = "__BAD__"
    raw = json.dumps(good_dict).replace('"__BAD__"', literal)
    expect_error(write(tmp_path, None, raw), 1, field, "NaN or inf")


def test_rotation_not_orthonormal(tmp_path, good_dict):
    T = np.array(good_dict["boards"][0]["T_cam_board"])
    ok = T.copy()
    ok[:3, :3] *= 1 + 1e-8          # within the 1e-6 tolerance: accepted
    good_dict["boards"][0]["T_cam_board"] = ok.tolist()
    load_observations(write(tmp_path, good_dict))
    bad = T.copy()
    bad[:3, :3] *= 1 + 1e-5         # |R^T R - I| ~ 2e-5 > 1e-6
    good_dict["boards"][0]["T_cam_board"] = bad.tolist()
    expect_error(write(tmp_path, good_dict), 0, "T_cam_board", "not orthonormal")
    refl = T.copy()
    refl[:3, 0] *= -1               # a reflection is orthonormal but not a rotation
    good_dict["boards"][0]["T_cam_board"] = refl.tolist()
    expect_error(write(tmp_path, good_dict), 0, "T_cam_board", "reflection")


def test_bow_tie_outline(tmp_path, good_dict):
    good_dict["boards"][2]["outline"] = [[0, 0], [1, 1], [1, 0], [0, 2]]   # edges 0 and 2 cross
    expect_error(write(tmp_path, good_dict), 2, "outline", "not a simple polygon")
    good_dict["boards"][2]["outline"] = [[0, 0], [1, 1], [1, 0], [0, 1]]   # symmetric: signed area 0 as well
    expect_error(write(tmp_path, good_dict), 2, "outline", "zero area|not a simple polygon")


def test_fewer_than_two_scan_points(tmp_path, good_dict):
    good_dict["boards"][1]["scan"] = [[3.0, 0.1]]
    expect_error(write(tmp_path, good_dict), 1, "scan", "fewer than 2")


def test_not_json_names_the_file(tmp_path):
    path = write(tmp_path, None, "{not json")
    with pytest.raises(ObservationError, match="not valid JSON") as info:
        load_observations(path)
    assert info.value.file == str(path)


def test_bad_ground_truth(tmp_path, good_dict):
    gt = copy.deepcopy(good_dict)
    gt["ground_truth"]["T_lidar_cam"][0][0] += 0.1
    expect_error(write(tmp_path, gt), None, "ground_truth.T_lidar_cam", "not a rigid transform")
