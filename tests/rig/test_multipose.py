"""Extraction over every pose: near-duplicates, background learnt from the poses, unknown outline, ambiguity;
intrinsics from the images; the vendored ACFR rig (MIT) end to end; the public rigs when ../shared has them."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pytest

from lidarcam.rig.dataset import DatasetError, load_dataset, make_scan
from lidarcam.rig.extract import ExtractOptions, extract
from lidarcam.rig.multipose import duplicate_groups, static_masks

ROOT = Path(__file__).resolve().parents[2]
REAL = Path(os.environ.get("REAL_DATA", ROOT.parent / "shared" / "real-data"))
ACFR_FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "acfr"
NOWICKI_FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "nowicki"


def _T(rotvec, t):
    from scipy.spatial.transform import Rotation

    T = np.eye(4)
    T[:3, :3], T[:3, 3] = Rotation.from_rotvec(rotvec).as_matrix(), t
    return T


def test_duplicate_groups_join_close_poses_only():
    a = _T([0.1, 0.2, 0.0], [0.1, 0.0, 1.0])
    near = _T([0.1 + np.radians(0.5), 0.2, 0.0], [0.105, 0.0, 1.0])
    far = _T([0.1 + np.radians(3.0), 0.2, 0.0], [0.1, 0.0, 1.0])
    moved = _T([0.1, 0.2, 0.0], [0.1, 0.03, 1.0])
    assert duplicate_groups([a, near, far, None, moved, near]) == [0, 0, 1, 2, 3, 0]


def test_static_masks_find_what_stays_put(rng):
    bearing = np.radians(np.arange(-90, 90, 0.5))
    wall = 3.0 / np.cos(bearing)  # a wall at x = 3 m: static
    scans, board = [], []
    for k in range(6):
        r = wall + rng.normal(0, 0.005, len(bearing))
        on = (np.degrees(bearing) > -40 + 12 * k) & (np.degrees(bearing) < -25 + 12 * k)
        r[on] = 1.0 + 0.15 * k  # a board that moves from pose to pose
        scans.append(make_scan(bearing, r))
        board.append(on)
    masks = static_masks(scans)
    for m, on in zip(masks, board, strict=True):
        order = np.argsort(np.radians(np.arange(-90, 90, 0.5)))  # make_scan keeps this order here
        on = on[order]
        assert not m[on].any()  # the board is never background
        assert m[~on].mean() > 0.85  # the wall mostly is (not where another pose's board hides it)
    # duplicates of one pose in one group: the board is not made static by its own repeats
    dup = static_masks(scans[:1] * 3 + scans[1:], groups=[0, 0, 0, 1, 2, 3, 4, 5])
    assert not dup[0][board[0]].any()
    assert not any(m.any() for m in static_masks(scans[:2]))  # too few poses to tell


@pytest.fixture(scope="module")
def sim_rig(tmp_path_factory):
    from simulate import SimOptions
    from simulate.dataset import write_dataset

    opts = SimOptions(n_boards=6, cam_width=640, cam_height=480, focal_px=600.0, noise_mm=10.0)
    root = write_dataset(opts, 5, tmp_path_factory.mktemp("mp") / "ds", distortion=(-0.1, 0.02, 0.0, 0.0, 0.0))
    ds = load_dataset(root)
    from lidarcam.rig.intrinsics import find_corners

    poses = []
    for p in ds.poses:  # detect once; every extraction below reuses the corners
        c = find_corners(p.read_image(), ds.board)
        poses.append(dataclasses.replace(p, corners=np.zeros((0, 2)) if c is None else c))
    return dataclasses.replace(ds, poses=tuple(poses))


def test_near_duplicate_poses_are_merged_into_one_board(sim_rig):
    ds = sim_rig
    p0 = ds.poses[0]
    dup = dataclasses.replace(p0, name="900")  # the same capture twice
    ds2 = dataclasses.replace(ds, poses=ds.poses + (dup,))
    obs, diags = extract(ds2)
    one, _ = extract(ds)
    assert obs.n_boards == one.n_boards
    assert obs.meta["merged"] == {p0.name: ["900"]}
    d = {x.name: x for x in diags}
    assert d["900"].used and d["900"].board_index == d[p0.name].board_index
    assert len(obs.boards[d[p0.name].board_index].scan) == 2 * d[p0.name].n_points
    off, _ = extract(ds2, ExtractOptions(merge_duplicates=False))
    assert off.n_boards == one.n_boards + 1


def test_unknown_outline_accepts_a_board_larger_than_its_pattern(sim_rig):
    """Shrink board.yaml's outline to the pattern: with outline_known the true (longer) segment is refused or
    penalised; with outline_kind="lower_bound" the same segments as with the true outline are found."""
    from lidarcam.rig.dataset import BoardSpec
    from lidarcam.rig.importers.bouguet import grid_outline

    ds = sim_rig
    b = ds.board
    pattern = grid_outline(b.corners, 0.25 * b.square)
    small = dataclasses.replace(ds, board=BoardSpec(b.cols, b.rows, b.square, pattern, b.origin_square_dark))
    truth, dt = extract(ds)
    _, dk = extract(small)
    obs, du = extract(small, ExtractOptions(outline_kind="lower_bound"))
    seg = {d.name: d.segment for d in dt if d.used}
    assert sum(d.used and d.segment == seg.get(d.name) for d in du) == len(seg)
    assert sum(d.used and d.segment == seg.get(d.name) for d in dk) < len(seg)


def test_intrinsics_from_the_images_recover_the_camera(sim_rig):
    from lidarcam.rig.intrinsics import PARAM_NAMES, calibrate_intrinsics, format_intrinsics

    ds = sim_rig
    fit = calibrate_intrinsics({p.name: p.read_image() for p in ds.poses}, ds.board,
                               corners={p.name: p.corners for p in ds.poses})
    assert fit.rms_px < 0.5
    K = ds.camera.K
    for j, (i, k) in enumerate([(0, 0), (1, 1), (0, 2), (1, 2)]):
        assert abs(fit.camera.K[i, k] - K[i, k]) < max(4 * fit.sigma[PARAM_NAMES[j]], 2.0)
    assert all(np.isfinite(v) and v >= 0 for v in fit.sigma.values())
    # the fit's 1-sigma travels with the camera (camera.std_intrinsics of the observations), k3 fixed: exact
    np.testing.assert_array_equal(fit.camera.std_intrinsics, [fit.sigma[n] for n in PARAM_NAMES])
    assert len(fit.camera.std_intrinsics) == 4 + len(fit.camera.dist) and fit.camera.std_intrinsics[-1] == 0
    assert "reprojection RMS" in format_intrinsics(fit)[0]
    with pytest.raises(DatasetError, match="at least 3 detected boards"):
        calibrate_intrinsics({p.name: p.read_image() for p in ds.poses[:2]}, ds.board,
                             corners={p.name: p.corners for p in ds.poses[:2]})


def test_acfr_fixture_every_segment_is_the_board():
    """The vendored ACFR rig (MIT): each pose's segment lies near bearing 0 at 0.6-1.2 m, not on the static object
    at -93..-101 deg nor the one near +80 deg."""
    from lidarcam.rig.public_sets import load_acfr

    rs = load_acfr(ACFR_FIXTURE)
    obs, diags = extract(rs.dataset, ExtractOptions(outline_kind="lower_bound"))
    assert obs.n_boards == 5, [d.reason for d in diags]
    for d in diags:
        lo, hi = d.bearing_deg
        assert -30 < lo < hi < 30, (d.name, d.bearing_deg)
        assert 0.6 < d.range_m < 1.2
        assert d.n_background > 0  # the static object was recognised as background


def test_nowicki_fixture_gives_all_14_poses_each_segment_on_the_board():
    """The vendored Nowicki rig (MIT): every pose detected and paired, each segment the plate's width, and every
    board's points on its plane from the camera through the calibrated extrinsic."""
    import calib_core
    from calib_core.geometry.transforms import invert_T
    from lidarcam.rig.public_sets import load_nowicki
    from lidarcam.rig.report import board_plane_distances

    rs = load_nowicki(NOWICKI_FIXTURE)
    obs, diags = extract(rs.dataset, rs.options)
    assert obs.n_boards == 14 and all(d.used for d in diags), [d.reason for d in diags]
    widths = [np.linalg.norm(b.scan[-1] - b.scan[0]) for b in obs.boards]
    assert min(widths) > 0.95 and max(widths) < 1.25
    res = calib_core.calibrate(obs)
    assert res.ok, res.reason
    Ti = invert_T(res.T_lidar_cam)
    rms = [np.sqrt(np.mean(board_plane_distances(Ti, b.T_cam_board, b.scan) ** 2)) for b in obs.boards]
    assert max(rms) < 0.012, rms


def test_acfr_without_the_learnt_background_is_worse():
    from lidarcam.rig.public_sets import load_acfr

    rs = load_acfr(ACFR_FIXTURE)
    _, diags = extract(rs.dataset, ExtractOptions(outline_kind="lower_bound", auto_background=False,
                                                  skip_ambiguous=False))
    on_board = [d.used and -30 < d.bearing_deg[0] < d.bearing_deg[1] < 30 for d in diags]
    assert not all(on_board)


@pytest.mark.skipif(not (REAL / "rplidar-a1-tx2-edenshin").is_dir(), reason="../shared/real-data not present")
def test_edenshin_zhang_pless_reproduces_the_published_extrinsic():
    import calib_core
    from calib_core.geometry.metrics import pose_errors
    from lidarcam.rig.public_sets import load_edenshin

    rs = load_edenshin(REAL / "rplidar-a1-tx2-edenshin")
    assert rs.observations.n_boards == 19
    res = calib_core.calibrate(rs.observations, "zhang_pless")
    e_R, e_t = pose_errors(res.T_lidar_cam, rs.published)
    assert float(e_R) < 0.05 and 1000 * float(e_t) < 0.5


@pytest.mark.skipif(not (REAL / "hokuyo-usbcam-kazmierczak").is_dir(), reason="../shared/real-data not present")
def test_kazmierczak_laser_lines_pair_with_images():
    from lidarcam.rig.public_sets import load_kazmierczak

    rs = load_kazmierczak(REAL / "hokuyo-usbcam-kazmierczak")
    assert [p.name for p in rs.dataset.poses] == [str(n) for n in range(31, 62)]
    s = rs.dataset.poses[0].scan
    assert len(s) + s.n_dropped == 511 and float(np.degrees(s.bearing.min())) >= -90.01
