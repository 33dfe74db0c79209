"""Our method ``lidarcam`` and the ``X+ml`` / ``X+plane`` refinement suffixes, through ``calibrate`` and the CLI."""

import json

import numpy as np
import pytest
from scenes import error_vector, make_observations, random_extrinsic, vertical_board_poses

from calib_core import METHODS, calibrate, get_method, load_result
from calib_core.data.io import save_observations
from calib_core.errors import CalibrationError
from calib_core.geometry.metrics import pose_errors
from calib_core.geometry.transforms import make_T
from calib_core.model.residuals import range_residuals
from calib_core.refine.refine import robust_cost
from lidarcam.cli import main

BASES = ["zhang_pless_linear", "vasconcelos", "peng2022"]


def test_suffixed_methods_are_registered_and_built_on_demand():
    for b in BASES:
        for s in ("ml", "plane"):
            assert f"{b}+{s}" in METHODS
    assert "lidarcam" in METHODS
    m = get_method("zhang_pless+ml")          # not in the table: built from its base on first use
    assert m.min_boards == get_method("zhang_pless").min_boards
    with pytest.raises(CalibrationError, match="unknown method"):
        get_method("peng2022+nope")
    with pytest.raises(CalibrationError, match="unknown method"):
        get_method("nope+ml")


@pytest.mark.parametrize("base", BASES)
def test_ml_suffix_stays_at_the_truth_on_noise_free_data(rng, base):
    obs = make_observations(rng, 6, 0.0)
    for suffix in ("ml", "plane"):
        r = calibrate(obs, f"{base}+{suffix}")
        assert r.ok, r.reason
        np.testing.assert_allclose(r.T_lidar_cam, obs.T_lidar_cam_true, atol=1e-8)


@pytest.mark.parametrize("base", BASES + ["zhang_pless"])
def test_ml_suffix_refines_without_raising_the_cost_and_reports_a_covariance(rng, base):
    n_near = 0
    for _ in range(4):
        obs = make_observations(rng, 7, 0.02)
        b = calibrate(obs, base)
        r = calibrate(obs, f"{base}+ml", loss="huber")
        assert r.ok == b.ok
        if not b.ok:
            continue
        assert r.info["refine_cost"] <= r.info["refine_initial_cost"] + 1e-15
        np.testing.assert_allclose(r.info["base_T_lidar_cam"], b.T_lidar_cam, atol=1e-12)
        assert r.covariance.shape == (6, 6) and np.all(np.linalg.eigvalsh(r.covariance) > 0)
        if np.all(np.array(pose_errors(b.T_lidar_cam, obs.T_lidar_cam_true)) < [3, 0.3]):   # a good start
            n_near += 1
            e_R, e_t = pose_errors(r.T_lidar_cam, obs.T_lidar_cam_true)
            assert e_R < 5 * r.sigma_rot_deg and 1000 * e_t < 5 * r.sigma_trans_mm   # ML estimate near the truth
    assert n_near >= 1


def test_suffix_options_go_to_the_right_place(rng):
    obs = make_observations(rng, 6, 0.02)
    r = calibrate(obs, "peng2022+ml", loss="cauchy", f_scale_m=0.05, range_sigma_m=0.02, delta_m=0.04)
    assert r.ok and r.info["refine_loss"] == "cauchy"
    P = calibrate(obs, "peng2022+ml", range_sigma_m=0.02).covariance
    P2 = calibrate(obs, "peng2022+ml", range_sigma_m=0.04).covariance
    np.testing.assert_allclose(P2, 4 * P, rtol=1e-6)
    with pytest.raises(CalibrationError):
        calibrate(obs, "peng2022+ml", bogus=1)


@pytest.mark.parametrize("n_boards", [3, 4, 6, 8])
def test_lidarcam_stays_at_the_truth_on_noise_free_data(rng, n_boards):
    for _ in range(3):
        obs = make_observations(rng, n_boards, 0.0)
        r = calibrate(obs)                                       # lidarcam is the default
        assert r.method == "lidarcam"
        assert r.ok, r.reason
        np.testing.assert_allclose(r.T_lidar_cam, obs.T_lidar_cam_true, atol=1e-8)


def test_lidarcam_final_cost_is_no_more_than_at_its_start(rng):
    """The answer scores no worse than the start it was refined from, to the refinement's own tolerance (a start that
    is already a range optimum, from the consensus's local optimisation, moves by its termination tolerance only)."""
    for _ in range(5):
        obs = make_observations(rng, 6, 0.02)
        r = calibrate(obs, "lidarcam")
        assert r.ok
        assert r.info["cost"] <= r.info["score_start"] * (1 + 1e-6)
        data = obs.scan_data
        # the answer is a stationary point of the range likelihood: no step of the 6 parameters lowers it
        e, J = range_residuals(r.T_lidar_cam, data, jacobian=True)
        assert np.linalg.norm(J.T @ e) < 1e-6 * np.linalg.norm(J, axis=0).max() * np.linalg.norm(e)
        assert robust_cost(e) == pytest.approx(r.info["refine_cost"], rel=1e-9)


def test_lidarcam_nees_and_error_match_its_covariance(rng):
    nees, valid = [], []
    for _ in range(60):
        obs = make_observations(rng, 8, 0.02)
        r = calibrate(obs, "lidarcam")
        valid.append(r.ok and bool(np.all(np.array(pose_errors(r.T_lidar_cam, obs.T_lidar_cam_true)) < [8, 0.8])))
        e = error_vector(r.T_lidar_cam, obs.T_lidar_cam_true)
        nees.append(e @ np.linalg.solve(r.covariance, e))
    assert np.mean(valid) >= 0.95
    assert 3.0 < np.mean(nees) < 10.0


def test_lidarcam_fails_with_a_reason_on_two_boards_and_degenerate_sets(rng):
    T = random_extrinsic(rng)
    two = make_observations(rng, 2, 0.02, T_lidar_cam=T)
    r = calibrate(two, "lidarcam")
    assert not r.ok and "at least 3 boards" in r.reason and r.T_lidar_cam is None
    flat = make_observations(rng, 6, 0.02, T_lidar_cam=T, poses=vertical_board_poses(6))
    r = calibrate(flat, "lidarcam")
    assert not r.ok and r.reason and r.T_lidar_cam is None
    # all boards parallel (same orientation, moved sideways): the minimal solver and Zhang & Pless both refuse
    P0 = vertical_board_poses(1)[0]
    poses = [P0 @ make_T(np.eye(3), [dx, 0.0, dz]) for dx, dz in ((-1.5, 0.0), (0.0, 0.5), (1.5, -0.3),
                                                                  (-3.0, 1.0), (3.0, 1.5))]
    par = make_observations(rng, range_sigma_m=0.02, T_lidar_cam=T, poses=poses)
    r = calibrate(par, "lidarcam")
    assert not r.ok and "no candidate" in r.reason


def test_lidarcam_warns_on_three_boards(rng):
    obs = make_observations(rng, 3, 0.0)
    r = calibrate(obs, "lidarcam")
    assert r.ok and any("only 3 boards" in w for w in r.info["warnings"])
    assert 0 < r.info["conditioning"] <= 1


def test_covariance_in_result_json_yaml_and_cli(rng, tmp_path, capsys):
    obs = make_observations(rng, 6, 0.02)
    save_observations(obs, tmp_path / "obs.json")
    rc = main(["calibrate", str(tmp_path / "obs.json"), "--out", str(tmp_path / "r.json"),
               "--yaml", str(tmp_path / "r.yaml")])
    out = capsys.readouterr().out
    assert rc == 0 and any(ln.startswith("lidarcam: ok") for ln in out.splitlines())  # warnings come first
    assert "1-sigma: rotation" in out and "conditioning" in out
    d = load_result(tmp_path / "r.json")
    assert d["covariance"].shape == (6, 6) and d["sigma_rot_deg"] > 0
    raw = json.loads((tmp_path / "r.json").read_text())
    assert raw["sigma_trans_mm"] == pytest.approx(1000 * np.sqrt(np.trace(d["covariance"][3:, 3:])))
    y = (tmp_path / "r.yaml").read_text()
    assert f"sigma_trans_mm: {raw['sigma_trans_mm']}" in y and "covariance:" in y and "conditioning:" in y
    main(["methods"])
    assert "peng2022+ml" in capsys.readouterr().out


@pytest.mark.parametrize("seed", range(12))
def test_lidarcam_linearised_jacobian_matches_central_differences(seed):
    """The batched residuals give each candidate's row exactly; ``lidarcam_linearised`` returns those residuals and
    a Jacobian equal to central differences, endpoint and outline rows included (poses off enough that scan points
    fall outside the outlines)."""
    from calib_core.model.linearised import lidarcam_linearised
    from calib_core.model.residuals import perturb
    from calib_core.model.score import lidarcam_residuals

    rng = np.random.default_rng(seed)
    obs = make_observations(rng, 3 + seed % 6, 0.02)
    T0 = perturb(obs.T_lidar_cam_true, rng.normal(0, [0.03] * 3 + [0.05] * 3))
    batch = np.array([perturb(T0, rng.normal(0, 0.01, 6)) for _ in range(5)])
    rows = lidarcam_residuals(obs, batch, range_sigma_m=0.02)
    for T, row in zip(batch, rows, strict=True):
        np.testing.assert_allclose(row, lidarcam_residuals(obs, T, range_sigma_m=0.02), rtol=1e-12, atol=1e-12)
    f, J = lidarcam_linearised(obs, T0, range_sigma_m=0.02)
    np.testing.assert_allclose(f, lidarcam_residuals(obs, T0, range_sigma_m=0.02), rtol=1e-12, atol=1e-12)
    h = 1e-7
    J_num = np.stack([(lidarcam_residuals(obs, perturb(T0, h * e), range_sigma_m=0.02)
                       - lidarcam_residuals(obs, perturb(T0, -h * e), range_sigma_m=0.02)) / (2 * h)
                      for e in np.eye(6)], axis=1)
    K = len(obs.scan_data.points)
    assert np.abs(J[K:]).max() > 1.0                     # the endpoint and outline rows are exercised
    np.testing.assert_allclose(J, J_num, atol=1e-6 * max(1.0, np.abs(J_num).max()))


@pytest.mark.parametrize("seed", range(6))
def test_polish_with_the_analytic_jacobian_reaches_the_forward_difference_optimum(seed):
    """``polish`` (analytic Jacobian) ends at a cost no higher than scipy's own forward-difference minimisation of
    the same residuals from the same start (to 1e-6 relative), near the same pose."""
    from scipy.optimize import least_squares

    from calib_core.model.residuals import perturb
    from calib_core.model.score import ScoreOptions, lidarcam_residuals
    from calib_core.robust.choose import polish

    rng = np.random.default_rng(100 + seed)
    obs = make_observations(rng, 3 + seed % 3, 0.02)
    T0 = perturb(obs.T_lidar_cam_true, rng.normal(0, [0.01] * 3 + [0.02] * 3))
    fun = lambda x: lidarcam_residuals(obs, perturb(T0, x), range_sigma_m=0.02)  # noqa: E731
    ref = least_squares(fun, np.zeros(6), method="trf", diff_step=1e-7, max_nfev=100)
    T_new = polish(obs, T0, 100, ScoreOptions(), 0.02)
    f_new = 0.5 * float(np.sum(lidarcam_residuals(obs, T_new, range_sigma_m=0.02) ** 2))
    assert f_new <= ref.cost * (1 + 1e-6)
    e_R, e_t = pose_errors(T_new, perturb(T0, ref.x))
    assert e_R < 0.05 and e_t < 1e-3


@pytest.mark.parametrize("seed", range(12))
def test_pruned_choice_of_starts_is_the_full_scoring_choice(seed):
    """``best_starts`` scores the outline term only where it can matter: its starts are those of the full score."""
    from calib_core.model.residuals import perturb
    from calib_core.model.score import ScoreOptions, evidence_cost
    from calib_core.robust.choose import best_starts
    from calib_core.robust.starts import distinct_order

    rng = np.random.default_rng(seed)
    obs = make_observations(rng, 3 + seed % 6, 0.02)
    C = np.array([perturb(obs.T_lidar_cam_true, rng.normal(0, [0.05] * 3 + [0.1] * 3)) for _ in range(40)])
    C[::7, :3, 3] *= -1                                  # some behind the camera: infinite costs
    n = 1 + seed % 3
    full = distinct_order(C, evidence_cost(obs, C, range_sigma_m=0.02), n)
    assert best_starts(obs, C, 0.02, ScoreOptions(), n) == full and len(full) == n


@pytest.mark.parametrize("seed", range(10))
def test_zhang_pless_on_many_subsets_at_once_equals_each_subset_alone(seed):
    """``linear_subsets`` (the consensus search's Zhang & Pless hypotheses, all subsets in one batch) gives each
    subset's ``zhang_pless_linear`` answer, exactly on noise-free data and to 1e-6 deg / 1e-7 m with noise."""
    from calib_core.data.observations import Observations
    from calib_core.solvers.zhang_pless import linear_subsets, zhang_pless_linear

    rng = np.random.default_rng(seed)
    obs = make_observations(rng, 5 + seed % 6, 0.0 if seed % 2 else 0.02)
    N = obs.n_boards
    S = np.zeros((6, N), bool)
    S[0] = True
    for k in range(1, 6):
        S[k, rng.choice(N, 5, replace=False)] = True
    T, full = linear_subsets(obs, S)
    assert full.all()
    for k in range(6):
        e_R, e_t = pose_errors(T[k], zhang_pless_linear(obs.subset(np.flatnonzero(S[k]))))
        assert e_R < 1e-6 and e_t < 1e-7
    if seed % 2:
        e_R, e_t = pose_errors(T[0], obs.T_lidar_cam_true)
        assert e_R < 1e-6 and e_t < 1e-7
    parallel = Observations(tuple(obs.boards[0] for _ in range(5)), obs.T_lidar_cam_true)
    assert not linear_subsets(parallel, np.ones((1, 5), bool))[1][0]      # one plane five times: rank deficient


@pytest.mark.parametrize("seed", range(6))
def test_gauss_newton_steps_on_some_boards_are_those_on_their_subset(seed):
    """The basin test's Gauss-Newton steps on the scan points of some boards equal the steps on the subset of those
    boards, and from a start near the truth on noise-free data they land on it."""
    from calib_core.model.residuals import perturb
    from calib_core.robust.starts import gauss_newton_steps

    rng = np.random.default_rng(seed)
    obs = make_observations(rng, 5, 0.0)
    boards = np.array([True, True, False, True, True])
    T0 = perturb(obs.T_lidar_cam_true, rng.normal(0, [0.01] * 3 + [0.02] * 3))
    T1 = gauss_newton_steps(obs.scan_data, T0, boards)
    np.testing.assert_allclose(T1, gauss_newton_steps(obs.subset(np.flatnonzero(boards)).scan_data, T0), atol=1e-12)
    T5 = gauss_newton_steps(obs.scan_data, T0, boards, n=5)
    assert max(pose_errors(T5, obs.T_lidar_cam_true)) < 1e-8
    # many starts at once, each on its own boards, take each start where it alone goes
    starts = np.array([perturb(obs.T_lidar_cam_true, rng.normal(0, [0.01] * 3 + [0.02] * 3)) for _ in range(3)])
    masks = np.array([boards, np.ones(5, bool), boards[::-1]])
    np.testing.assert_allclose(gauss_newton_steps(obs.scan_data, starts, masks),
                               [gauss_newton_steps(obs.scan_data, T, m) for T, m in zip(starts, masks, strict=True)],
                               atol=1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_scan_data_of_some_boards_is_that_of_their_subset(seed):
    """``ScanData.of_boards`` equals the scan data built from the subset of those boards (points, renumbered boards,
    planes, ranges and beams), and ``Observations.subset`` keeps the parts as they were validated."""
    rng = np.random.default_rng(seed)
    obs = make_observations(rng, 6, 0.02)
    boards = rng.random(6) < 0.6
    boards[:2] = True
    full = obs.scan_data
    full.beams  # noqa: B018 -- computed before the subset is taken: carried over
    part, ref = full.of_boards(boards), obs.subset(np.flatnonzero(boards))
    for name in ("points", "board", "normals", "offsets", "ranges", "beams"):
        np.testing.assert_array_equal(getattr(part, name), getattr(ref.scan_data, name))
    assert ref.boards == tuple(b for b, k in zip(obs.boards, boards, strict=True) if k)
    assert ref.T_lidar_cam_true is obs.T_lidar_cam_true and ref.camera is obs.camera


@pytest.mark.parametrize("seed", range(6))
def test_board_frames_map_scan_points_as_the_board_poses_do(seed):
    """``board_frames`` composes ``Phi^T (R^T (p - t) - Delta)`` for every candidate and board: the scan points and
    the endpoints in their boards' frames equal the inverse board pose applied to the inverse extrinsic."""
    from calib_core.model.residuals import endpoints_in_board, perturb, scan_points_in_boards

    rng = np.random.default_rng(seed)
    obs = make_observations(rng, 4, 0.02)
    C = np.array([perturb(obs.T_lidar_cam_true, rng.normal(0, 0.2, 6)) for _ in range(3)])
    P = scan_points_in_boards(obs, C)
    E = endpoints_in_board(obs, C)
    for m, T in enumerate(C):
        for i, b in enumerate(obs.boards):
            T_board_lidar = np.linalg.inv(b.T_cam_board) @ np.linalg.inv(T)
            p = b.scan_3d @ T_board_lidar[:3, :3].T + T_board_lidar[:3, 3]
            np.testing.assert_allclose(P[m, obs.scan_data.board == i], p, atol=1e-12)
            np.testing.assert_allclose(E[m, i], p[[0, -1]], atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 4])
def test_a_hopeless_polish_is_stopped_and_a_hopeful_one_is_not(seed):
    """``polish`` from a start far off (seeds whose full polish takes more than ``GIVE_UP_ITERATIONS`` iterations):
    with ``give_up_above`` below any cost it stops early (a higher cost than the full polish, still below the
    start's); with it above the start's cost it is the full polish."""
    from calib_core.model.residuals import perturb
    from calib_core.model.score import ScoreOptions, lidarcam_residuals
    from calib_core.robust.choose import polish

    rng = np.random.default_rng(200 + seed)
    obs = make_observations(rng, 3, 0.02)
    T0 = perturb(obs.T_lidar_cam_true, np.r_[rng.normal(0, 1.0, 3), rng.normal(0, 1.0, 3)])

    def cost(T):
        return 0.5 * float(np.sum(lidarcam_residuals(obs, T, range_sigma_m=0.02) ** 2))

    full = polish(obs, T0, 200, ScoreOptions(), 0.02)
    stopped = polish(obs, T0, 200, ScoreOptions(), 0.02, give_up_above=0.0)
    np.testing.assert_allclose(polish(obs, T0, 200, ScoreOptions(), 0.02, give_up_above=10 * cost(T0)), full,
                               atol=1e-12)
    assert cost(full) < cost(stopped) < cost(T0)


@pytest.mark.parametrize("seed", range(4))
def test_a_start_the_consensus_refined_keeps_its_refinement(seed):
    """The consensus's local optimisation that ran on exactly the consensus boards hands its refinement on: the
    choice made with it equals the choice that refines every start again (to the refinement's tolerance), and the
    start it keeps is that optimum."""
    from calib_core.methods.options import LidarcamOptions
    from calib_core.robust.choose import choose_and_refine
    from calib_core.robust.search import consensus_search

    rng = np.random.default_rng(300 + seed)
    obs = make_observations(rng, 6, 0.02)
    opts = LidarcamOptions()
    s = consensus_search(obs, None, range_sigma_m=None, outline_sigma_m=opts.score.outline_sigma_m)
    assert s.refined and all(any(np.array_equal(r.T_lidar_cam, T) for T in s.pool) for r in s.refined)
    kept = choose_and_refine(s.obs_used, s.pool, s.sigma_m, opts.score, opts.choose, refined=s.refined)
    again = choose_and_refine(s.obs_used, s.pool, s.sigma_m, opts.score, opts.choose)
    e_R, e_t = pose_errors(kept.T, again.T)  # degrees, metres: a thousandth of the noise's effect or less
    assert e_R < 1e-4 and e_t < 1e-5
    assert abs(kept.cost - again.cost) < 1e-6 * max(1.0, again.cost)


@pytest.mark.parametrize("seed", range(4))
def test_outline_term_is_the_cost_less_its_lower_bound(seed):
    """``score.outline_term`` is what the ``lidarcam`` cost adds to its ``with_outline=False`` bound."""
    from calib_core.model.residuals import perturb
    from calib_core.model.score import evidence_cost, outline_term

    rng = np.random.default_rng(400 + seed)
    obs = make_observations(rng, 5, 0.02)
    C = np.array([perturb(obs.T_lidar_cam_true, rng.normal(0, 0.1, 6)) for _ in range(12)])
    full = evidence_cost(obs, C, range_sigma_m=0.02)
    bound = evidence_cost(obs, C, range_sigma_m=0.02, with_outline=False)
    term = outline_term(obs, C)
    assert np.any(term > 0)
    np.testing.assert_allclose(bound + term, full, rtol=1e-12)
