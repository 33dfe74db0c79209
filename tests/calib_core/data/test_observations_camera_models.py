"""The camera model in ``lidarcam.observations/1``: optional Kalibr keys; a file without them reads as the OpenCV
pinhole as before; a model, key or value the project does not know is refused naming the field."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from test_camera_models import NAMES, random_camera

from calib_core.data.camera import Camera
from calib_core.data.io import observations_from_dict, observations_to_dict
from calib_core.errors import ObservationError
from simulate import SimOptions, generate


@pytest.fixture(scope="module")
def obs():
    return generate(SimOptions(pose_mode="pixel", n_boards=3), seed=1)


@pytest.mark.parametrize("name", NAMES)
def test_every_model_survives_the_file(obs, name):
    rng = np.random.default_rng(4)
    cam = random_camera(name, rng)
    std = np.r_[1.0, 1.0, 2.0, 2.0, np.full(cam.n_core - 4, 0.01)]
    cam = replace(cam, std_intrinsics=std)
    back = observations_from_dict(json.loads(json.dumps(observations_to_dict(replace(obs, camera=cam)))))
    assert type(back.camera) is type(cam) and back.camera.name == name
    np.testing.assert_array_equal(back.camera.intrinsics, cam.intrinsics)
    np.testing.assert_array_equal(back.camera.std_intrinsics, std)


def test_a_file_without_the_keys_is_the_opencv_pinhole_as_before(obs):
    d = observations_to_dict(obs)
    assert set(d["camera"]) == {"K", "dist", "width", "height"}
    assert type(observations_from_dict(d).camera) is Camera
    d["camera"]["camera_model"] = "pinhole"
    assert type(observations_from_dict(d).camera) is Camera


@pytest.mark.parametrize("change, field, words", [
    ({"camera_model": "fov"}, "camera.camera_model", "known: pinhole/radtan"),
    ({"camera_model": "pinhole", "distortion_model": "equi"}, "camera.camera_model", "pinhole/equidistant"),
    ({"camera_model": "ds", "xi": 0.1, "alpha": 0.5, "beta": 1.0, "dist": []}, "camera.beta", "xi, alpha"),
    ({"camera_model": "ds", "xi": 0.1, "alpha": 1.5, "dist": []}, "camera.alpha", "[0, 1)"),
    ({"camera_model": "ds", "dist": [0.1]}, "camera.dist", "takes 0"),
    ({"camera_model": "omni", "xi": "one"}, "camera.xi", "number"),
    ({"camera_model": ["ds"]}, "camera.camera_model", "strings"),
    ({"camera_model": "pinhole", "distortion_model": "equidistant", "dist": [0.1, 0.2]}, "camera.dist", "4"),
])
def test_what_the_project_does_not_know_is_refused_naming_the_field(obs, change, field, words):
    d = observations_to_dict(obs)
    d["camera"].update(change)
    with pytest.raises(ObservationError) as err:
        observations_from_dict(d, source="f.json")
    assert field in str(err.value) and words in str(err.value) and "f.json" in str(err.value)
