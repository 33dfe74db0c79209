"""A declared scan direction (lidarcam.rig.dataset.direction): lidar.yaml's ``scan_direction`` and ``--scan-direction``
mirror the scan angles (scans, background, windows), a clockwise lidar's mirrored scans calibrate upright once declared,
the upside-down warning names the declaration or advises it, ``import radlocc`` reads a settings file's
``Laser_Direction``, and ``import`` / ``bag`` write the declaration."""

from __future__ import annotations

import contextlib
import io
import shutil

import numpy as np
import pytest

from calib_core import calibrate
from calib_core.checks.verdict import orientation_warnings
from calib_core.geometry.metrics import pose_errors
from lidarcam.cli import main as cli
from lidarcam.rig.dataset import DatasetError, load_dataset, read_scan_csv
from lidarcam.rig.extract import direction_line, extract
from simulate import SimOptions


def _run(argv: list[str]) -> tuple[int, str]:
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = cli(argv)
    return rc, buf.getvalue()


@pytest.fixture(scope="module")
def rigs(tmp_path_factory):
    """A rendered dataset (its lidar counts counter-clockwise) and its copy with every scan file mirrored, as a
    driver counting clockwise writes it."""
    from simulate.dataset import write_dataset

    root = tmp_path_factory.mktemp("direction")
    opts = SimOptions(n_boards=6, cam_width=480, cam_height=360, focal_px=450.0, noise_mm=10.0, dist_max_m=5.0)
    ccw = write_dataset(opts, 3, root / "ccw")
    cw = root / "cw"
    shutil.copytree(ccw, cw)
    for f in cw.glob("*.csv"):
        rows = np.loadtxt(f, delimiter=",", skiprows=1, ndmin=2)
        rows[:, 0] = -rows[:, 0]
        np.savetxt(f, rows, delimiter=",", header="bearing_rad,range_m", comments="", fmt="%.9g")
    return ccw, cw


def test_the_declared_direction_mirrors_the_scan_angles(rigs, tmp_path):
    ccw, cw = rigs
    folder = tmp_path / "ds"
    shutil.copytree(cw, folder)
    (folder / "lidar.yaml").write_text("scan_direction: cw\n")
    (folder / "windows.yaml").write_text("units: deg\nwindows:\n  '000': [10.0, 25.0]\n")
    ds = load_dataset(folder)
    assert (ds.scan_direction, ds.scan_direction_source) == ("cw", "lidar.yaml")
    for pose in ds.poses:
        raw = read_scan_csv(folder / f"{pose.name}.csv")
        np.testing.assert_allclose(np.sort(pose.scan.bearing), np.sort(-raw.bearing), atol=1e-12)
        # the same return at the negated bearing, its point mirrored (y -> -y)
        back = raw.range[np.argsort(-raw.bearing)]
        np.testing.assert_allclose(pose.scan.range[np.argsort(pose.scan.bearing)], back)
        np.testing.assert_allclose(np.sort(pose.scan.points[:, 1]), np.sort(-raw.points[:, 1]), atol=1e-12)
    assert ds.pose("000").window == pytest.approx((np.radians(-25.0), np.radians(-10.0)))
    same = load_dataset(folder, scan_direction="ccw")          # the option overrides the file
    assert (same.scan_direction, same.scan_direction_source) == ("ccw", "given")
    np.testing.assert_allclose(same.pose("001").scan.bearing, read_scan_csv(folder / "001.csv").bearing)
    assert load_dataset(ccw).scan_direction_source == "default"
    for text, field in (("scan_direction: sideways\n", "scan_direction"), ("direction: cw\n", "unknown keys")):
        (folder / "lidar.yaml").write_text(text)
        with pytest.raises(DatasetError, match=field) as err:
            load_dataset(folder)
        assert "lidar.yaml" in str(err.value)


def test_mirrored_scans_calibrate_upright_once_declared_and_warn_otherwise(rigs, tmp_path):
    ccw, cw = rigs
    truth = load_dataset(ccw).ground_truth["T_lidar_cam"]
    plain, _ = extract(load_dataset(ccw))
    assert not [w for w in calibrate(plain).warnings if "upside down" in w]

    undeclared, _ = extract(load_dataset(cw))
    warned = [w for w in calibrate(undeclared).warnings if "upside down" in w]
    assert warned and "--scan-direction cw" in warned[0] and "lidar.yaml" in warned[0]

    declared, _ = extract(load_dataset(cw, scan_direction="cw"))
    assert declared.meta["scan_direction"] == "cw" and declared.meta["scan_direction_source"] == "given"
    assert declared.n_boards == plain.n_boards
    for a, b in zip(declared.boards, plain.boards, strict=True):
        np.testing.assert_allclose(a.scan, b.scan, atol=1e-6)
    res = calibrate(declared)
    assert res.ok and not [w for w in res.warnings if "upside down" in w]
    e_R, e_t = pose_errors(res.T_lidar_cam, truth)
    assert float(e_R) < 2.5 and float(e_t) < 0.15

    wrong, _ = extract(load_dataset(ccw, scan_direction="cw"))   # a counter-clockwise lidar declared clockwise
    warned = [w for w in calibrate(wrong).warnings if "upside down" in w]
    assert warned and "read clockwise as declared (given)" in warned[0] and "ccw fits it upright" in warned[0]

    rc, out = _run(["extract", str(cw), "--scan-direction", "cw", "--out", str(tmp_path / "o.json")])
    assert rc == 0 and "scans read clockwise (given): bearings mirrored" in out


def test_the_warning_names_the_declaration_or_advises_it():
    T = np.eye(4)
    T[:3, :3] = [[1, 0, 0], [0, 0, 1], [0, 1, 0]]          # lidar z along the camera's +y: upside down
    assert orientation_warnings(np.eye(4)) == []
    (name, undeclared), = orientation_warnings(T)
    assert name == "mirrored" and "declare it clockwise (--scan-direction cw" in undeclared
    assert orientation_warnings(T, "ccw", "default") == orientation_warnings(T)
    (_, declared), = orientation_warnings(T, "cw", "lidar.yaml")
    assert "read clockwise as declared (lidar.yaml)" in declared and "--scan-direction" not in declared
    assert direction_line({"scan_direction": "cw", "scan_direction_source": "lidar.yaml"}) == \
        "scans read clockwise (lidar.yaml): bearings mirrored"


SETTINGS = """<?xml version="1.0"?>
<opencv_storage>
  <Laser>
    <!-- SET Laser rotation direction>
    <!-- 1 for CLOCKWISE -->
    <!-- <Laser_Direction>2</Laser_Direction> a commented-out setting is not read -->
    <Laser_Direction>{value}</Laser_Direction>
  </Laser>
</opencv_storage>
"""


def _radlocc_source(root, value: str | None):
    import cv2

    root.mkdir()
    (root / "images").mkdir()
    for n in (1, 2):
        cv2.imwrite(str(root / "images" / f"RGB{n}.png"), np.zeros((48, 64), np.uint8))
    ranges = ", ".join(f"{1.0 + 0.01 * i:.2f}" for i in range(181))      # distinct: a mirror shows
    (root / "laser.txt").write_text("".join(f"{n} -1.5707963 0.0174533 1.5707963 3 181 {ranges}\n" for n in (1, 2)))
    if value is not None:
        (root / "calib").mkdir()
        (root / "calib" / "camera.yaml").write_text(
            "image_width: 64\nimage_height: 48\ncamera_matrix: {rows: 3, cols: 3, data: [60, 0, 32, 0, 60, 24, 0, 0, "
            "1]}\ndistortion_coefficients: {rows: 1, cols: 5, data: [0, 0, 0, 0, 0]}\n")
        (root / "calib" / "CamCalibConfig.xml").write_text(SETTINGS.format(value=value))


@pytest.mark.parametrize(("value", "flag", "want"), [("1", None, "cw"), ("2", None, "ccw"), ("1", "ccw", "ccw"),
                                                      (None, None, None), (None, "cw", "cw")])
def test_import_radlocc_reads_laser_direction_beside_the_camera_file(tmp_path, value, flag, want):
    src = tmp_path / "src"
    _radlocc_source(src, value)
    camera = ["--camera", str(src / "calib" / "camera.yaml")] if value is not None else \
        ["--intrinsics", "60,60,32,24"]
    out = tmp_path / "ds"
    argv = ["import", "radlocc", str(src / "laser.txt"), "--images", str(src / "images"), *camera,
            "--board-grid", "9x6", "--square", "0.09", "--out", str(out)]
    rc, printed = _run(argv + (["--scan-direction", flag] if flag else []))
    assert rc == 0, printed
    ds = load_dataset(out)
    if want is None:
        assert not (out / "lidar.yaml").exists() and ds.scan_direction_source == "default"
        return
    assert (ds.scan_direction, ds.scan_direction_source) == (want, "lidar.yaml")
    if flag is None:
        assert f"Laser_Direction {value} in {src / 'calib' / 'CamCalibConfig.xml'}" in printed
        assert "CamCalibConfig.xml" in (out / "lidar.yaml").read_text()
    scan, raw = ds.pose("1").scan, read_scan_csv(out / "1.csv")
    np.testing.assert_allclose(np.sort(scan.bearing), np.sort(-raw.bearing if want == "cw" else raw.bearing))
    # the return at the leftmost bearing is the file's rightmost one when read clockwise
    left = raw.range[np.argmin(raw.bearing)] if want == "cw" else raw.range[np.argmax(raw.bearing)]
    assert scan.range[np.argmax(scan.bearing)] == pytest.approx(left)
    if flag is not None:              # re-imported without a declaration: the stale lidar.yaml goes
        rc, _ = _run(argv)
        assert rc == 0 and (out / "lidar.yaml").exists() == (value is not None)


def test_import_of_observations_mirrors_their_points_when_declared_clockwise():
    from lidarcam.rig.importing import mirror_observations
    from simulate import generate

    obs = generate(SimOptions(n_boards=4), seed=0, trial=0)
    m = mirror_observations(obs, "--scan-direction cw of lidarcam import")
    assert m.meta["scan_direction"] == "cw" and m.meta["scan_direction_source"].startswith("--scan-direction")
    for a, b in zip(m.boards, obs.boards, strict=True):
        np.testing.assert_allclose(np.sort(a.scan[:, 1]), np.sort(-b.scan[:, 1]))
        assert np.all(np.diff(np.arctan2(a.scan[:, 1], a.scan[:, 0])) >= 0)


def test_the_bag_verb_writes_the_declared_direction(tmp_path):
    from simulate.recording import RecordingOptions, write_recording_bag

    sim = SimOptions(n_boards=3, cam_width=480, cam_height=360, focal_px=480.0, lidar_res_deg=0.25, noise_mm=10.0,
                     render_supersample=2, dist_min_m=2.0, dist_max_m=4.0)
    write_recording_bag(sim, 3, tmp_path / "r.bag", RecordingOptions(fps=15.0, scan_hz=20.0, still_s=0.8,
                                                                      move_s=0.6, ros=1, eased=False))
    rc, printed = _run(["bag", str(tmp_path / "r.bag"), "--image-topic", "/camera/image_raw", "--scan-topic", "/scan",
                        "--camera-info-topic", "/camera/camera_info", "--board", str(tmp_path / "r.board.yaml"),
                        "--out", str(tmp_path / "ds"), "--scan-direction", "cw"])
    assert rc == 0, printed
    ds = load_dataset(tmp_path / "ds")
    assert (ds.scan_direction, ds.scan_direction_source) == ("cw", "lidar.yaml")
    raw = read_scan_csv(tmp_path / "ds" / f"{ds.poses[0].name}.csv")
    np.testing.assert_allclose(np.sort(ds.poses[0].scan.bearing), np.sort(-raw.bearing), atol=1e-12)
