"""``lidarcam demo OUT``: the sample folders (a pinhole + checkerboard, a fisheye + ChArUco with boards cut by the
image edge) and bags (the pinhole rig's, the fisheye + ChArUco rig's with an ``equidistant`` CameraInfo) it writes,
calibrated by the very commands it prints, give the simulated extrinsic within 0.5 deg and 20 mm, with no warning;
``lidarcam bag --list-topics`` lists the bag's topics."""

from __future__ import annotations

import json
import shlex

import numpy as np
import yaml

from calib_core.geometry.metrics import pose_errors
from lidarcam.cli import main
from lidarcam.cli.demo import DEMO_FISHEYE


def test_demo_then_its_printed_commands_calibrate_the_folder_and_the_bag(tmp_path, capsys):
    out = tmp_path / "demo"
    assert main(["demo", str(out)]) == 0
    printed = capsys.readouterr().out
    commands = [shlex.split(ln.strip())[1:] for ln in printed.splitlines() if ln.startswith("  lidarcam ")]
    assert len(commands) == 10
    for argv in commands:
        assert main(argv) == 0, argv
    capsys.readouterr()
    truth = json.loads((out / "truth.json").read_text())
    for part, result in (("dataset", "dataset_result.json"), ("recording", "bag_result.json"),
                         ("fisheye_charuco", "fisheye_result.json"),
                         ("fisheye_recording", "fisheye_bag_result.json")):
        res = json.loads((out / result).read_text())
        e_R, e_t = pose_errors(np.array(res["T_lidar_cam"]), np.array(truth[part]["T_lidar_cam"]))
        assert res["ok"] and float(e_R) < 0.5 and float(e_t) < 0.020, (part, float(e_R), float(e_t))
        assert not res["warnings"], (part, res["warnings"])    # a new user's first result: no false alarm
    cam = yaml.safe_load((out / "fisheye_bag_dataset" / "camera.yaml").read_text())   # from the bag's CameraInfo
    assert cam["distortion_model"] == "equidistant"
    k1_k4 = [float(v) for v in DEMO_FISHEYE["cam_params"].split(",")]
    np.testing.assert_allclose(cam["distortion_coefficients"], k1_k4)
    assert cam["camera_matrix"][0][0] == DEMO_FISHEYE["focal_px"] and cam["image_width"] == DEMO_FISHEYE["cam_width"]
    assert main(["bag", "--list-topics", str(out / "recording")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["topic", "messages", "type"]
    rows = {ln.split()[0]: ln.split()[1:] for ln in lines[1:]}
    assert rows["/scan"][1] == "sensor_msgs/msg/LaserScan" and int(rows["/scan"][0]) > 100
    assert rows["/camera/camera_info"] == ["1", "sensor_msgs/msg/CameraInfo"]


def test_bag_without_its_topics_is_one_line(tmp_path, capsys):
    assert main(["bag", str(tmp_path / "nope")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--list-topics" in err
