"""ROS exports: every printed form, parsed back independently, reproduces the 4x4 matrix to 1e-9, in the
stated direction (parent -> child maps child points into the parent frame), parent and child not swapped."""

import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from calib_core.data.exports import frame_export
from calib_core.data.io import extrinsic_yaml
from calib_core.errors import CalibrationError
from calib_core.geometry.transforms import invert_T, make_T, transform_points
from lidarcam.cli import main

TOL = 1e-9


def _random_T(rng):
    return make_T(Rotation.random(random_state=rng).as_matrix(), rng.uniform(-2, 2, 3))


def _from_xyz_quat(xyz, q_xyzw):
    return make_T(Rotation.from_quat(q_xyzw).as_matrix(), xyz)


def _parse_positional(line):
    w = line.split()[-9:]
    v = [float(x) for x in w[:7]]
    return _from_xyz_quat(v[:3], v[3:]), w[7], w[8]


def _parse_ros2(line):
    args = dict(re.findall(r"--([a-z-]+) (\S+)", line))
    T = _from_xyz_quat([float(args[k]) for k in "xyz"], [float(args[k]) for k in ("qx", "qy", "qz", "qw")])
    return T, args["frame-id"], args["child-frame-id"]


def _rpy_matrix(r, p, y):
    """URDF's fixed-axis roll-pitch-yaw written out by hand: Rz(yaw) Ry(pitch) Rx(roll)."""
    c, s = np.cos, np.sin
    Rx = np.array([[1, 0, 0], [0, c(r), -s(r)], [0, s(r), c(r)]])
    Ry = np.array([[c(p), 0, s(p)], [0, 1, 0], [-s(p), 0, c(p)]])
    Rz = np.array([[c(y), -s(y), 0], [s(y), c(y), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _parse_urdf(xml):
    j = ET.fromstring(xml)
    o = j.find("origin")
    xyz = [float(v) for v in o.get("xyz").split()]
    rpy = [float(v) for v in o.get("rpy").split()]
    return make_T(_rpy_matrix(*rpy), xyz), j.find("parent").get("link"), j.find("child").get("link")


@pytest.mark.parametrize("parent_sensor", ["lidar", "camera"])
def test_every_form_reproduces_the_matrix_in_the_stated_direction(parent_sensor):
    rng = np.random.default_rng(16)
    for _ in range(200):
        T_lidar_cam = _random_T(rng)
        expect = T_lidar_cam if parent_sensor == "lidar" else invert_T(T_lidar_cam)
        ex = frame_export(T_lidar_cam, "laser", "camera", parent_sensor)
        for parse, text in ((_parse_positional, ex.tf_args), (_parse_positional, ex.ros1), (_parse_ros2, ex.ros2),
                            (_parse_urdf, ex.urdf_joint())):
            T, parent, child = parse(text)
            assert (parent, child) == ("laser", "camera"), text
            np.testing.assert_allclose(T, expect, atol=TOL, rtol=0)


def test_published_transform_maps_child_points_into_the_parent_frame():
    """A camera point p_C lands at T_lidar_cam p_C in the lidar frame when the lidar is the parent."""
    rng = np.random.default_rng(3)
    T_lidar_cam = _random_T(rng)
    p_cam = rng.normal(size=(5, 3))
    T, parent, child = _parse_positional(frame_export(T_lidar_cam, "laser", "camera").tf_args)
    np.testing.assert_allclose(transform_points(T, p_cam), transform_points(T_lidar_cam, p_cam), atol=TOL)
    # and the camera's origin, seen from the lidar, is the published translation
    np.testing.assert_allclose(T[:3, 3], T_lidar_cam[:3, 3], atol=TOL)


def test_rpy_near_gimbal_lock_still_reproduces_the_matrix():
    rng = np.random.default_rng(7)
    for k in range(2, 17):
        for sign in (1, -1):
            pitch = sign * (np.pi / 2 - 10.0 ** -k)
            R = Rotation.from_euler("xyz", [rng.uniform(-3, 3), pitch, rng.uniform(-3, 3)]).as_matrix()
            T = make_T(R, rng.normal(size=3))
            np.testing.assert_allclose(_parse_urdf(frame_export(T, "a", "b").urdf_joint())[0], T, atol=TOL)


@pytest.mark.parametrize("args", [("laser", "laser", "lidar"), ("la ser", "camera", "lidar"),
                                  ("laser", 'cam"era', "lidar"), ("laser", "camera", "imu")])
def test_bad_frames_are_errors(args):
    with pytest.raises(CalibrationError):
        frame_export(np.eye(4), *args)


def test_non_rigid_matrix_is_an_error():
    T = np.eye(4)
    T[0, 0] = 2.0
    with pytest.raises(CalibrationError, match="rigid"):
        frame_export(T, "laser", "camera")


def test_yaml_block_parses_back():
    rng = np.random.default_rng(5)
    T = _random_T(rng)
    d = yaml.safe_load(extrinsic_yaml(T, {"method": "x"}, ros=frame_export(T, "base_laser", "cam0", "camera")))
    r = d["ros"]
    assert (r["parent_frame"], r["child_frame"], r["T_parent_child"]) == ("base_laser", "cam0", "T_cam_lidar")
    np.testing.assert_allclose(_from_xyz_quat(r["translation"], r["quaternion_xyzw"]), invert_T(T), atol=TOL)
    np.testing.assert_allclose(make_T(_rpy_matrix(*r["urdf_rpy"]), r["translation"]), invert_T(T), atol=TOL)
    np.testing.assert_allclose(_parse_ros2(r["ros2"])[0], invert_T(T), atol=TOL)
    np.testing.assert_allclose(_parse_urdf(r["urdf_joint"])[0], invert_T(T), atol=TOL)
    np.testing.assert_allclose(d["T_cam_lidar"]["matrix"], invert_T(T), atol=TOL)


def test_cli_prints_and_writes_the_ros_forms(tmp_path, capsys):
    obs, yml = tmp_path / "obs.json", tmp_path / "r.yaml"
    assert main(["simulate", "--boards", "6", "--noise-mm", "20", "--seed", "2", "--out", str(obs)]) == 0
    capsys.readouterr()
    assert main(["calibrate", str(obs), "--method", "peng2022", "--parent-frame", "laser", "--child-frame",
                 "camera", "--yaml", str(yml)]) == 0
    out = capsys.readouterr().out
    ros1 = next(ln for ln in out.splitlines() if "rosrun tf2_ros static_transform_publisher" in ln)
    ros2 = next(ln for ln in out.splitlines() if "ros2 run tf2_ros static_transform_publisher" in ln)
    d = yaml.safe_load(yml.read_text())
    T_lidar_cam = np.array(d["T_lidar_cam"]["matrix"])
    assert "maps camera points into the laser frame" in out
    for parse, line in ((_parse_positional, ros1), (_parse_ros2, ros2)):
        T, parent, child = parse(line)
        assert (parent, child) == ("laser", "camera")
        np.testing.assert_allclose(T, T_lidar_cam, atol=TOL)
    np.testing.assert_allclose(_parse_urdf(d["ros"]["urdf_joint"])[0], T_lidar_cam, atol=TOL)


def test_cli_needs_both_frame_names(tmp_path, capsys):
    obs = tmp_path / "obs.json"
    main(["simulate", "--boards", "4", "--out", str(obs)])
    capsys.readouterr()
    assert main(["calibrate", str(obs), "--parent-frame", "laser"]) == 2
    assert "--child-frame" in capsys.readouterr().err
