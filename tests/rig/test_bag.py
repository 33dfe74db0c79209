"""From a recording to a calibration: ROS 1 / ROS 2 bags written by the simulator (moving board with still
stretches, scans at another rate than images, a known clock offset) -> picking -> extract -> calibrate."""

from __future__ import annotations

import contextlib
import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from calib_core import calibrate
from calib_core.geometry.metrics import pose_errors
from lidarcam.cli import main as cli_main
from lidarcam.rig import stills, timesync
from lidarcam.rig.bag import BagError, BagSource, iter_scans, scan_arrays
from lidarcam.rig.dataset import load_dataset
from lidarcam.rig.extract import ExtractOptions, extract
from lidarcam.rig.frombag import bag_to_dataset
from simulate import SimOptions
from simulate.recording import RecordingOptions, write_recording_bag

SIM = SimOptions(n_boards=6, cam_width=480, cam_height=360, focal_px=480.0, lidar_res_deg=0.25, noise_mm=10.0,
                 render_supersample=2, dist_min_m=2.0, dist_max_m=4.0)
TOPICS = dict(image_topic="/camera/image_raw", scan_topic="/scan")
KINDS = {"ros1-raw": dict(ros=1, image_format="raw"), "ros2-sqlite3-png": dict(ros=2, storage="sqlite3",
                                                                                image_format="png"),
         "ros2-mcap-jpeg": dict(ros=2, storage="mcap", image_format="jpeg")}
OFFSET_S = 0.04


@dataclass
class Converted:
    bag: Path
    board: Path
    truth: object
    ds: Path
    doc: dict
    printed: str


@pytest.fixture(scope="module", params=list(KINDS))
def recording(request, tmp_path_factory):
    """One bag flavour written by the simulator and converted by ``lidarcam bag --estimate-offset``."""
    root = tmp_path_factory.mktemp(request.param)
    rec = RecordingOptions(fps=15.0, scan_hz=20.0, still_s=0.8, move_s=0.6, time_offset_s=OFFSET_S, eased=False,
                           **KINDS[request.param])
    bag = root / ("rec.bag" if rec.ros == 1 else "rec")
    truth = write_recording_bag(SIM, 3, bag, rec)
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = cli_main(["bag", str(bag), "--image-topic", TOPICS["image_topic"], "--scan-topic", "/scan",
                       "--camera-info-topic", "/camera/camera_info", "--board", str(root / "rec.board.yaml"),
                       "--out", str(root / "ds"), "--estimate-offset"])
    assert rc == 0, buf.getvalue()
    doc = json.loads((root / "ds" / "picking.json").read_text())
    return Converted(bag, root / "rec.board.yaml", truth, root / "ds", doc, buf.getvalue())


def test_every_still_stretch_gives_one_pose_and_only_still_frames_are_kept(recording):
    truth, doc = recording.truth, recording.doc
    assert len(doc["poses"]) == len(truth.still)
    t = np.array([p["image_stamp_ns"] for p in doc["poses"]]) / 1e9
    inside = (t[:, None] >= truth.still[:, 0]) & (t[:, None] <= truth.still[:, 1])
    assert np.all(inside.sum(axis=1) == 1), "a kept frame lies outside every still stretch"
    assert np.all(inside.sum(axis=0) == 1), "a still stretch gave no pose or two"
    kept = [f for f in doc["frames"] if f["kept"]]
    assert len(kept) == len(doc["poses"]) and len(doc["frames"]) == truth.n_images
    assert all(f["reason"] for f in doc["frames"])
    assert f"{len(truth.still)} poses kept" in recording.printed and "(estimated)" in recording.printed


def test_time_offset_is_estimated_and_pairs_are_within_tolerance(recording):
    truth, sync = recording.truth, recording.doc["sync"]
    assert sync["offset_source"] == "estimated"
    assert abs(sync["offset_s"] - truth.time_offset_s) < 0.012
    assert all(abs(p["dt_ms"]) <= 1000 * sync["tol_s"] for p in recording.doc["poses"])


def test_extract_and_calibrate_recover_the_extrinsic(recording):
    truth = recording.truth
    obs, diags = extract(load_dataset(recording.ds), ExtractOptions(range_sigma_m=0.01))
    assert obs.n_boards == len(truth.still), [d.reason for d in diags if not d.used]
    res = calibrate(obs)
    assert res.ok, res.reason
    e_R, e_t = pose_errors(res.T_lidar_cam, truth.T_lidar_cam)
    assert float(e_R) < 1.5 and float(e_t) < 0.06, (float(e_R), float(e_t))


def test_a_board_that_never_rests_gives_no_pose(tmp_path):
    rec = RecordingOptions(fps=15.0, scan_hz=20.0, still_s=0.0, move_s=1.0, ros=1)
    write_recording_bag(SimOptions(**{**SIM.to_dict(), "n_boards": 3}), 4, tmp_path / "m.bag", rec)
    conv = bag_to_dataset(tmp_path / "m.bag", tmp_path / "ds", board_path=tmp_path / "m.board.yaml",
                          camera_info_topic="/camera/camera_info", **TOPICS)
    assert conv.poses == []
    assert not any(f["kept"] for f in conv.frames)


@pytest.mark.parametrize("topic,role", [("/nope", "image"), ("/camera/camera_info", "image")])
def test_missing_or_wrong_topic_is_one_line_naming_file_and_topic(recording, tmp_path, capsys, topic, role):
    bag, board = recording.bag, recording.board
    rc = cli_main(["bag", str(bag), "--image-topic", topic, "--scan-topic", "/scan", "--camera-info-topic",
                   "/camera/camera_info", "--board", str(board), "--out", str(tmp_path / "d")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1
    assert str(bag) in err and topic in err and role in err


def test_not_a_bag_is_one_line(tmp_path, capsys):
    bad = tmp_path / "junk.bag"
    bad.write_bytes(b"not a bag at all")
    with pytest.raises(BagError, match="junk.bag"):
        with BagSource(bad):
            pass
    rc = cli_main(["bag", str(bad), "--image-topic", "/i", "--scan-topic", "/s", "--camera-info-topic", "/c",
                   "--board", str(bad), "--out", str(tmp_path / "d")])
    assert rc == 2 and len(capsys.readouterr().err.strip().splitlines()) == 1


def test_scan_ranges_outside_limits_are_no_returns(recording):
    with BagSource(recording.bag) as src:
        sc = next(iter_scans(src, "/scan"))
    step = np.radians(SIM.lidar_res_deg)
    assert np.isclose(sc.bearing[0], -np.pi / 2) and np.allclose(np.diff(sc.bearing), step, atol=1e-6)

    class Msg:  # a LaserScan's fields, with ranges on both sides of the limits
        angle_min, angle_increment, range_min, range_max = -0.1, 0.05, 0.1, 5.0
        ranges = np.array([0.05, 0.1, 2.0, 5.0, 5.5, np.inf, np.nan], np.float32)

    b, r = scan_arrays(Msg)
    assert np.allclose(b, -0.1 + 0.05 * np.arange(7))
    assert np.array_equal(np.isnan(r), [True, False, False, False, True, True, True])


# ------------------------------------------------------------------------------------------------ pure parts
def test_pair_nearest_refuses_beyond_tolerance_and_applies_the_offset():
    scans = np.array([0, 25, 50, 75, 200], np.int64) * 10**6
    imgs = np.array([1, 30, 60, 140, 190], np.int64) * 10**6
    p = timesync.pair_nearest(imgs, scans)  # default tolerance: half the median period (12.5 ms)
    assert np.isclose(p.tol_s, 0.0125)
    assert p.scan.tolist() == [0, 1, 2, -1, 4]
    assert np.allclose(p.dt_s, [-0.001, -0.005, -0.010, 0.060, 0.010])
    q = timesync.pair_nearest(imgs, scans + 10 * 10**6, 0.004, offset_s=0.010)
    assert q.scan.tolist() == [0, -1, -1, -1, -1] and np.isclose(q.offset_s, 0.01)


def test_still_runs_and_threshold():
    m = np.array([np.nan, 9, 0.3, 0.2, 0.3, 0.2, 8, 0.1, 0.2, 9, 0.3])
    assert stills.still_runs(m, 1.0, 3) == [(2, 5)]
    assert stills.still_runs(m, 1.0, 1) == [(2, 5), (7, 8)]
    rng = np.random.default_rng(0)
    noise = np.abs(rng.normal(0, 0.5, 200)) + 0.4
    assert stills.quiet_threshold(np.r_[noise, 20 + noise]) < 5


def test_offset_estimate_recovers_a_shift_of_a_synthetic_signal():
    rng = np.random.default_rng(1)
    t_img = np.arange(0, 20, 1 / 30) * 1e9
    t_scan = np.arange(0, 20, 1 / 40) * 1e9

    def speed(t):
        return np.clip(np.sin(2 * np.pi * t / 3.0), 0, None) ** 2

    for off in (-0.2, 0.0, 0.137):
        # a change between samples i-1 and i belongs to their midpoint
        mi = speed((t_img[1:] + t_img[:-1]) / 2e9) + 0.02 * rng.normal(size=len(t_img) - 1)
        ms = speed((t_scan[1:] + t_scan[:-1]) / 2e9 - off) + 0.02 * rng.normal(size=len(t_scan) - 1)
        est = timesync.estimate_offset(t_img.astype(np.int64), np.r_[np.nan, mi], t_scan.astype(np.int64),
                                       np.r_[np.nan, ms])
        assert est.reliable and abs(est.offset_s - off) < 0.003, (off, est)


# ------------------------------------------------------------------------------------------------ opt-in: memory
_PEAK_RSS = """
import resource, sys
from lidarcam.rig.frombag import bag_to_dataset
from lidarcam.rig.stills import PickOptions
conv = bag_to_dataset(sys.argv[1], sys.argv[2], "/camera/image_raw", "/scan", sys.argv[3],
                      camera_info_topic="/camera/camera_info", opts=PickOptions())
print(len(conv.poses), conv.n_images, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


@pytest.mark.slow
def test_a_2_gib_bag_is_read_in_under_1_gib_of_memory(tmp_path):
    """1280x1024 raw mono8 images at 30 fps, long rests: about 2 GiB of bag; the conversion's peak resident
    memory (a fresh process, ``ru_maxrss``) must stay under 1 GiB."""
    import subprocess
    import sys

    sim = SimOptions(n_boards=16, cam_width=1280, cam_height=1024, focal_px=1000.0, render_supersample=1,
                     noise_mm=10.0, dist_min_m=2.0, dist_max_m=4.0)
    rec = RecordingOptions(fps=30.0, scan_hz=40.0, still_s=3.0, move_s=0.5, ros=1, image_format="raw")
    truth = write_recording_bag(sim, 5, tmp_path / "big.bag", rec)
    size = (tmp_path / "big.bag").stat().st_size
    assert size > 2 * 2**30 * 0.95, f"bag is only {size / 2**30:.2f} GiB"
    out = subprocess.run([sys.executable, "-c", _PEAK_RSS, str(tmp_path / "big.bag"), str(tmp_path / "ds"),
                          str(tmp_path / "big.board.yaml")], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[2])
    n_poses, n_images, rss_kib = (int(v) for v in out.stdout.split()[-3:])
    print(f"bag {size / 2**30:.2f} GiB, {n_images} images, {n_poses} poses, peak RSS {rss_kib / 2**20:.2f} GiB")
    assert n_images == truth.n_images and n_poses == len(truth.still)
    assert rss_kib < 2**20, f"peak resident memory {rss_kib / 2**20:.2f} GiB"


def _board_with_normal(n, t=(0.0, 0.0, 3.0)):
    from calib_core.data.observations import BoardObservation
    from calib_core.geometry.transforms import make_T

    n = np.asarray(n, float) / np.linalg.norm(n)
    x = np.cross([0.0, 1.0, 0.0], n)
    x /= np.linalg.norm(x)
    R = np.column_stack([x, np.cross(n, x), n])
    outline = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    return BoardObservation(make_T(R, np.asarray(t)), outline, np.array([[3.0, 0.1], [3.0, -0.1], [3.0, 0.0]]))


def test_spread_order_prefers_the_board_that_leaves_the_plane_of_normals():
    # five normals in the x-z plane (degenerate) and one tilted up: the tilted one must be among the first three
    flat = [_board_with_normal([np.sin(a), 0.0, np.cos(a)]) for a in np.radians([-30, -15, 0, 15, 30])]
    up = _board_with_normal([0.0, np.sin(0.4), np.cos(0.4)])
    order, spread = stills.spread_order(flat + [up], np.zeros(6), 3)
    assert 5 in order and spread > 5.0
    order_flat, spread_flat = stills.spread_order(flat, np.zeros(5), 5)
    assert spread_flat < 1e-6 and sorted(order_flat) == list(range(5))


def test_too_close_needs_both_small_rotation_and_small_move():
    opts = stills.PickOptions(min_angle_deg=5.0, min_move_m=0.1)
    a = _board_with_normal([0, 0, 1]).T_cam_board
    b = _board_with_normal([np.sin(0.03), 0, np.cos(0.03)], t=(0.05, 0.0, 3.0)).T_cam_board  # 1.7 deg, ~5 cm
    c = _board_with_normal([0, 0, 1], t=(0.5, 0.0, 3.0)).T_cam_board                         # same angle, 50 cm
    centre = np.array([0.5, 0.5])
    assert stills.too_close(b, [(7, a)], centre, opts)[0] == 7
    assert stills.too_close(c, [(7, a)], centre, opts) is None


def test_scan_segment_shift_sees_a_moved_board_and_not_noise():
    rng = np.random.default_rng(2)
    step = np.radians(0.25)
    b = np.arange(-40, 41) * step
    r = 3.0 / np.cos(b)  # a wall-like board 3 m ahead
    noisy = [r + rng.normal(0, 0.02, len(b)) for _ in range(2)]
    dm, db, n = stills.scan_segment_shift(step, (b, noisy[0]), (b, noisy[1]))
    assert n == len(b) and db == 0 and dm < stills.median_shift_tolerance(0.02, n)
    dm, db, n = stills.scan_segment_shift(step, (b, noisy[0]), (b + 3 * step, noisy[1] + 0.05))
    assert np.isclose(db, 3) and dm > stills.median_shift_tolerance(0.02, n)


def test_the_bag_verb_ends_with_the_capture_planners_verdict(recording):
    last = recording.printed.strip().splitlines()[-1]
    assert last.startswith("capture plan: "), recording.printed
    assert "1-sigma" in last or "not determined" in last, last  # the planner's words, not a failure to plan


def test_a_charuco_recording_goes_through_bag_extract_and_calibrate(tmp_path):
    """``lidarcam bag`` with a ChArUco board.yaml: every still pose kept, each board found with its identified
    corners, and the extrinsic recovered."""
    from simulate.patterns import Pattern

    sim = SimOptions(**{**SIM.to_dict(), "dist_min_m": 1.5, "dist_max_m": 3.0})
    rec = RecordingOptions(fps=15.0, scan_hz=20.0, still_s=0.8, move_s=0.6, eased=False, ros=2, storage="sqlite3",
                           image_format="png")
    truth = write_recording_bag(sim, 5, tmp_path / "rec", rec, pattern=Pattern("charuco", 7, 5, 0.12, 0.09))
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        rc = cli_main(["bag", str(tmp_path / "rec"), "--image-topic", TOPICS["image_topic"], "--scan-topic", "/scan",
                       "--camera-info-topic", "/camera/camera_info", "--board", str(tmp_path / "rec.board.yaml"),
                       "--out", str(tmp_path / "ds")])
    assert rc == 0, buf.getvalue()
    ds = load_dataset(tmp_path / "ds")
    assert ds.board.kind == "charuco"
    obs, diags = extract(ds, ExtractOptions(range_sigma_m=0.01))
    assert obs.n_boards >= len(truth.still) - 1, [d.reason for d in diags if not d.used]
    res = calibrate(obs)
    e_R, e_t = pose_errors(res.T_lidar_cam, truth.T_lidar_cam)
    assert res.ok and float(e_R) < 1.0 and float(e_t) < 0.04, (float(e_R), float(e_t))


def test_a_recording_through_a_lens_a_camera_info_cannot_hold_is_refused(tmp_path):
    """A CameraInfo holds a pinhole or ROS's ``equidistant`` fisheye: a double-sphere lens is refused in one line
    before anything is written."""
    from simulate.lens import LENSES

    sim = SimOptions(**{**SIM.to_dict(), **LENSES["ds180"]})
    with pytest.raises(ValueError, match="CameraInfo holds no ds lens") as err:
        write_recording_bag(sim, 5, tmp_path / "rec", RecordingOptions(ros=2))
    assert len(str(err.value).splitlines()) == 1 and not (tmp_path / "rec").exists()
