"""The directions a board set cannot fix, named in lidar axes, and the one home of the board-set warnings
(calib_core.checks.degeneracy)."""

from pathlib import Path

import numpy as np
import pytest
from rigs import VERTICAL_OPTIONS, facing_board, general_rig, rig_from_boards, vertical_rig

from calib_core import calibrate
from calib_core.checks.degeneracy import (
    AXES,
    AXIS_WORDS,
    MIN_NORMAL_SPREAD_DEG,
    WARN_BELOW_BOARDS,
    board_set_warnings,
    degeneracy_warnings,
    origin_jacobian,
    undetermined_directions,
)
from calib_core.checks.profile import MIN_FREE_SPAN_M, free_span, profile_extent
from calib_core.data.io import load_observations
from calib_core.geometry.metrics import pose_errors
from calib_core.geometry.transforms import make_T, rotvec_to_matrix
from calib_core.model.residuals import range_residuals
from calib_core.refine.uncertainty import normal_spread_deg, typical_range
from lidarcam.rig.report import report_warnings

SEEDS = range(5)
NOWICKI = Path(__file__).resolve().parents[3] / "tests" / "fixtures" / "nowicki" / "observations.json"


def _projector(U):
    return U.T @ U


def _axes_projector(names):
    idx = [AXES.index(a) for a in names]
    P = np.zeros((6, 6))
    P[idx, idx] = 1.0
    return P


@pytest.mark.parametrize("seed", SEEDS)
def test_vertical_boards_leave_exactly_roll_pitch_and_height_free(seed):
    obs = vertical_rig(seed)
    d = undetermined_directions(obs, obs.T_lidar_cam_true, 0.005)
    assert d.axes == ("roll", "pitch", "z") and d.aligned and d.geometric and not d.determined
    # the undetermined subspace is exactly span(roll, pitch, z), not just near it
    np.testing.assert_allclose(_projector(d.directions), _axes_projector(d.axes), atol=1e-6)
    assert np.all(np.isinf(d.sigmas))
    msg = d.message()
    assert "every board stands vertical" in msg and "'roll_deg'" in msg and "'z_m'" in msg and "not determined" in msg


@pytest.mark.parametrize("seed", SEEDS)
def test_named_directions_leave_the_residuals_unchanged_to_first_order(seed):
    """Independent of the information matrix: moving the camera about the lidar's origin along a named axis
    changes the scan residuals by O(delta^2), along yaw by O(delta)."""
    obs = vertical_rig(seed)
    T = obs.T_lidar_cam_true
    e0 = range_residuals(T, obs.scan_data)
    delta = 1e-4

    def change(k):
        x = np.zeros(6)
        x[k] = delta
        return np.linalg.norm(range_residuals(make_T(rotvec_to_matrix(x[:3]), x[3:]) @ T, obs.scan_data) - e0)

    moved = change(AXES.index("yaw"))
    assert moved > 1e-5
    for a in ("roll", "pitch", "z"):
        assert change(AXES.index(a)) < 1e-3 * moved


def test_origin_jacobian_matches_finite_differences():
    obs = general_rig(3)
    T = obs.T_lidar_cam_true
    _, J = range_residuals(T, obs.scan_data, jacobian=True)
    Jo = origin_jacobian(J, T)
    h = 1e-7
    for k in range(6):
        x = np.zeros(6)
        x[k] = h
        Tp = make_T(rotvec_to_matrix(x[:3]), x[3:]) @ T
        Tm = make_T(rotvec_to_matrix(-x[:3]), -x[3:]) @ T
        fd = (range_residuals(Tp, obs.scan_data) - range_residuals(Tm, obs.scan_data)) / (2 * h)
        np.testing.assert_allclose(Jo[:, k], fd, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("seed", SEEDS)
def test_general_rigs_are_not_flagged(seed):
    obs = general_rig(seed)
    d = undetermined_directions(obs, obs.T_lidar_cam_true, 0.02)
    assert d.determined and len(d.directions) == 0 and d.axes == ()
    r = calibrate(obs, "lidarcam")
    assert r.ok and "degeneracy" not in r.info
    assert not any("determined" in w for w in r.info["warnings"])


def test_vertical_rig_calibration_refuses_and_names_the_directions():
    obs = vertical_rig(11)
    for method in ("lidarcam", "vasconcelos+ml", "zhang_pless_linear+ml"):
        r = calibrate(obs, method)
        assert not r.ok and r.T_lidar_cam is None, method
        assert "roll" in r.reason and "pitch" in r.reason and "z (height" in r.reason and "fixed=" in r.reason
        assert r.info["degeneracy"]["axes"] == ["roll", "pitch", "z"]
        assert r.to_dict()["degeneracy"]["cause"].startswith("every board stands vertical")


def test_boards_leaning_a_little_are_answered_with_a_sigma_that_covers_the_truth():
    """Boards leaning back by up to 1 or 10 deg (normals within 5 deg of one plane): the lean fixes roll, pitch
    and z weakly but truly (exact board poses here). They are named, not refused: answered with their 1-sigma
    (the larger of the linear and the profile one), and the reported 1-sigma covers the error."""
    for lean in (1.0, 10.0):
        answered = 0
        for seed in range(4):
            obs = vertical_rig(seed, lean_deg=lean)
            assert normal_spread_deg(obs) < MIN_NORMAL_SPREAD_DEG
            d = undetermined_directions(obs, obs.T_lidar_cam_true, 0.005)
            assert d.axes == ("roll", "pitch", "z") and d.aligned and not d.geometric and d.determined
            assert np.all(np.isfinite(d.sigmas)) and "poorly determined" in d.message()
            assert "only their lean fixes these" in d.message()
            r = calibrate(obs, "lidarcam")
            if not r.ok:                       # a tie between two answers may still be refused, by its own rule
                assert "do not decide" in r.reason
                continue
            answered += 1
            e_rot, e_trans = pose_errors(r.T_lidar_cam, obs.T_lidar_cam_true)
            assert e_rot < 3 * r.sigma_rot_deg and 1000 * e_trans < 3 * r.sigma_trans_mm, (lean, seed)
            assert any("only their lean fixes these" in w for w in r.info["warnings"])
        assert answered >= 3
    # boards leaning by up to 30 deg spread their normals beyond 5 deg: then everything is determined
    spread = 0
    for seed in range(6):
        obs = vertical_rig(seed, lean_deg=30.0)
        if normal_spread_deg(obs) >= MIN_NORMAL_SPREAD_DEG:
            spread += 1
            assert undetermined_directions(obs, obs.T_lidar_cam_true, 0.005).determined
    assert spread >= 3


@pytest.mark.parametrize("seed", range(3))
def test_a_refused_direction_is_flat_across_the_physically_possible_span(seed):
    """Boards exactly vertical: z is free at every order (its profile likelihood never rises within
    ``free_span``), so the set is refused; a lean of 3 deg makes every profile rise within it: answered."""
    obs = vertical_rig(seed)
    T, L = obs.T_lidar_cam_true, typical_range(obs)
    z = np.eye(6)[AXES.index("z")]
    assert np.isinf(profile_extent(obs.scan_data, T, z, free_span(L), L, 0.005))
    assert not undetermined_directions(obs, T, 0.005).determined
    r = calibrate(obs, "lidarcam")
    assert not r.ok and "z (height" in r.reason and "not determined" in r.reason
    leaning = vertical_rig(seed, lean_deg=3.0)
    T, L = leaning.T_lidar_cam_true, typical_range(leaning)
    assert np.isfinite(profile_extent(leaning.scan_data, T, z, free_span(L), L, 0.005))
    assert undetermined_directions(leaning, T, 0.005).determined


def test_the_free_span_refuses_nothing_under_10_deg_or_30_cm():
    """A direction is refused only when its profile stays flat across ``free_span``: more than 10 deg of
    rotation and 0.3 m of translation whatever the typical range."""
    for L in (0.1, 0.3, 0.5, 2.0, 10.0):
        span = free_span(L)
        assert span >= np.radians(10.0) and span * L >= MIN_FREE_SPAN_M >= 0.3


def test_normals_perpendicular_to_a_tilted_axis_free_the_translation_along_it():
    """Every board normal perpendicular to a = (0, sin 40, cos 40): the translation along a is free (a
    combination of y and z, not an axis)."""
    a = np.array([0.0, np.sin(np.radians(40)), np.cos(np.radians(40))])
    u1, u2 = np.array([1.0, 0.0, 0.0]), np.cross(a, [1.0, 0.0, 0.0])
    rng = np.random.default_rng(5)
    boards = []
    for phi in np.radians([-35, -20, -5, 10, 25, 40]):
        c = rng.uniform(1.5, 2.5) * np.array([1.0, rng.uniform(-0.3, 0.3), 0.0])
        boards.append(facing_board(c, np.cos(phi) * u1 + np.sin(phi) * u2, VERTICAL_OPTIONS.board_size_m))
    T = make_T(rotvec_to_matrix([0.01, -0.02, 0.03]) @ vertical_rig(0).T_lidar_cam_true[:3, :3], [0.1, 0.05, 0.1])
    obs = rig_from_boards(T, boards, VERTICAL_OPTIONS, rng)
    assert obs.n_boards >= 5
    d = undetermined_directions(obs, T, 0.005)
    v = np.r_[0.0, 0.0, 0.0, a]
    assert not d.determined and d.geometric
    assert np.linalg.norm(d.directions @ v) == pytest.approx(1.0, abs=1e-6)
    assert len(d.directions) == 1 and not d.aligned and d.axes == ("y", "z") and "a combination" in d.message()


def test_weak_for_lack_of_data_is_a_warning_not_a_refusal():
    obs = general_rig(0, n_boards=3)
    d = undetermined_directions(obs, obs.T_lidar_cam_true, 0.2)
    assert len(d.directions) and not d.geometric and d.determined
    assert "poorly determined" in d.message() and "1-sigma" in d.message()


def test_board_set_warnings_have_one_home():
    obs = general_rig(2, n_boards=6)
    assert board_set_warnings(obs) == []
    few = obs.subset(range(WARN_BELOW_BOARDS - 1))
    assert any(f"fewer than {WARN_BELOW_BOARDS}" in w for w in board_set_warnings(few))
    vert = vertical_rig(1)
    assert any("nearly in one plane" in w for w in board_set_warnings(vert))
    par = obs.subset([0, 0, 0, 0])
    assert any("near-parallel" in w for w in board_set_warnings(par))
    # the rig report uses the same warnings, thresholds included, then adds its residual outliers
    for o in (obs, few, vert, par):
        T = o.T_lidar_cam_true
        assert report_warnings(o, [1.0] * o.n_boards, T) == degeneracy_warnings(o, T)
    assert any("board 1" in w for w in report_warnings(obs, [1.0, 9.0, 1.0, 1.0, 1.0, 1.0]))


def test_vertical_boards_are_recognised_at_a_tilted_estimate():
    """An extrinsic estimated from near-vertical boards may itself be tilted by 15 deg; the boards still read
    as vertical (their normals turn onto the scan lines' normals), and roll, pitch and z are named (weak, with
    their sigma, where the lean fixes them)."""
    obs = vertical_rig(8, lean_deg=1.0)
    tilted = make_T(rotvec_to_matrix([np.radians(15), np.radians(-10), 0.0]), np.zeros(3)) @ obs.T_lidar_cam_true
    d = undetermined_directions(obs, tilted, 0.005)
    assert d.axes == ("roll", "pitch", "z") and "stands vertical" in d.cause


def _named_before_refusal(reason: str) -> list[str]:
    head = reason[:reason.index("not determined")]
    return [a for a in AXES if AXIS_WORDS[a] in head]


def _own_profile(obs, T, axis, sigma):
    L = typical_range(obs)
    return profile_extent(obs.scan_data, T, np.eye(6)[AXES.index(axis)], free_span(L), L, sigma)


@pytest.mark.parametrize("seed", range(3))
def test_a_refusal_names_only_the_axes_whose_own_profile_stays_flat(seed):
    """Boards exactly vertical: z is free at every order, roll and pitch rise (fourth order) within the span.
    The refusal stands, names z, and says roll and pitch with their profile 1-sigma instead of calling them
    free; the hint still lists all three (the planar calibration needs them)."""
    obs = vertical_rig(seed)
    T = obs.T_lidar_cam_true
    d = undetermined_directions(obs, T, 0.005)
    assert not d.determined and d.axes == ("roll", "pitch", "z") and "z" in d.free_axes
    assert set(d.free_axes) < set(d.axes)                  # roll and pitch rise: they are not called free
    msg = d.message()
    assert _named_before_refusal(msg) == list(d.free_axes)
    assert "'roll_deg'" in msg and "'pitch_deg'" in msg and "'z_m'" in msg
    for a, s in zip(d.axes, d.axis_sigmas, strict=True):
        own = _own_profile(obs, T, a, 0.005)               # computed again, independently of the analysis
        assert (a in d.free_axes) == (not np.isfinite(own)) and np.isfinite(s) == np.isfinite(own), a
        if np.isfinite(own):
            assert f"{a} {np.degrees(own):.1f} deg" in msg
    r = calibrate(obs, "lidarcam")
    assert not r.ok and _named_before_refusal(r.reason) == list(d.free_axes)
    assert r.info["degeneracy"]["free_axes"] == list(d.free_axes)


@pytest.mark.skipif(not NOWICKI.exists(), reason="the committed Nowicki observations are not in this checkout")
def test_a_real_refusal_names_no_axis_the_boards_fix():
    """Three near-vertical Nowicki boards (the subset the real experiment refuses): every axis the reason names
    as not determined has a profile flat across the span; the weak axis the boards do fix (its own profile
    rises within it) is said with its sigma, not named."""
    obs = load_observations(NOWICKI).subset([2, 3, 6])
    r = calibrate(obs, "lidarcam")
    deg = r.info["degeneracy"]
    named = _named_before_refusal(r.reason)
    assert not r.ok and named and set(named) < set(deg["axes"])
    T = r.candidates[0]
    for a in deg["axes"]:
        own = _own_profile(obs, T, a, deg["range_sigma_m"])
        assert (a in named) == (not np.isfinite(own)), a
