"""Rig conditions of the simulator (simulate.rig): a physical board larger than its printed pattern, seen by the
lidar, with the pattern's outline in the file as a lower bound; intrinsics off by a drawn error, the poses PnP with
them, the error's 1-sigma stated; everything off by default without moving the existing random streams."""

import cv2
import numpy as np
import pytest

from calib_core.geometry.transforms import invert_T, transform_points
from simulate import SimOptions, generate
from simulate.camera import camera_matrix
from simulate.lidar import scan_chords
from simulate.options import RIG_DEFAULTS, hashed_settings, settings_hash
from simulate.rig import intrinsics_std, pattern_outline, physical_outline

STEP = np.radians(0.25)
MARGINS = {"board_margin_min_m": 0.0, "board_margin_max_m": 0.05}


def outside_distance(xy, outline):
    """Distance (K,) of points outside an axis-aligned rectangle ``outline`` (0 inside)."""
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    d = np.maximum(np.maximum(lo - xy, xy - hi), 0.0)
    return np.linalg.norm(d, axis=1)


@pytest.mark.parametrize("known", [False, True])
def test_the_lidar_sees_the_physical_board_beyond_the_pattern_outline(known):
    o = SimOptions(noise_mm=0.0, dist_min_m=1.0, dist_max_m=4.0, outline_known=known, **MARGINS)
    seen = []
    for trial in range(8):
        obs = generate(o, seed=4, trial=trial)
        margins = np.array(obs.meta["board_margin_m"])
        assert margins.shape == (obs.n_boards,) and np.all((margins >= 0) & (margins <= 0.05))
        for b, m in zip(obs.boards, margins, strict=True):
            T_lb = obs.T_lidar_cam_true @ b.T_cam_board
            P = transform_points(invert_T(T_lb), np.column_stack([b.scan, np.zeros(len(b.scan))]))[:, :2]
            phys = physical_outline(o, m)
            r = np.linalg.norm(b.scan[[0, -1]], axis=1)
            n_L = T_lb[:3, 2]
            u = np.column_stack([np.cos(np.arctan2(b.scan[[0, -1], 1], b.scan[[0, -1], 0])),
                                 np.sin(np.arctan2(b.scan[[0, -1], 1], b.scan[[0, -1], 0])), np.zeros(2)])
            spacing = r * STEP / np.abs(u @ n_L) ** 2 * 1.01
            # every point on the physical board; both ends of the segment lie the margin beyond the pattern
            assert np.all(outside_distance(P, phys) < 1e-9)
            ends = outside_distance(P[[0, -1]], pattern_outline(o))
            assert np.all(ends >= m - spacing - 1e-9)
            chord = scan_chords(T_lb[None], phys)[0]
            assert np.all(np.isfinite(chord))
            seen.append(ends.min())
            if known:
                assert b.outline_kind == "exact" and np.allclose(b.outline, phys)
            else:
                assert b.outline_kind == "lower_bound" and np.allclose(b.outline, pattern_outline(o))
    assert max(seen) > 0.03  # margins of several centimetres were drawn and seen


def test_the_files_camera_is_off_by_the_drawn_error_and_the_poses_are_pnp_with_it():
    o = SimOptions(pose_mode="pixel", n_boards=3, dist_min_m=1.0, dist_max_m=4.0, focal_error_rel=0.003,
                   principal_point_error_px=2.0, distortion_error=0.01)
    std = intrinsics_std(o)
    K_true = camera_matrix(o.focal_px, o.cam_width, o.cam_height)
    z = []
    for trial in range(150):
        obs = generate(o, seed=9, trial=trial)
        cam = obs.camera
        np.testing.assert_array_equal(cam.std_intrinsics, std)
        k_true = np.r_[K_true[0, 0], K_true[1, 1], K_true[0, 2], K_true[1, 2], np.zeros(4)]
        z.append((cam.intrinsics[:8] - k_true) / std)
        assert not np.any(cam.dist[4:])
        if trial < 10:
            for b in obs.boards:
                ok, rvec, tvec = cv2.solvePnP(b.corners_board, b.corners_px, cam.K, cam.dist[:4],
                                              flags=cv2.SOLVEPNP_IPPE)
                np.testing.assert_allclose(cv2.Rodrigues(rvec)[0], b.T_cam_board[:3, :3], atol=1e-9)
                np.testing.assert_allclose(tvec.ravel(), b.T_cam_board[:3, 3], atol=1e-9)
    z = np.array(z)
    # each normalised error ~ N(0, 1), drawn independently: mean square within 4 standard errors of 1
    np.testing.assert_allclose(np.mean(z**2, axis=0), 1.0, atol=4 * np.sqrt(2 / len(z)))
    assert np.all(np.abs(z.mean(axis=0)) < 4 / np.sqrt(len(z)))
    assert np.abs(np.corrcoef(z.T) - np.eye(8)).max() < 4 / np.sqrt(len(z))


def test_the_rig_conditions_draw_from_their_own_streams():
    # under common random numbers, an intrinsics error changes the camera and the poses, never the scene, the
    # scans or the corners
    base = SimOptions(pose_mode="pixel", n_boards=4)
    a = generate(base, seed=2, trial=1, stream=11)
    b = generate(SimOptions(pose_mode="pixel", n_boards=4, focal_error_rel=0.003, principal_point_error_px=2.0),
                 seed=2, trial=1, stream=11)
    np.testing.assert_array_equal(a.T_lidar_cam_true, b.T_lidar_cam_true)
    for ba, bb in zip(a.boards, b.boards, strict=True):
        np.testing.assert_array_equal(ba.scan, bb.scan)
        np.testing.assert_array_equal(ba.corners_px, bb.corners_px)
        assert not np.allclose(ba.T_cam_board, bb.T_cam_board, atol=1e-6, rtol=0)
    assert a.camera.std_intrinsics is None
    no_std = generate(SimOptions(pose_mode="pixel", n_boards=4, focal_error_rel=0.003, std_intrinsics_known=False),
                      seed=2, trial=1)
    assert no_std.camera.std_intrinsics is None


def test_the_rig_options_at_their_defaults_leave_hashes_and_keys_as_they_were():
    d = SimOptions().to_dict()
    assert set(RIG_DEFAULTS) <= set(d)
    assert not set(RIG_DEFAULTS) & set(hashed_settings(d))
    on = SimOptions(pose_mode="pixel", focal_error_rel=0.001)
    assert hashed_settings(on.to_dict())["focal_error_rel"] == 0.001
    assert settings_hash(on) != settings_hash(SimOptions(pose_mode="pixel"))
    assert settings_hash(SimOptions(outline_known=True)) != settings_hash(SimOptions())


@pytest.mark.parametrize("bad, msg", [
    ({"focal_error_rel": 0.003}, "pose_mode pixel or image"),
    ({"board_margin_max_m": 0.2}, "does not fit"),
    ({"board_margin_min_m": 0.02, "board_margin_max_m": 0.01}, "board_margin_min_m <= board_margin_max_m"),
    ({"board_margin_max_m": 0.02, "shared_scan": True}, "shared_scan"),
    ({"pose_mode": "pixel", "principal_point_error_px": -1.0}, "principal_point_error_px must be >= 0"),
])
def test_rig_options_are_validated(bad, msg):
    with pytest.raises(ValueError, match=msg):
        SimOptions(**bad)


def test_observe_poses_applies_the_rig_conditions_and_the_writers_refuse_them(tmp_path):
    from simulate import file_camera, observe_poses
    from simulate.dataset import write_dataset

    o = SimOptions(pose_mode="pixel", n_boards=3, focal_error_rel=0.003, principal_point_error_px=2.0, **MARGINS)
    obs = generate(o, seed=6, trial=2)
    T_lb = obs.T_lidar_cam_true[None] @ np.array(obs.meta["T_cam_board_true"])
    again = observe_poses(o, obs.T_lidar_cam_true, T_lb, seed=6, trial=2)
    np.testing.assert_array_equal(again.camera.K, file_camera(o, 6, 2).K)
    np.testing.assert_array_equal(again.camera.K, obs.camera.K)
    assert all(b.outline_kind == "lower_bound" for b in again.boards)
    assert len(again.meta["board_margin_m"]) == 3
    for b in again.boards:
        ok, rvec, tvec = cv2.solvePnP(b.corners_board, b.corners_px, again.camera.K, None, flags=cv2.SOLVEPNP_IPPE)
        np.testing.assert_allclose(tvec.ravel(), b.T_cam_board[:3, 3], atol=1e-9)
    with pytest.raises(ValueError, match="write_dataset: board margins and intrinsics error"):
        write_dataset(o, 0, tmp_path / "ds")
