"""Camera measurements in observation files: per-board ``corners_px`` / ``corners_board`` and the file's ``camera``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calib_core.data.io import load_observations, observations_to_dict, save_observations
from calib_core.errors import ObservationError
from simulate import SimOptions, generate


@pytest.fixture
def pixel_dict():
    return observations_to_dict(generate(SimOptions(n_boards=3, pose_mode="pixel"), 0, 0))


def load(tmp_path, d, name="obs.json"):
    p = tmp_path / name
    p.write_text(json.dumps(d))
    return load_observations(p)


def test_round_trip_keeps_corners_and_camera(tmp_path):
    obs = generate(SimOptions(n_boards=3, pose_mode="pixel"), 0, 0)
    assert obs.has_corners
    save_observations(obs, tmp_path / "o.json")
    back = load_observations(tmp_path / "o.json")
    assert back.has_corners
    np.testing.assert_array_equal(back.camera.K, obs.camera.K)
    np.testing.assert_array_equal(back.camera.dist, obs.camera.dist)
    for a, b in zip(obs.boards, back.boards, strict=True):
        np.testing.assert_array_equal(a.corners_px, b.corners_px)
        np.testing.assert_array_equal(a.corners_board, b.corners_board)


def test_files_without_corners_load_as_before(tmp_path, pixel_dict):
    d = {k: v for k, v in pixel_dict.items() if k != "camera"}
    for b in d["boards"]:
        b.pop("corners_px"), b.pop("corners_board")
    obs = load(tmp_path, d)
    assert not obs.has_corners and obs.camera is None


def test_planar_board_corners_get_z_zero(tmp_path, pixel_dict):
    for b in pixel_dict["boards"]:
        b["corners_board"] = [c[:2] for c in b["corners_board"]]
    obs = load(tmp_path, pixel_dict)
    assert obs.boards[0].corners_board.shape[1] == 3 and not np.any(obs.boards[0].corners_board[:, 2])


def expect(tmp_path, d, *parts):
    with pytest.raises(ObservationError) as exc:
        load(tmp_path, d)
    msg = str(exc.value)
    assert "obs.json" in msg and "\n" not in msg
    for p in parts:
        assert p in msg, msg


def test_corners_without_camera(tmp_path, pixel_dict):
    del pixel_dict["camera"]
    expect(tmp_path, pixel_dict, "board 0", "field 'camera'")


def test_mismatched_corner_counts(tmp_path, pixel_dict):
    pixel_dict["boards"][1]["corners_board"] = pixel_dict["boards"][1]["corners_board"][:-1]
    expect(tmp_path, pixel_dict, "board 1", "corners_board", "30 image corners but 29")


def test_one_of_the_pair_missing(tmp_path, pixel_dict):
    del pixel_dict["boards"][2]["corners_board"]
    expect(tmp_path, pixel_dict, "board 2", "corners_board", "both or neither")


@pytest.mark.parametrize("field", ["corners_px", "corners_board"])
def test_non_finite_corners(tmp_path, pixel_dict, field):
    pixel_dict["boards"][1][field][3][0] = float("nan")
    expect(tmp_path, pixel_dict, "board 1", f"field '{field}'", "NaN")


def test_too_few_corners(tmp_path, pixel_dict):
    b = pixel_dict["boards"][0]
    b["corners_px"], b["corners_board"] = b["corners_px"][:3], b["corners_board"][:3]
    expect(tmp_path, pixel_dict, "board 0", "corners_px", "fewer than 4")


@pytest.mark.parametrize("change, parts", [
    (lambda c: c.update(K=[[-800, 0, 400], [0, 800, 300], [0, 0, 1]]), ("camera.K", "focal")),
    (lambda c: c.update(K=[[800, 0, 4000], [0, 800, 300], [0, 0, 1]]), ("camera.K", "principal point")),
    (lambda c: c.update(K=[[800, 3, 400], [0, 800, 300], [0, 0, 1]]), ("camera.K", "skew")),
    (lambda c: c.update(K=[[800, 0, 400], [0, 800, 300], [0, 0, 2]]), ("camera.K",)),
    (lambda c: c.update(K=[[800, 0], [0, 800]]), ("camera.K", "3x3")),
    (lambda c: c.update(dist=[0.1, 0.2, 0.0]), ("camera.dist", "length 3")),
    (lambda c: c.update(dist=[0.1, float("inf"), 0, 0]), ("camera.dist", "NaN or inf")),
    (lambda c: c.update(width=0), ("camera.width",)),
    (lambda c: c.pop("height"), ("camera.height", "missing")),
])
def test_implausible_camera(tmp_path, pixel_dict, change, parts):
    change(pixel_dict["camera"])
    expect(tmp_path, pixel_dict, *parts)


def test_exact_mode_writes_no_corners():
    obs = generate(SimOptions(n_boards=3), 0, 0)
    d = observations_to_dict(obs)
    assert "camera" not in d and "corners_px" not in d["boards"][0]
