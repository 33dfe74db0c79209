"""The simulator's lens (simulate.lens): the camera model a config key and a ``simulate`` flag, the wide-angle
presets, the default pinhole untouched."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calib_core.data.cameras import DoubleSphere, Equidistant
from simulate import SimOptions, generate
from simulate.lens import LENSES
from simulate.options import settings_hash

WIDE = {"pose_mode": "pixel", "n_boards": 8, "dist_min_m": 1.0, "dist_max_m": 3.0, "bearing_spread_deg": 150.0}


@pytest.mark.parametrize("lens, cls", [("fisheye150", Equidistant), ("ds180", DoubleSphere)])
def test_a_wide_angle_trial_sees_its_boards_through_the_lens(lens, cls):
    o = SimOptions(**WIDE, **LENSES[lens])
    obs = generate(o, seed=3, trial=1)
    cam = obs.camera
    assert type(cam) is cls and cam.width == o.cam_width
    T_true = np.asarray(obs.meta["T_cam_board_true"])
    e, off_axis = [], []
    for b, T in zip(obs.boards, T_true, strict=True):
        X = b.corners_board @ T[:3, :3].T + T[:3, 3]
        assert cam.valid(X).all()
        assert ((b.corners_px >= 0) & (b.corners_px <= [cam.width - 1, cam.height - 1])).all()
        e.append(b.corners_px - cam.project(X))
        off_axis.append(np.degrees(np.arccos(X[:, 2] / np.linalg.norm(X, axis=1))).max())
        assert np.abs(b.T_cam_board[:3, 3] - T[:3, 3]).max() < 0.05          # the pose fitted through the lens
    assert 0.4 < np.std(np.concatenate(e)) < 0.6                                # pixel_noise_px 0.5
    assert max(off_axis) > 45                                                   # the lens's wide field is used


def test_the_default_lens_is_the_pinhole_as_before():
    assert settings_hash(SimOptions(cam_model="pinhole-radtan", cam_params="")) == settings_hash(SimOptions())
    a = generate(SimOptions(pose_mode="pixel"), seed=2)
    b = generate(SimOptions(pose_mode="pixel", cam_model="pinhole-radtan"), seed=2)
    assert [x.corners_px.tolist() for x in a.boards] == [x.corners_px.tolist() for x in b.boards]
    assert settings_hash(SimOptions(**LENSES["ds180"])) != settings_hash(SimOptions())


@pytest.mark.parametrize("kw, words", [({"cam_model": "fov"}, "cam_model must be one of"),
                                       ({"cam_model": "ds", "cam_params": "0.1"}, "needs xi, alpha"),
                                       ({"cam_model": "ds", "cam_params": "0.1,1.2"}, "alpha"),
                                       ({"cam_model": "eucm", "cam_params": "a,b"}, "numbers"),
                                       ({**LENSES["ds180"], "pose_mode": "pixel", "distortion_error": 0.01},
                                        "pinhole-radtan")])
def test_a_lens_the_simulator_cannot_take_is_refused(kw, words):
    with pytest.raises(ValueError, match=words):
        SimOptions(**kw)


def test_the_intrinsics_error_of_a_lens_keeps_its_parameters_and_states_zero_for_them():
    o = SimOptions(**WIDE, **LENSES["ds180"], focal_error_rel=0.003, principal_point_error_px=2.0)
    obs = generate(o, seed=5)
    cam = obs.camera
    assert (cam.xi, cam.alpha) == (-0.2, 0.6)
    assert cam.std_intrinsics.tolist() == pytest.approx([0.003 * 340, 0.003 * 340, 2.0, 2.0, 0.0, 0.0])
    assert cam.K[0, 0] != 340.0


def test_the_simulate_verb_takes_a_lens(tmp_path):
    from lidarcam.cli import main
    out = tmp_path / "w.json"
    assert main(["simulate", "--lens", "fisheye150", "--pose-mode", "pixel", "--focal-px", "380", "--out",
                 str(out)]) == 0
    cam = json.loads(out.read_text())["camera"]
    assert cam["camera_model"] == "pinhole" and cam["distortion_model"] == "equidistant"
    assert cam["K"][0][0] == 380.0 and cam["width"] == 1024                      # the flag given wins
    assert main(["simulate", "--cam-model", "ds", "--cam-params=-0.2", "--out", str(out)]) == 2


def test_image_mode_renders_through_the_lens_and_detects_the_corners():
    o = SimOptions(**{**WIDE, "n_boards": 3, "pose_mode": "image"}, **LENSES["fisheye150"])
    obs = generate(o, seed=1)
    cam = obs.camera
    T_true = np.asarray(obs.meta["T_cam_board_true"])
    e = np.concatenate([b.corners_px - cam.project(b.corners_board @ T[:3, :3].T + T[:3, 3])
                        for b, T in zip(obs.boards, T_true, strict=True)])
    assert np.sqrt(np.mean(e**2)) < 0.3                         # the rendered corners sit where the lens puts them
