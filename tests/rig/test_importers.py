"""Readers of lidarcam/rig/importers on small files written here: values, frames, units, and one-line errors."""

from __future__ import annotations

import numpy as np
import pytest

from lidarcam.rig.dataset import DatasetError
from lidarcam.rig.importers.bouguet import grid_outline, read_bouguet
from lidarcam.rig.importers.camera_yaml import read_camera_file
from lidarcam.rig.importers.pcd import read_pcd_scan
from lidarcam.rig.importers.radlocc import RADLOCC_FROM_LIDAR, T_lidar_cam_from_radlocc, read_radlocc_laser
from lidarcam.rig.importers.segmented import read_segmented_points


def _one_line(err) -> str:
    s = str(err.value)
    assert "\n" not in s
    return s


def test_radlocc_bearings_units_and_no_returns(tmp_path):
    p = tmp_path / "laser.txt"
    p.write_text("100 -0.5 0.25 0.5 3 5 1.0, inf, 2.0, 0, 3.0\n"
                 "110 -0.5 0.25 0.5 1 5 1000 2000 3000 4000 nan\n")
    scans = read_radlocc_laser(p)
    assert [s.timestamp for s in scans] == [100, 110]
    s0, s1 = scans[0].scan, scans[1].scan
    np.testing.assert_allclose(s0.bearing, [-0.5, 0.0, 0.5])
    np.testing.assert_allclose(s0.range, [1.0, 2.0, 3.0])
    assert s0.n_dropped == 2
    np.testing.assert_allclose(s0.points[2], [3 * np.cos(0.5), 3 * np.sin(0.5)])
    np.testing.assert_allclose(s1.range, [1.0, 2.0, 3.0, 4.0])  # RangeUnitType 1 = mm


def test_radlocc_errors_name_file_line_and_field(tmp_path):
    p = tmp_path / "laser.txt"
    p.write_text("100 -0.5 0.25 0.5 3 5 1, 2, 3, 4, 5\n2.4, 2.5, 2.6, 2.7, 2.8, 2.9, 3.0\n")
    with pytest.raises(DatasetError) as err:
        read_radlocc_laser(p)
    assert "laser.txt: line 2: field RangeUnitType" in _one_line(err)
    assert len(read_radlocc_laser(p, lines=range(1, 2))) == 1
    p.write_text("100 -0.5 0.25 0.5 3 6 1, 2, 3, 4, 5\n")
    with pytest.raises(DatasetError) as err:
        read_radlocc_laser(p)
    assert "line 1: field N says 6 ranges, the line holds 5" in _one_line(err)
    p.write_text("100 -0.5 0.25 0.5 3 5 1, 2, x, 4, 5\n")
    with pytest.raises(DatasetError, match="range 3: not a number"):
        read_radlocc_laser(p)


def test_radlocc_result_convention_round_trip():
    """Build PHI, DELTA from a known T_lidar_cam with RADLOCC's [y; 0; x] convention and read it back."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(11)
    for _ in range(20):
        R = Rotation.random(random_state=rng).as_matrix()
        t = rng.normal(0, 0.2, 3)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, t
        # RADLOCC: Lr = PHI (C - DELTA), Lr = M p_L, p_L = R C + t  =>  PHI = M R, DELTA = -R^T t
        PHI, DELTA_mm = RADLOCC_FROM_LIDAR @ R, -1000 * R.T @ t
        np.testing.assert_allclose(T_lidar_cam_from_radlocc(PHI, DELTA_mm), T, atol=1e-12)
        p_L = np.array([rng.normal(), rng.normal(), 0.0])
        C = R.T @ (p_L - t)
        Lr = PHI @ (C - DELTA_mm / 1000)
        np.testing.assert_allclose(Lr, [p_L[1], 0.0, p_L[0]], atol=1e-12)


_PCD_HEAD = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\nCOUNT 1 1 1 1\n"
             "WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {mode}\n")


def test_pcd_ascii_and_binary(tmp_path):
    pts = np.array([[1.0, 0.5, 0, 1e-38], [0, 0, 0, 0], [0.0, -2.0, 0, 0], [np.nan, 1, 0, 0]], np.float32)
    a = tmp_path / "a.pcd"
    a.write_text(_PCD_HEAD.format(n=4, mode="ascii") + "\n".join(" ".join(map(str, r)) for r in pts) + "\n")
    b = tmp_path / "b.pcd"
    b.write_bytes(_PCD_HEAD.format(n=4, mode="binary").encode() + pts.astype("<f4").tobytes())
    for p in (a, b):
        s = read_pcd_scan(p)
        assert len(s) == 2 and s.n_dropped == 2
        np.testing.assert_allclose(sorted(map(tuple, s.points)), [(0.0, -2.0), (1.0, 0.5)], atol=1e-6)


def test_pcd_errors(tmp_path):
    p = tmp_path / "c.pcd"
    p.write_text(_PCD_HEAD.format(n=2, mode="ascii") + "1 2 0 0\n1 2 0.5 0\n")
    with pytest.raises(DatasetError) as err:
        read_pcd_scan(p)
    assert "c.pcd: field z: up to 0.500 m" in _one_line(err)
    p.write_text(_PCD_HEAD.format(n=3, mode="ascii") + "1 2 0 0\n1 2 0 0\n")
    with pytest.raises(DatasetError, match="2 points, header says 3"):
        read_pcd_scan(p)
    p.write_text(_PCD_HEAD.format(n=1, mode="binary_compressed") + "xx")
    with pytest.raises(DatasetError, match="binary_compressed"):
        read_pcd_scan(p)


def _bouguet_mat(path, Rc, Tc_mm, active=(1, 1)):
    from scipy.io import savemat

    X = np.array([[0, 23, 0, 23], [0, 0, 23, 23], [0, 0, 0, 0]], float)
    d = {"fc": [[500.0], [600.0]], "cc": [[320.0], [240.0]], "alpha_c": [[0.0]],
         "kc": [[0.1], [-0.2], [0.001], [0.002], [0.0]], "nx": [[640]], "ny": [[480]], "n_ima": [[2]],
         "active_images": [list(active)], "dX": [[23.0]], "fc_error": [[3.0], [4.0]]}
    for k in (1, 2):
        d[f"Rc_{k}"], d[f"Tc_{k}"] = Rc, np.reshape(Tc_mm, (3, 1))
        d[f"x_{k}"], d[f"X_{k}"] = np.arange(8.0).reshape(2, 4), X
    savemat(path, d)


def test_bouguet_units_frames_and_inactive(tmp_path):
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    p = tmp_path / "Calib_Results.mat"
    _bouguet_mat(p, R, [10.0, -20.0, 500.0], active=(1, 0))
    c = read_bouguet(p)
    np.testing.assert_allclose(c.camera.K, [[500, 0, 320], [0, 600, 240], [0, 0, 1]])
    np.testing.assert_allclose(c.camera.dist, [0.1, -0.2, 0.001, 0.002, 0.0])
    assert (c.camera.width, c.camera.height) == (640, 480) and c.square_m == pytest.approx(0.023)
    assert [v.index for v in c.views] == [1]  # image 2 inactive
    v = c.views[0]
    np.testing.assert_allclose(v.T_cam_board[:3, :3], R)
    np.testing.assert_allclose(v.T_cam_board[:3, 3], [0.01, -0.02, 0.5])  # mm -> m
    np.testing.assert_allclose(v.grid_m[3], [0.023, 0.023, 0.0])
    np.testing.assert_allclose(v.corners_px[1], [1.0, 5.0])
    np.testing.assert_allclose(c.sigma["fc"], [3.0, 4.0])
    np.testing.assert_allclose(grid_outline(v.grid_m, 0.023), [[-0.023, -0.023], [0.046, -0.023],
                                                               [0.046, 0.046], [-0.023, 0.046]])


def test_bouguet_errors(tmp_path):
    p = tmp_path / "Calib_Results.mat"
    _bouguet_mat(p, np.diag([1.0, 1.0, 2.0]), [0, 0, 500])
    with pytest.raises(DatasetError) as err:
        read_bouguet(p)
    assert "Calib_Results.mat: field Rc_1: not a rotation matrix" in _one_line(err)
    (tmp_path / "bad.mat").write_text("not a mat file")
    with pytest.raises(DatasetError, match="bad.mat: not a readable MATLAB file"):
        read_bouguet(tmp_path / "bad.mat")


def test_segmented_points(tmp_path):
    p = tmp_path / "pts.csv"
    p.write_text("pose,x_m,y_m\n1,-0.5,0.1\n1,-0.5,0.12\n2,0.3,0.4\n")
    pts = read_segmented_points(p)
    assert list(pts) == ["1", "2"]
    np.testing.assert_allclose(pts["1"], [[-0.5, 0.1], [-0.5, 0.12]])
    p.write_text("pose,x_m,y_m\n1,-0.5,abc\n")
    with pytest.raises(DatasetError) as err:
        read_segmented_points(p)
    assert "pts.csv: line 2: field y_m: not a number" in _one_line(err)
    p.write_text("pose,x,y\n1,2,3\n")
    with pytest.raises(DatasetError, match="lacks column"):
        read_segmented_points(p)


def test_camera_files_ros_opencv_kalibr(tmp_path):
    K = [[500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]]
    ros = tmp_path / "ros.yaml"
    ros.write_text("image_width: 640\nimage_height: 480\ncamera_name: cam\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
                   "  data: [500, 0, 320, 0, 510, 240, 0, 0, 1]\ndistortion_model: plumb_bob\n"
                   "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0.1, -0.2, 0, 0, 0]\n")
    kal = tmp_path / "camchain.yaml"
    kal.write_text("cam0:\n  camera_model: pinhole\n  intrinsics: [500, 510, 320, 240]\n"
                   "  distortion_model: radtan\n  distortion_coeffs: [0.1, -0.2, 0, 0]\n  resolution: [640, 480]\n")
    import cv2

    xml = tmp_path / "cam.xml"
    fs = cv2.FileStorage(str(xml), cv2.FILE_STORAGE_WRITE)
    fs.write("image_Width", 640)
    fs.write("image_Height", 480)
    fs.write("Camera_Matrix", np.array(K))
    fs.write("Distortion_Coefficients", np.array([[0.1], [-0.2], [0], [0], [0]]))
    fs.release()
    for p in (ros, kal, xml):
        c = read_camera_file(p)
        np.testing.assert_allclose(c.K, K)
        np.testing.assert_allclose(c.dist[:2], [0.1, -0.2])
        assert (c.width, c.height) == (640, 480)
    kal.write_text(kal.read_text().replace("radtan", "fov"))
    with pytest.raises(DatasetError) as err:
        read_camera_file(kal)
    assert "camchain.yaml: key 'cam0.distortion_model': 'fov' is not a model the project knows" in _one_line(err)
    with pytest.raises(DatasetError, match="no camera 'cam1'"):
        read_camera_file(kal, cam="cam1")


def test_bouguet_errors_are_three_sigma_and_give_std_intrinsics(tmp_path):
    from scipy.io import loadmat, savemat

    p = tmp_path / "Calib_Results.mat"
    _bouguet_mat(p, np.eye(3), [0, 0, 500])
    c = read_bouguet(p)
    assert c.camera.std_intrinsics is None  # fc_error alone: no principal point error, nothing stated
    d = {k: v for k, v in loadmat(str(p)).items() if not k.startswith("__")}
    d.update(cc_error=[[1.5], [2.4]], kc_error=[[0.03], [0.06], [0.003], [0.0015], [0.0]])
    savemat(p, d)
    c = read_bouguet(p)
    np.testing.assert_allclose(c.camera.std_intrinsics, np.r_[3.0, 4.0, 1.5, 2.4, 0.03, 0.06, 0.003, 0.0015, 0] / 3)
    d["kc_error"] = [[0.03], [-0.06], [0.003], [0.0015], [0.0]]
    savemat(p, d)
    with pytest.raises(DatasetError) as err:
        read_bouguet(p)
    assert "Calib_Results.mat: field kc_error: expected 5 finite non-negative values" in _one_line(err)
