"""Real-rig pipeline: dataset loading and its errors, board/segment extraction, report, CLI verbs.

The end-to-end tests write a simulated dataset (``simulate.dataset.write_dataset``: rendered, blurred, noisy,
distorted images; scans in a room with clutter) and check extraction and calibration against its ground truth.
"""

import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from calib_core.geometry.metrics import pose_errors
from calib_core.geometry.transforms import invert_T, make_T, rotvec_to_matrix, transform_points
from lidarcam.rig.dataset import DatasetError, load_board, load_camera, load_dataset, make_scan, read_scan_csv
from lidarcam.rig.extract import ExtractionError, ExtractOptions, extract, format_diagnostics
from lidarcam.rig.segment import find_board_segment

R_NOMINAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # camera axes -> lidar axes

BOARD_YAML = "cols: 6\nrows: 5\nsquare_m: 0.12\noutline_m: [[-0.2, -0.26], [0.8, -0.26], [0.8, 0.74], [-0.2, 0.74]]\n"
CAMERA_YAML = "image_width: 64\nimage_height: 48\ncamera_matrix: [[60, 0, 31.5], [0, 60, 23.5], [0, 0, 1]]\n" \
              "distortion_coefficients: [0, 0, 0, 0, 0]\n"


# ----------------------------------------------------------------------------------------------- file formats
def test_camera_yaml_opencv_plain_and_ros_forms(tmp_path):
    (tmp_path / "a.yaml").write_text(
        "%YAML:1.0\n---\nimage_width: 800\nimage_height: 600\ncamera_matrix: !!opencv-matrix\n   rows: 3\n"
        "   cols: 3\n   dt: d\n   data: [ 700., 0., 399.5, 0., 710., 299.5, 0., 0., 1. ]\n"
        "distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n"
        "   data: [ -0.1, 0.01, 0., 0., 0. ]\n")
    (tmp_path / "b.yaml").write_text("image_width: 800\nimage_height: 600\n"
                                     "camera_matrix: [[700, 0, 399.5], [0, 710, 299.5], [0, 0, 1]]\n"
                                     "distortion_coefficients: [-0.1, 0.01, 0, 0, 0]\n")
    (tmp_path / "c.yaml").write_text("image_width: 800\nimage_height: 600\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
                                     "  data: [700, 0, 399.5, 0, 710, 299.5, 0, 0, 1]\ndistortion_coefficients:\n"
                                     "  rows: 1\n  cols: 5\n  data: [-0.1, 0.01, 0, 0, 0]\n")
    cams = [load_camera(tmp_path / f) for f in ("a.yaml", "b.yaml", "c.yaml")]
    for c in cams:
        assert (c.width, c.height) == (800, 600)
        np.testing.assert_allclose(c.K, [[700, 0, 399.5], [0, 710, 299.5], [0, 0, 1]])
        np.testing.assert_allclose(c.dist, [-0.1, 0.01, 0, 0, 0])


@pytest.mark.parametrize("body, needle", [
    ("camera_matrix: [[700, 0, 399.5], [0, 710, 299.5]]\n", "'camera_matrix': expected shape 3x3, got 2x3"),
    ("camera_matrix: [700, 0, 399.5, 0, 710, 299.5, 0, 0, 1]\n", "expected shape 3x3, got 9"),
    ("camera_matrix: [[700, 0, 399.5], [0, 710, 299.5], [0, 0, 1]]\ndistortion_coefficients: [0.1, 0.2, 0.3]\n",
     "OpenCV takes 4, 5, 8, 12 or 14, got 3"),
    ("camera_matrix: [[0, 0, 399.5], [0, 710, 299.5], [0, 0, 1]]\n", "fx, fy > 0"),
    ("camera_matrix: [[700, 0, 399.5], [0, 710, 299.5], [0, 0, 1]\n", "line 4"),
])
def test_camera_yaml_errors_name_the_file(tmp_path, body, needle):
    p = tmp_path / "camera.yaml"
    p.write_text("image_width: 800\nimage_height: 600\n" + body)
    with pytest.raises(DatasetError) as e:
        load_camera(p)
    assert str(e.value).startswith(str(p)) and needle in str(e.value)


def test_board_yaml_and_default_outline(tmp_path):
    p = tmp_path / "board.yaml"
    p.write_text("cols: 6\nrows: 5\nsquare_m: 0.1\n")
    b = load_board(p)
    np.testing.assert_allclose(b.outline, [[-0.1, -0.1], [0.6, -0.1], [0.6, 0.5], [-0.1, 0.5]])
    assert b.corners.shape == (30, 3) and b.origin_square_dark is None and not b.reversible
    np.testing.assert_allclose(b.corners[7], [0.1, 0.1, 0.0])
    p.write_text("cols: 6\nrows: 5\nsquare_m: 0.1\noutline_m: [[0, 0], [1, 1], [1, 0], [0, 2]]\n")
    with pytest.raises(DatasetError, match="not a simple polygon"):
        load_board(p)


def test_scan_csv_forms_bad_rows_and_no_returns(tmp_path):
    b = np.radians([-10.0, -5.0, 0.0, 5.0, 10.0])
    r = np.array([4.0, 0.0, 4.1, np.inf, 4.2])
    (tmp_path / "a.csv").write_text("bearing_rad,range_m,intensity\n" + "\n".join(
        f"{float(x)!r},{y},7" for x, y in zip(b, r, strict=True)) + "\n")
    s = read_scan_csv(tmp_path / "a.csv")
    assert len(s) == 3 and s.n_dropped == 2
    np.testing.assert_allclose(s.points[1], [4.1, 0.0])
    (tmp_path / "b.csv").write_text("x,y\n# a comment\n1.0,-1.0\n\n1.0,1.0\n2.0,0.0\n")
    s = read_scan_csv(tmp_path / "b.csv")
    np.testing.assert_allclose(s.bearing, np.radians([-45.0, 0.0, 45.0]))
    (tmp_path / "c.csv").write_text("x,y\n1.0,-1.0\n1.0,oops\n")
    with pytest.raises(DatasetError, match=r"c\.csv: line 3: not a number in '1.0,oops'"):
        read_scan_csv(tmp_path / "c.csv")
    (tmp_path / "d.csv").write_text("angle,dist\n1,2\n")
    with pytest.raises(DatasetError, match=r"d\.csv: line 1: header must name"):
        read_scan_csv(tmp_path / "d.csv")


def test_scan_order_follows_the_sweep_across_the_wrap():
    b = np.radians([170.0, 175.0, -180.0, -175.0, -170.0, 10.0])  # the largest gap is -170 -> 10 deg
    s = make_scan(b, np.full(6, 5.0))
    np.testing.assert_allclose(np.degrees(s.bearing), [10, 170, 175, -180, -175, -170], atol=1e-9)


def _tiny_dataset(root: Path) -> None:
    root.mkdir()
    (root / "camera.yaml").write_text(CAMERA_YAML)
    (root / "board.yaml").write_text(BOARD_YAML)
    img = np.full((48, 64), 128, np.uint8)
    scan = "bearing_rad,range_m\n0.0,4.0\n0.01,4.0\n"
    for name in ("000", "001", "003", "004"):
        (root / f"{name}.csv").write_text(scan)
    cv2.imwrite(str(root / "000.png"), img)
    cv2.imwrite(str(root / "001.png"), np.zeros((40, 64), np.uint8))  # wrong size
    (root / "002.png").write_bytes(b"not an image")                     # unreadable (and no scan)
    cv2.imwrite(str(root / "003.jpg"), img)
    (root / "003.csv").write_text("bearing_rad,range_m\n0.0,4.0\n0.01,4.0,9\n")  # bad row (line 3)
    # 004: scan without an image


def test_load_dataset_records_per_pose_errors_and_goes_on(tmp_path):
    root = tmp_path / "ds"
    _tiny_dataset(root)
    ds = load_dataset(root)
    assert [p.name for p in ds.poses] == ["000", "001", "002", "003", "004"]
    errs = {p.name: str(p.error) for p in ds.poses}
    assert errs["000"] == "None"
    assert "001.png: image is 64x40 but camera.yaml says 64x48" in errs["001"]
    assert "002.png: cannot read image" in errs["002"]
    assert "003.csv: line 3: expected 2 fields" in errs["003"]
    assert "004.png: image missing" in errs["004"]
    obs, diags = extract(ds)
    assert obs.n_boards == 0
    assert "not found in the image" in diags[0].reason
    assert all(d.reason == errs[d.name] for d in diags[1:])
    table = format_diagnostics(diags)
    assert "skipped 003: " in table and "0 of 5 poses used" in table


def test_whole_dataset_errors(tmp_path):
    with pytest.raises(DatasetError, match="not a dataset folder"):
        load_dataset(tmp_path / "nope")
    root = tmp_path / "ds"
    _tiny_dataset(root)
    (root / "camera.yaml").unlink()
    with pytest.raises(DatasetError, match=r"camera\.yaml: cannot read"):
        load_dataset(root)


# ----------------------------------------------------------------------------------------------- segmentation
def _synthetic_scene(rng, clutter=True):
    """A full 180-degree scan of a room (walls at ~9 m), a 2 m cabinet, and a 1 m board at ~4 m."""
    bearings = np.radians(np.arange(-90, 90.001, 0.25))
    u = np.column_stack([np.cos(bearings), np.sin(bearings)])
    r = np.full(len(bearings), np.inf)
    for a, d in ((0.0, 9.0), (np.pi / 2, 8.5), (-np.pi / 2, 10.0)):
        den = u @ [np.cos(a), np.sin(a)]
        r = np.minimum(r, np.where(den > 1e-9, d / np.maximum(den, 1e-9), np.inf))
    if clutter:  # a cabinet front 2 m long at 4 m, bearing 60 deg
        c = 4.0 * np.array([np.cos(1.05), np.sin(1.05)])
        n = c / 4.0
        rc = 4.0 / np.maximum(u @ n, 1e-9)
        s = (rc[:, None] * u - c) @ [-n[1], n[0]]
        r = np.where((np.abs(s) < 1.0) & (rc < r), rc, r)
    T_lidar_cam = make_T(R_NOMINAL @ rotvec_to_matrix(rng.normal(0, 0.03, 3)), [0.05, -0.1, 0.2])
    # board: centre at 4 m, bearing 10 deg, turned 30 deg about the vertical, outline square 1 m around its centre
    yaw = np.radians(10.0 + 30.0)
    R_lb = np.column_stack([[-np.sin(yaw), np.cos(yaw), 0.0], [0.0, 0.0, -1.0], [np.cos(yaw), np.sin(yaw), 0.0]])
    centre = 4.0 * np.array([np.cos(np.radians(10)), np.sin(np.radians(10)), 0.05])
    outline = np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
    T_lidar_board = make_T(R_lb, centre)
    n, o = R_lb[:, 2], centre
    rb = (n @ o) / (np.column_stack([u, np.zeros(len(u))]) @ n)
    hit = transform_points(invert_T(T_lidar_board), np.column_stack([rb[:, None] * u, np.zeros(len(u))]))
    on = (rb > 0) & (np.abs(hit[:, 0]) <= 0.5) & (np.abs(hit[:, 1]) <= 0.5) & (rb < r)
    r_bg = r.copy()
    r = np.where(on, rb, r)
    noisy = r + rng.normal(0, 0.01, len(r))
    scan = make_scan(bearings, noisy)
    background = make_scan(bearings, r_bg + rng.normal(0, 0.01, len(r)))
    return scan, background, invert_T(T_lidar_cam) @ T_lidar_board, outline, np.flatnonzero(on)


class _Board:
    def __init__(self, outline):
        from lidarcam.rig.dataset import BoardSpec

        self.spec = BoardSpec(6, 5, 0.12, outline)


@pytest.mark.parametrize("use_background", [False, True])
def test_find_board_segment_picks_the_board(rng, use_background):
    scan, background, T_cam_board, outline, truth = _synthetic_scene(rng)
    board = _Board(outline).spec
    idx = find_board_segment(scan, T_cam_board, board, ExtractOptions(range_sigma_m=0.01),
                             background if use_background else None)
    assert set(idx) <= set(truth) and len(idx) >= len(truth) - 2


def test_find_board_segment_refuses_when_the_board_is_not_in_the_scan(rng):
    scan, _, T_cam_board, outline, truth = _synthetic_scene(rng)
    keep = np.setdiff1d(np.arange(len(scan)), truth)
    empty = make_scan(scan.bearing[keep], scan.range[keep])
    with pytest.raises(ExtractionError, match="no scan segment matches the board"):
        find_board_segment(empty, T_cam_board, _Board(outline).spec)


# ----------------------------------------------------------------------------------------------- simulated rig


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    from simulate import SimOptions
    from simulate.dataset import write_dataset

    opts = SimOptions(n_boards=6, cam_width=640, cam_height=480, focal_px=600.0, noise_mm=10.0)
    root = write_dataset(opts, 11, tmp_path_factory.mktemp("rig") / "ds", distortion=(-0.1, 0.02, 0.0, 0.0, 0.0))
    ds = load_dataset(root)
    obs, diags = extract(ds)
    return ds, obs, diags


def test_extraction_matches_the_simulated_truth(rig):
    ds, obs, diags = rig
    gt = ds.ground_truth
    assert obs.n_boards == 6, format_diagnostics(diags)
    T_lc = np.asarray(gt["T_lidar_cam"])
    np.testing.assert_allclose(obs.T_lidar_cam_true, T_lc)
    from simulate import SimOptions

    assert SimOptions.from_dict(gt["options"]).n_boards == 6
    for name, b, d in zip(obs.meta["poses"], obs.boards, diags, strict=True):
        T_true = np.asarray(gt["poses"][name]["T_cam_board"])
        e_R, e_t = pose_errors(b.T_cam_board, T_true)
        assert d.reproj_rms_px < 0.5
        assert e_R < 1.0 and e_t < 0.01 * np.linalg.norm(T_true[:3, 3]), (name, e_R, e_t)
        # every chosen scan point lies on the true board (within 5 sigma of its plane, inside its chord)
        T_lb = T_lc @ T_true
        P = transform_points(invert_T(T_lb), b.scan_3d)
        assert np.all(np.abs(P[:, 2]) < 5 * gt["range_noise_m"]), name
        lo, hi = gt["poses"][name]["board_beams"]
        assert len(b.scan) >= 0.9 * (hi - lo), (name, len(b.scan), hi - lo)


def test_calibration_from_extracted_rig_recovers_the_truth(rig):
    from calib_core import calibrate

    _, obs, _ = rig
    # 6 boards, 10 mm range noise, board poses from 640x480 images (0.2-0.6 deg per board pose). Measured on
    # seeds 11-13: zhang_pless 0.9-1.1 deg, 60-96 mm (0.1-0.25 deg, 5-21 mm with the true board poses);
    # vasconcelos 0.3-0.6 deg, 21-46 mm; peng2022 0.3-0.6 deg, 21-44 mm.
    for method in ("zhang_pless", "vasconcelos", "peng2022"):
        res = calibrate(obs, method=method)
        assert res.ok, (method, res.reason)
        e_R, e_t = pose_errors(res.T_lidar_cam, obs.T_lidar_cam_true)
        assert e_R < 2.5 and e_t < 0.15, (method, e_R, e_t)


def test_report_files_and_overlay_points_on_the_board(rig, tmp_path):
    from calib_core import calibrate
    from lidarcam.rig.report import project_scan, write_report

    ds, obs, _ = rig
    res = calibrate(obs, method="zhang_pless")
    summary = write_report(ds, obs, res, tmp_path / "rep")
    md = summary.markdown.read_text()
    for needle in ("T_lidar_cam", "T_cam_lidar", "quaternion (x, y, z, w)", "residual RMS", "Against the ground"):
        assert needle in md
    assert len(summary.overlays) == len(summary.residual_plots) == obs.n_boards
    assert all(p.exists() for p in summary.overlays + summary.residual_plots)
    assert (tmp_path / "rep" / "extrinsic.yaml").exists()
    assert max(summary.board_rms_mm) < 40.0
    for name, b, png in zip(obs.meta["poses"], obs.boards, summary.overlays, strict=True):
        uv, ok = project_scan(ds.camera, res.T_cam_lidar, b.scan)
        assert ok.mean() > 0.9
        ring = transform_points(b.T_cam_board, np.column_stack([b.outline, np.zeros(len(b.outline))]))
        poly, _ = cv2.projectPoints(ring, np.zeros(3), np.zeros(3), ds.camera.K, ds.camera.dist)
        inside = [cv2.pointPolygonTest(poly.astype(np.float32), (float(x), float(y)), True) > -3 for x, y in uv[ok]]
        assert np.mean(inside) > 0.95, name
        img = cv2.imread(str(png))  # the overlay maps image pixel (u, v) to PNG pixel (u, v)
        hsv = cv2.cvtColor(img, cv2.COLOR_BGR2HSV)
        px = np.rint(uv[ok]).astype(int)
        coloured = [hsv[v, u, 1] > 100 for u, v in px]  # the image is grey: saturated pixels are scan points
        assert np.mean(coloured) > 0.9, name


def test_bad_poses_in_a_rig_are_skipped_with_reasons(rig, tmp_path):
    ds, _, _ = rig
    root = tmp_path / "bad"
    shutil.copytree(ds.root, root)
    lines = (root / "001.csv").read_text().splitlines()
    lines[5] = "0.1;4.0"
    (root / "001.csv").write_text("\n".join(lines) + "\n")
    (root / "002.png").unlink()
    cv2.imwrite(str(root / "003.png"), cv2.resize(cv2.imread(str(root / "003.png")), (320, 240)))
    (root / "windows.yaml").write_text("units: deg\nwindows:\n  '004': [-170, -160]\n")
    bad = load_dataset(root)
    obs, diags = extract(bad)
    reasons = {d.name: d.reason for d in diags}
    assert obs.meta["poses"] == ["000", "005"]
    assert "001.csv: line 6: expected 2 fields, got 1: '0.1;4.0'" in reasons["001"]
    assert "002.png: image missing" in reasons["002"]
    assert "003.png: image is 320x240 but camera.yaml says 640x480" in reasons["003"]
    assert "manual window -170.0..-160.0 deg holds 0 points" in reasons["004"]


def test_manual_window_overrides_the_search(rig, tmp_path):
    ds, obs, diags = rig
    d = diags[2]
    lo, hi = d.bearing_deg
    root = tmp_path / "win"
    shutil.copytree(ds.root, root)
    (root / "windows.yaml").write_text(f"units: deg\nwindows:\n  '{d.name}': [{lo + 1.0}, {hi - 1.0}]\n")
    obs2, diags2 = extract(load_dataset(root))
    d2 = diags2[2]
    assert d2.used and d2.source == "window" and d2.n_points == d.n_points - 8


def test_cli_extract_and_report(rig, tmp_path, capsys):
    from calib_core import calibrate
    from lidarcam.cli import main

    ds, obs, _ = rig
    out = tmp_path / "obs.json"
    assert main(["extract", str(ds.root), "--out", str(out), "--range-sigma", "0.01"]) == 0
    text = capsys.readouterr().out
    assert "6 of 6 poses used" in text and out.exists()
    assert "capture plan: 6 boards give 1-sigma" in text
    m = re.search(r"add (\d+) boards?[^(]*\((\d+) boards in all", text)
    assert m and int(m.group(2)) == 6 + int(m.group(1)), text
    from calib_core.data.io import load_observations

    obs2 = load_observations(out)
    assert obs2.n_boards == 6 and obs2.meta["poses"] == obs.meta["poses"]
    res = calibrate(obs2, method="zhang_pless")
    res.save(tmp_path / "res.json")
    assert main(["report", str(ds.root), str(tmp_path / "res.json"), "--obs", str(out),
                 "--out", str(tmp_path / "rep")]) == 0
    assert (tmp_path / "rep" / "report.md").exists()
    capsys.readouterr()
    assert main(["extract", str(tmp_path / "missing"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a dataset folder" in err[0]


def test_keyed_xy_scans_plain_camera_and_jpg(tmp_path):
    from simulate import SimOptions
    from simulate.dataset import write_dataset

    opts = SimOptions(n_boards=4, cam_width=480, cam_height=360, focal_px=450.0, noise_mm=5.0, dist_max_m=5.0)
    root = write_dataset(opts, 5, tmp_path / "ds", keyed_scans=True, scan_columns="xy", camera_style="plain",
                         image_format="jpg")
    assert (root / "scans.csv").exists() and not (root / "000.csv").exists()
    ds = load_dataset(root)
    obs, diags = extract(ds, ExtractOptions(range_sigma_m=0.005))
    assert obs.n_boards == 4, format_diagnostics(diags)
    warn = __import__("lidarcam.rig.report", fromlist=["x"]).report_warnings
    assert "fewer than 4" in " ".join(warn(obs.subset([0, 1, 2]), [1.0] * 3))
    assert "fewer than" not in " ".join(warn(obs, [1.0] * 4))


def test_extracted_rig_carries_corners_and_lidarcam_uses_the_joint_model(rig):
    # the detected corners (distorted pixels) and the camera go into the observations; the joint model projects
    # through the dataset's distortion, so the corner residuals at the refined poses are sub-pixel
    from calib_core import calibrate

    _, obs, _ = rig
    assert obs.has_corners and obs.camera.dist[0] == -0.1
    res = calibrate(obs, "lidarcam")
    assert res.ok and res.info["covariance_model"] == "joint", res.info
    assert res.info["corner_rms_px"] < 0.5
    e_R, e_t = pose_errors(res.T_lidar_cam, obs.T_lidar_cam_true)
    assert e_R < 4 * res.sigma_rot_deg and 1000 * e_t < 4 * res.sigma_trans_mm, (e_R, e_t, res.sigma_rot_deg)
