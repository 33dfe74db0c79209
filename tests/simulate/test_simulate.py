"""The simulator: geometry of the scans, noise, camera poses, placement constraints, seeding, CLI."""

from __future__ import annotations

import json
import zlib
from dataclasses import fields, replace

import numpy as np
import pytest

from calib_core.data.io import load_observations
from calib_core.geometry.metrics import rotation_error_deg
from calib_core.geometry.transforms import invert_T, make_T, rotvec_to_matrix, transform_points
from simulate import SceneError, SimOptions, generate, simulate_trial
from simulate.camera import (
    BoardSpec,
    camera_matrix,
    checkerboard_corners,
    detect_corners,
    project,
    render_board_image,
)
from simulate.lidar import beam_bearings, board_ranges, cast_scan, scan_chords
from simulate.options import CAMERA_DEFAULTS, CONTAMINATION_DEFAULTS, RIG_DEFAULTS, settings_hash
from simulate.scene import R_LIDAR_CAM_NOMINAL, sample_scene

STEP = np.radians(0.25)


def rng_for(name: str) -> np.random.Generator:
    return np.random.default_rng(zlib.crc32(name.encode()))


def board_frame(obs, i):
    """Scan points of board i mapped into its board frame (N,3)."""
    T_lidar_board = obs.T_lidar_cam_true @ obs.boards[i].T_cam_board
    return transform_points(invert_T(T_lidar_board), obs.boards[i].scan_3d)


def dist_to_outline(xy, outline):
    """Distance of points xy (N,2) to the polygon's boundary (N,)."""
    d = np.full(len(xy), np.inf)
    for a, b in zip(outline, np.roll(outline, -1, axis=0), strict=True):
        s = np.clip((xy - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
        d = np.minimum(d, np.linalg.norm(xy - (a + s[:, None] * (b - a)), axis=1))
    return d


NOISE_FREE = SimOptions(n_boards=8, noise_mm=0.0)


@pytest.fixture(scope="module")
def clean_trials():
    return [generate(NOISE_FREE, seed=11, trial=k) for k in range(4)]


def test_noise_free_scans_on_board_planes_and_inside_outlines(clean_trials):
    c = NOISE_FREE.board_size_m
    for obs in clean_trials:
        for i in range(obs.n_boards):
            P = board_frame(obs, i)
            assert np.max(np.abs(P[:, 2])) < 1e-12
            assert np.all(P[:, :2] > -1e-12) and np.all(P[:, :2] < c + 1e-12)


def test_scan_ends_within_one_beam_step_of_board_edges(clean_trials):
    for obs in clean_trials:
        for i, b in enumerate(obs.boards):
            T_lidar_board = obs.T_lidar_cam_true @ b.T_cam_board
            ends = scan_chords(T_lidar_board[None], b.outline)[0]
            # the analytic chord ends lie on the board's edges
            ends_W = transform_points(invert_T(T_lidar_board), np.column_stack([ends, np.zeros(2)]))
            assert np.max(dist_to_outline(ends_W[:, :2], b.outline)) < 1e-9
            bearing = np.arctan2(b.scan[:, 1], b.scan[:, 0])
            assert np.all(np.diff(bearing) > 0), "points ordered by bearing"
            end_bearing = np.arctan2(ends[:, 1], ends[:, 0])
            assert 0 <= bearing[0] - end_bearing[0] < STEP + 1e-12
            assert 0 <= end_bearing[1] - bearing[-1] < STEP + 1e-12
            # in metres: the first/last point is within one beam spacing (range x step, along the board) of an edge
            P = board_frame(obs, i)[[0, -1], :2]
            r = np.linalg.norm(b.scan[[0, -1]], axis=1)
            n_L = T_lidar_board[:3, 2]
            u = np.column_stack([np.cos(bearing[[0, -1]]), np.sin(bearing[[0, -1]]), np.zeros(2)])
            cos_inc = np.abs(u @ n_L)
            assert np.all(dist_to_outline(P, b.outline) <= r * STEP / cos_inc**2 * 1.01)


def test_point_count_matches_chord_over_beam_spacing(clean_trials):
    for obs in clean_trials:
        for b in obs.boards:
            T_lidar_board = obs.T_lidar_cam_true @ b.T_cam_board
            ends = scan_chords(T_lidar_board[None], b.outline)[0]
            span = np.diff(np.arctan2(ends[:, 1], ends[:, 0]))[0]
            assert abs(len(b.scan) - span / STEP) <= 1.0
            # the same in metres, beam spacing taken at the mean range (a tilted board: within 15 %)
            chord = np.linalg.norm(ends[1] - ends[0])
            mean_r = np.mean(np.linalg.norm(ends, axis=1))
            assert len(b.scan) >= NOISE_FREE.min_points_per_board
            assert abs(len(b.scan) - chord / (mean_r * STEP)) <= 2 + 0.35 * len(b.scan)


def test_range_noise_std_matches_noise_mm():
    opts = SimOptions(n_boards=8, noise_mm=20.0)
    residuals = []
    for k in range(10):
        obs = generate(opts, seed=3, trial=k)
        for b in obs.boards:
            T_lidar_board = obs.T_lidar_cam_true @ b.T_cam_board
            bearing = np.arctan2(b.scan[:, 1], b.scan[:, 0])
            r_true = board_ranges(bearing, T_lidar_board[None], b.outline)[0]
            r_true = np.where(np.isfinite(r_true), r_true, np.nan)  # a noisy end may fall just off the board
            residuals.append(np.linalg.norm(b.scan, axis=1) - r_true)
    res = np.concatenate(residuals)
    res = res[np.isfinite(res)]
    assert len(res) > 3000
    assert abs(np.std(res) / 0.020 - 1) < 0.05
    assert abs(np.mean(res)) < 4 * 0.020 / np.sqrt(len(res))


def test_noise_is_along_the_beam():
    rng = rng_for("test_noise_is_along_the_beam")
    scene = sample_scene(SimOptions(n_boards=3), rng)
    bearings = beam_bearings(180.0, 0.25)
    clean = cast_scan(bearings, scene.T_lidar_board, scene.outline, 30.0)
    noisy = cast_scan(bearings, scene.T_lidar_board, scene.outline, 30.0, 0.05, rng)
    for c, n in zip(clean, noisy, strict=True):
        cross = c[:, 0] * n[:, 1] - c[:, 1] * n[:, 0]
        assert np.max(np.abs(cross)) < 1e-9
        assert np.max(np.abs(n - c)) > 0.01


def test_nearest_hit_wins_for_boards_one_behind_the_other():
    R = np.array([[0.0, 0, 1], [-1, 0, 0], [0, -1, 0]])  # board facing the lidar, plane normal along +x
    near = make_T(R, [3.0, 0.5, 0.5])                     # covers y in [-0.5, 0.5]
    far = make_T(R, [5.0, 1.0, 0.5])                      # covers y in [0, 1]: partly hidden behind `near`
    outline = BoardSpec().outline()
    scans = cast_scan(beam_bearings(180.0, 0.25), np.stack([near, far]), outline, 30.0)
    assert np.allclose(scans[0][:, 0], 3.0) and np.allclose(scans[1][:, 0], 5.0)
    # far-board points are only those whose beams pass beside the near board
    assert np.all(scans[1][:, 1] / 5.0 > 0.5 / 3.0)
    assert len(scans[1]) > 0


def test_shared_scan_boards_do_not_overlap_in_bearing():
    obs = generate(SimOptions(n_boards=3, shared_scan=True, noise_mm=0.0), seed=5)
    spans = sorted((np.arctan2(b.scan[0, 1], b.scan[0, 0]), np.arctan2(b.scan[-1, 1], b.scan[-1, 0]))
                   for b in obs.boards)
    for (_, hi), (lo, _) in zip(spans[:-1], spans[1:], strict=True):
        assert lo - hi > STEP


def test_boards_in_image_in_front_at_distance_and_facing_the_camera():
    opts = SimOptions(n_boards=8)
    K = camera_matrix(opts.focal_px, opts.cam_width, opts.cam_height)
    for k in range(5):
        obs = generate(opts, seed=7, trial=k)
        t_cam_L = obs.T_lidar_cam_true[:3, 3]
        for b in obs.boards:
            corners = np.column_stack([b.outline, np.zeros(4)])
            P_C = transform_points(b.T_cam_board, corners)
            assert np.all(P_C[:, 2] > opts.min_depth_m)
            uv = project(K, b.T_cam_board, corners)
            assert np.all(uv >= 0)
            assert np.all(uv[:, 0] <= opts.cam_width - 1) and np.all(uv[:, 1] <= opts.cam_height - 1)
            T_lidar_board = obs.T_lidar_cam_true @ b.T_cam_board
            centre = transform_points(T_lidar_board, [[0.5, 0.5, 0.0]])[0]
            assert 3.0 <= np.linalg.norm(centre) <= 6.0
            los = (centre - t_cam_L) / np.linalg.norm(centre - t_cam_L)
            assert np.degrees(np.arccos(los @ T_lidar_board[:3, 2])) <= opts.max_tilt_deg + 1e-9


def test_true_extrinsic_near_nominal_axis_change():
    opts = SimOptions(n_boards=1)
    for k in range(5):
        T = generate(opts, seed=2, trial=k).T_lidar_cam_true
        assert rotation_error_deg(T[:3, :3], R_LIDAR_CAM_NOMINAL) <= opts.extrinsic_rot_deg + 1e-9
        assert opts.extrinsic_trans_min_m <= np.linalg.norm(T[:3, 3]) <= opts.extrinsic_trans_max_m
    # the nominal change: camera optical axis (z) -> lidar x, camera x -> lidar -y, camera y -> lidar -z
    assert np.array_equal(R_LIDAR_CAM_NOMINAL @ [0, 0, 1], [1, 0, 0])
    assert np.array_equal(R_LIDAR_CAM_NOMINAL @ [1, 0, 0], [0, -1, 0])
    assert np.array_equal(R_LIDAR_CAM_NOMINAL @ [0, 1, 0], [0, 0, -1])


def _pose_errors(obs):
    """Per board: rotation error (deg), translation error (m) and the 2D RMS (px) over the inner corners
    between the estimated and the true pose's projections."""
    opts = SimOptions.from_dict(obs.meta["options"])
    K = camera_matrix(opts.focal_px, opts.cam_width, opts.cam_height)
    P = checkerboard_corners(opts)
    T_true = np.array(obs.meta["T_cam_board_true"])
    T_est = np.array([b.T_cam_board for b in obs.boards])
    rms = [np.sqrt(np.mean(np.sum((project(K, a, P) - project(K, b, P)) ** 2, axis=1)))
           for a, b in zip(T_est, T_true, strict=True)]
    return (rotation_error_deg(T_est[:, :3, :3], T_true[:, :3, :3]),
            np.linalg.norm(T_est[:, :3, 3] - T_true[:, :3, 3], axis=1), np.array(rms))


def test_pixel_mode_recovers_board_pose():
    e_R0, e_t0, _ = _pose_errors(generate(SimOptions(n_boards=6, pose_mode="pixel", pixel_noise_px=0.0), seed=4))
    assert np.max(e_R0) < 1e-6 and np.max(e_t0) < 1e-8
    sigma = 0.5
    e_R, e_t, rms = _pose_errors(generate(SimOptions(n_boards=8, pose_mode="pixel", pixel_noise_px=sigma), seed=4))
    # a least-squares fit of 6 pose parameters to 2N noisy coordinates leaves a model error of 2D RMS
    # sigma * sqrt(12 / 2N) (0.45 sigma for N = 30): the pose is as good as the noise allows, no better
    n = len(checkerboard_corners(SimOptions()))
    expected = sigma * np.sqrt(12 / (2 * n))
    assert 0.6 * expected < np.sqrt(np.mean(rms**2)) < 1.5 * expected
    # a small, far board's tilt is weakly observed: 0.5 px already costs up to ~3 deg of board normal
    assert np.max(e_R) < 5.0 and np.max(e_t) < 0.15


def test_rendered_corners_are_where_the_projection_puts_them():
    rng = rng_for("test_rendered_corners_are_where_the_projection_puts_them")
    spec = BoardSpec()
    K = camera_matrix(800.0, 800, 600)
    P = checkerboard_corners(spec)
    errs = []
    for _ in range(3):
        R = rotvec_to_matrix(rng.normal(size=3) * 0.3) @ rotvec_to_matrix([0, 0, rng.uniform(-np.pi, np.pi)])
        T = make_T(R, np.array([0, 0, rng.uniform(3, 5)]) - R @ [0.5, 0.5, 0])
        img = render_board_image(K, T, spec, 800, 600)
        assert img.dtype == np.uint8 and img.shape == (600, 800)
        uv = detect_corners(img, spec)
        assert uv is not None
        errs.append(uv - project(K, T, P))
    errs = np.concatenate(errs)
    assert np.max(np.linalg.norm(errs, axis=1)) < 0.5   # same order as checkerboard_corners, not reversed
    assert np.all(np.abs(errs.mean(axis=0)) < 0.1)      # no half-pixel bias


def test_image_mode_recovers_board_pose():
    obs = generate(SimOptions(n_boards=2, pose_mode="image"), seed=9)
    e_R, e_t, rms = _pose_errors(obs)
    assert 0 < np.max(rms) < 0.3    # detected corners are accurate to a fraction of a pixel
    # a small, far board's tilt is weakly observed: 0.5 px already costs up to ~3 deg of board normal
    assert np.max(e_R) < 5.0 and np.max(e_t) < 0.15


def test_checkerboard_corners_centred_on_the_board():
    opts = SimOptions()
    P = checkerboard_corners(opts)
    assert P.shape == ((opts.board_squares_x - 1) * (opts.board_squares_y - 1), 3)
    assert np.allclose(P.mean(axis=0), [0.5, 0.5, 0.0])
    assert np.allclose(P[1] - P[0], [opts.checker_square_m, 0, 0])           # x fastest
    assert np.allclose(P[opts.board_squares_x - 1] - P[0], [0, opts.checker_square_m, 0])


def test_same_seed_same_data_other_seed_or_trial_different():
    opts = SimOptions(n_boards=4)
    a, b = generate(opts, seed=1, trial=2), generate(opts, seed=1, trial=2)
    assert np.array_equal(a.T_lidar_cam_true, b.T_lidar_cam_true)
    for ba, bb in zip(a.boards, b.boards, strict=True):
        assert np.array_equal(ba.scan, bb.scan) and np.array_equal(ba.T_cam_board, bb.T_cam_board)
    for other in (generate(opts, seed=2, trial=2), generate(opts, seed=1, trial=3)):
        assert not np.array_equal(a.T_lidar_cam_true, other.T_lidar_cam_true)
    assert a.meta["seed"] == 1 and a.meta["trial"] == 2 and a.meta["options"] == opts.to_dict()


def test_settings_hash_is_stable_and_type_blind():
    assert settings_hash(SimOptions(board_size_m=1)) == settings_hash(SimOptions(board_size_m=1.0))
    assert settings_hash(SimOptions(noise_mm=10.0)) != settings_hash(SimOptions(noise_mm=20.0))
    # the contamination options are not hashed, nor the rig and lens options at their defaults: the clean settings
    # keep the streams they had before them
    d = {k: v for k, v in SimOptions().to_dict().items()
         if k not in CONTAMINATION_DEFAULTS and k not in RIG_DEFAULTS and k not in CAMERA_DEFAULTS}
    text = json.dumps(d, sort_keys=True, separators=(",", ":"))
    assert settings_hash(SimOptions()) == zlib.crc32(text.encode())
    assert settings_hash(SimOptions(wrong_segments=1, gross_outlier_frac=0.1)) == settings_hash(SimOptions())


def test_options_validation():
    with pytest.raises(ValueError, match="max_tilt_deg"):
        SimOptions(max_tilt_deg=90.0)
    with pytest.raises(ValueError, match="pose_mode"):
        SimOptions(pose_mode="magic")
    with pytest.raises(ValueError, match="dist_min_m"):
        SimOptions(dist_min_m=7.0)
    with pytest.raises(ValueError, match="n_boards must be int"):
        SimOptions(n_boards=2.5)
    with pytest.raises(ValueError, match="does not fit"):
        SimOptions(checker_square_m=0.2)
    with pytest.raises(ValueError, match="unknown option"):
        SimOptions.from_dict({"n_board": 3})
    assert all(f.type in ("int", "float", "str", "bool") for f in fields(SimOptions))


def test_impossible_constraint_is_named():
    with pytest.raises(SceneError, match="min_points_per_board"):
        generate(SimOptions(n_boards=1, min_points_per_board=500, max_attempts=50))
    with pytest.raises(SceneError, match="inside the image"):
        generate(SimOptions(n_boards=1, focal_px=4000.0, max_attempts=50))


def test_simulate_trial_scans_match_generate():
    opts = replace(NOISE_FREE, n_boards=2)
    scene, scans, _, _ = simulate_trial(opts, seed=1)
    obs = generate(opts, seed=1)
    assert np.array_equal(scene.T_lidar_cam, obs.T_lidar_cam_true)
    assert all(np.array_equal(s, b.scan) for s, b in zip(scans, obs.boards, strict=True))


def test_cli_writes_a_valid_observation_file(tmp_path):
    from lidarcam.cli import main

    out = tmp_path / "obs.json"
    assert main(["simulate", "--boards", "3", "--noise-mm", "20", "--seed", "1", "--trial", "0",
                 "--max-tilt-deg", "30", "--pose-mode", "pixel", "--out", str(out)]) == 0
    obs = load_observations(out)
    assert obs.n_boards == 3 and obs.meta["options"]["max_tilt_deg"] == 30.0
    assert np.array_equal(obs.T_lidar_cam_true, generate(
        SimOptions(n_boards=3, max_tilt_deg=30.0, pose_mode="pixel"), seed=1).T_lidar_cam_true)
    assert main(["simulate", "--max-tilt-deg", "100", "--out", str(tmp_path / "bad.json")]) == 2


def test_undistort_points_inverts_strong_distortion_on_either_opencv_api(monkeypatch):
    """``simulate.camera.undistort_points`` undoes ``cv2.projectPoints``'s distortion to 1e-6 px, through
    ``undistortPoints(criteria=)`` (OpenCV 5) and through ``undistortPointsIter`` where ``undistortPoints`` takes no
    criteria (OpenCV 4.8, emulated)."""
    import cv2

    from simulate.camera import undistort_points

    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    dist = np.array([-0.35, 0.15, 0.001, -0.002, -0.03])
    xy = np.random.default_rng(0).uniform(-0.5, 0.5, (50, 2))
    px, _ = cv2.projectPoints(np.column_stack([xy, np.ones(50)]), np.zeros(3), np.zeros(3), K, dist)
    truth = xy * 500 + [320, 240]
    assert np.abs(undistort_points(px.reshape(-1, 2), K, dist) - truth).max() < 1e-6
    plain = cv2.undistortPoints

    def no_criteria(src, cameraMatrix, distCoeffs, R=None, P=None, **kw):
        if kw:
            raise TypeError("undistortPoints() takes no criteria (OpenCV 4.8)")
        return plain(src, cameraMatrix, distCoeffs, R=R, P=P)

    monkeypatch.setattr(cv2, "undistortPoints", no_criteria, raising=True)
    monkeypatch.setattr(cv2, "undistortPointsIter", lambda src, Km, d, R, P, crit: plain(src, Km, d, R=R, P=P,
                                                                                          criteria=crit),
                        raising=False)
    assert np.abs(undistort_points(px.reshape(-1, 2), K, dist) - truth).max() < 1e-6
