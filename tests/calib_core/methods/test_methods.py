"""The seed methods behind calibrate(): exact recovery, invariances, noise behaviour and failures."""

import numpy as np
import pytest

import simulate
from calib_core import BoardObservation, Observations, calibrate
from calib_core.geometry.metrics import pose_errors
from calib_core.geometry.transforms import invert_T, make_T, rotvec_to_matrix
from calib_core.robust.scorers import point_to_plane
from calib_core.solvers.candidates import minimal_candidates

SEED_METHODS = ["zhang_pless_linear", "zhang_pless", "vasconcelos", "peng2022"]


def sim(n_boards, noise_mm=0.0, trial=0, seed=7, **kw):
    return simulate.generate(simulate.SimOptions(n_boards=n_boards, noise_mm=noise_mm, **kw), seed=seed, trial=trial)


def min_candidate_error(T_cands, T_true):
    """Smallest combined error (Frobenius of R difference + translation norm) over the candidates."""
    dR = np.linalg.norm(T_cands[:, :3, :3] - T_true[:3, :3], axis=(1, 2))
    dt = np.linalg.norm(T_cands[:, :3, 3] - T_true[:3, 3], axis=1)
    return np.min(np.maximum(dR, dt))


def test_truth_among_minimal_solutions_of_every_triple_on_noise_free_simulated_data():
    """>= 200 random simulated scenes: every non-degenerate triple has the truth among its solutions."""
    worst, solved = 0.0, 0
    for trial in range(200):
        obs = sim(3, trial=trial)
        c = minimal_candidates(obs)
        if c.reasons[0] is not None:       # flagged near-degenerate (e.g. nearly parallel scan lines)
            assert len(c.T_lidar_cam) == 0
            continue
        worst = max(worst, min_candidate_error(c.T_lidar_cam, obs.T_lidar_cam_true))
        solved += 1
    assert solved >= 180 and worst < 2e-9, (solved, worst)   # ~1e-9 at 3-6 m


@pytest.mark.parametrize("method", ["zhang_pless_linear", "zhang_pless"])
def test_zhang_pless_is_exact_on_noise_free_data_with_5_or_more_boards(method):
    for trial in range(10):
        obs = sim(5 + trial % 4, trial=trial)
        r = calibrate(obs, method)
        assert r.ok, r.reason
        np.testing.assert_allclose(r.T_lidar_cam, obs.T_lidar_cam_true, atol=1e-8)


@pytest.mark.parametrize("method", ["vasconcelos", "peng2022"])
def test_minimal_methods_return_the_truth_with_4_or_more_noise_free_boards(method):
    for trial in range(10):
        obs = sim(4 + trial % 3, trial=trial)
        r = calibrate(obs, method)
        assert r.ok, r.reason
        e_R, e_t = pose_errors(r.T_lidar_cam, obs.T_lidar_cam_true)
        if method == "vasconcelos":
            assert e_R < 1e-7 and e_t < 1e-9
        else:  # first/last scan points sit up to one beam step inside the board edges
            assert e_R < 1.0
            assert min_candidate_error(r.candidates, obs.T_lidar_cam_true) < 1e-9


def test_with_3_boards_point_to_plane_cannot_choose_but_peng2022_can():
    """The weakness the paper attacks: with 3 boards every candidate fits its planes exactly."""
    peng_right = 0
    for trial in range(20):
        obs = sim(3, trial=trial)
        c = minimal_candidates(obs)
        assert len(c.T_lidar_cam) >= 2
        cost = point_to_plane(obs, c.T_lidar_cam)
        assert np.all(cost < 1e-18)                # all candidates equally good under point-to-plane
        r = calibrate(obs, "peng2022")
        peng_right += pose_errors(r.T_lidar_cam, obs.T_lidar_cam_true)[0] < 1.0
    assert peng_right >= 18


@pytest.mark.parametrize("method", SEED_METHODS)
def test_relabelling_the_boards_changes_no_result(rng, method):
    obs = sim(6, noise_mm=20, trial=3)
    perm = rng.permutation(6)
    a, b = calibrate(obs, method), calibrate(obs.subset(perm), method)
    assert a.ok and b.ok
    np.testing.assert_allclose(a.T_lidar_cam, b.T_lidar_cam, atol=1e-8)


def move_camera(obs, T_new_old):
    return Observations(tuple(BoardObservation(T_new_old @ b.T_cam_board, b.outline, b.scan) for b in obs.boards),
                        obs.T_lidar_cam_true @ invert_T(T_new_old))


@pytest.mark.parametrize("method,options", [(m, {}) for m in SEED_METHODS[1:]]
                         + [("zhang_pless_linear", {"weighting": "unit"})])
def test_a_rigid_change_of_the_camera_frame_moves_the_answer_accordingly(rng, method, options):
    obs = sim(6, noise_mm=20, trial=4)
    T_new_old = make_T(rotvec_to_matrix(rng.normal(scale=0.5, size=3)), rng.normal(scale=0.5, size=3))
    a, b = calibrate(obs, method, **options), calibrate(move_camera(obs, T_new_old), method, **options)
    assert a.ok and b.ok
    np.testing.assert_allclose(b.T_lidar_cam, a.T_lidar_cam @ invert_T(T_new_old), atol=1e-7)


def test_zhang_pless_paper_weighting_is_invariant_to_camera_rotation_but_not_to_moving_its_origin(rng):
    """The printed equations N_i^T H q = |N_i|^2 weight board i by d_i, its distance from the camera
    centre: rotating the camera frame keeps every d_i, moving its origin changes them (and the noisy answer)."""
    obs = sim(6, noise_mm=20, trial=4)
    a = calibrate(obs, "zhang_pless_linear").T_lidar_cam
    T_rot = make_T(rotvec_to_matrix(rng.normal(scale=0.5, size=3)), np.zeros(3))
    np.testing.assert_allclose(calibrate(move_camera(obs, T_rot), "zhang_pless_linear").T_lidar_cam,
                               a @ invert_T(T_rot), atol=1e-7)
    T_shift = make_T(np.eye(3), [0.0, 0.0, 2.0])
    b = calibrate(move_camera(obs, T_shift), "zhang_pless_linear").T_lidar_cam
    assert not np.allclose(b, a @ invert_T(T_shift), atol=1e-4)


@pytest.fixture(scope="module")
def noisy_sets():
    return {noise: [sim(6, noise_mm=noise, trial=trial, seed=11) for trial in range(50)] for noise in (5.0, 30.0)}


@pytest.mark.parametrize("method", SEED_METHODS)
def test_error_grows_with_noise(method, noisy_sets):
    med = {}
    for noise, sets in noisy_sets.items():
        e = []
        for obs in sets:
            r = calibrate(obs, method)
            e.append(pose_errors(r.T_lidar_cam, obs.T_lidar_cam_true)[0] if r.ok else np.inf)
        med[noise] = np.median(e)
    assert med[30.0] > med[5.0], med


def parallel_boards(n, noise_mm=0.0):
    """``n`` boards all facing the camera head-on at different depths and heights (parallel planes)."""
    base = sim(n, noise_mm=noise_mm, trial=0)
    boards = []
    T_lc = base.T_lidar_cam_true
    for i in range(n):
        T_cb = make_T(np.eye(3), [-0.5 + 0.1 * i, -0.5, 3.0 + 0.5 * i])
        # scan = where the lidar plane z = 0 cuts the board: sample along that chord
        T_lb = T_lc @ T_cb
        n_L, c_L = T_lb[:3, 2], T_lb[:3, 3]
        u = np.cross(n_L, [0, 0, 1.0])
        u /= np.linalg.norm(u)
        p0 = np.linalg.lstsq(np.array([n_L, [0, 0, 1.0]]), np.array([n_L @ c_L, 0.0]), rcond=None)[0]
        pts = p0 + np.outer(np.linspace(-0.3, 0.3, 30), u)
        boards.append(BoardObservation(T_cb, [[0, 0], [1, 0], [1, 1], [0, 1]], pts[:, :2]))
    return Observations(tuple(boards), T_lc)


@pytest.mark.parametrize("method", SEED_METHODS)
def test_degenerate_sets_fail_with_a_reason(method):
    for obs, why in ((parallel_boards(6), "parallel"), (sim(2), "boards")):
        r = calibrate(obs, method)
        assert not r.ok and r.T_lidar_cam is None, (method, why)
        assert r.reason and len(r.reason) > 10


def test_a_triple_of_parallel_planes_gives_no_candidates_and_a_reason():
    c = minimal_candidates(parallel_boards(3))
    assert len(c.T_lidar_cam) == 0 and c.reasons[0] is not None and "planes" in c.reasons[0]


def test_calibrate_rejects_unknown_methods_and_options():
    from calib_core import CalibrationError
    obs = sim(6)
    with pytest.raises(CalibrationError, match="unknown method"):
        calibrate(obs, "nope")
    with pytest.raises(CalibrationError, match=r"peng2022: unknown option .delta.; it takes .*delta_m"):
        calibrate(obs, "peng2022", delta=3)


@pytest.mark.parametrize("method,key", [("lidarcam", "f_scale"), ("lidarcam", "min_conditioning"),
                                        ("zhang_pless+ml", "f_scale"), ("zhang_pless+joint", "f_scale")])
def test_an_option_that_meant_two_things_is_refused_with_its_new_name(method, key):
    from calib_core import CalibrationError, calibrate
    from calib_core.methods.options import RENAMED
    from simulate import SimOptions, generate

    obs = generate(SimOptions(n_boards=5), seed=3, trial=0)
    with pytest.raises(CalibrationError, match=RENAMED[key].split(" ")[0]):
        calibrate(obs, method, **{key: 0.05})
