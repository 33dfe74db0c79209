"""The evidence ``lidarcam`` reads beyond the range residuals: physical plausibility of a candidate, the one-sided
terms of a lower-bound outline (chord coverage, margin prior), ties refused with their alternatives, and the
mounting prior (score, refinement, covariance, CLI)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from calib_core import calibrate
from calib_core.data.io import load_observations
from calib_core.data.observations import BoardObservation, Observations
from calib_core.errors import CalibrationError
from calib_core.geometry.metrics import pose_errors
from calib_core.geometry.mounting import MountingPrior, T_from_params, params_from_T
from calib_core.geometry.transforms import make_T
from calib_core.model.chords import _shortfalls, chord_shortfalls
from calib_core.model.linearised import lidarcam_linearised
from calib_core.model.lower_bound import MARGIN_CAP, lower_bound_rows
from calib_core.model.plausible import plausibility, plausible_boards
from calib_core.model.residuals import board_frames, perturb
from calib_core.model.score import lidarcam_residuals
from simulate import SimOptions, generate

REPO = Path(__file__).resolve().parents[3]
NOWICKI = REPO / "tests" / "fixtures" / "nowicki" / "observations.json"


def lower_bound(obs: Observations, factor) -> Observations:
    """``obs`` with every outline scaled about its centre by ``factor`` (one, or one per board) and read as a lower
    bound."""
    boards = []
    for b, k in zip(obs.boards, np.broadcast_to(factor, (obs.n_boards,)), strict=True):
        c = b.outline.mean(axis=0)
        boards.append(BoardObservation(b.T_cam_board, c + k * (b.outline - c), b.scan, b.corners_px,
                                       b.corners_board, outline_kind="lower_bound"))
    return Observations(tuple(boards), obs.T_lidar_cam_true, dict(obs.meta), obs.camera, obs.board_range_sigma_m)


def random_polygon(rng: np.random.Generator) -> np.ndarray:
    """A star-shaped polygon of 5-8 vertices about the origin (metres), holding the disc of radius 0.25 about it:
    vertices at radii 0.5-1.0, angles evenly spaced with a jitter of under half a spacing."""
    V = int(rng.integers(5, 9))
    ang = (np.arange(V) + rng.uniform(-0.25, 0.25, V)) * 2 * np.pi / V
    return np.stack([np.cos(ang), np.sin(ang)], axis=1) * rng.uniform(0.5, 1.0, (V, 1))


def test_chord_shortfall_zero_when_covered_positive_when_short_and_rigid_invariant():
    rng = np.random.default_rng(0)
    for _ in range(200):
        a = random_polygon(rng)
        d = rng.normal(size=2)
        d /= np.linalg.norm(d)
        far = np.stack([-3 * d, 3 * d])                       # a segment through the origin, well past the polygon
        f, _ = _shortfalls(far[0], far[1], a, False)
        assert np.all(f == 0)
        f, _ = _shortfalls(-0.05 * d, 0.15 * d, a, False)   # ends inside the polygon: short at both ends
        assert np.all(f > 0.2)
        th = rng.uniform(0, 2 * np.pi)
        R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        sh = rng.normal(size=2)
        p0, p1 = rng.normal(scale=0.4, size=(2, 2))
        f1, _ = _shortfalls(p0, p1, a, False)
        f2, _ = _shortfalls(R @ p0 + sh, R @ p1 + sh, a @ R.T + sh, False)
        np.testing.assert_allclose(f1, f2, atol=1e-12)
        f3, _ = _shortfalls(p1, p0, a, False)                # the segment reversed: the shortfalls swap
        np.testing.assert_allclose(f1, f3[::-1], atol=1e-12)


def test_chord_shortfall_gradient_matches_finite_differences():
    rng = np.random.default_rng(1)
    checked = 0
    for _ in range(300):
        a = random_polygon(rng)
        p = rng.normal(scale=0.3, size=(2, 2))
        f, g = _shortfalls(p[0], p[1], a, True)
        if not np.any(f > 1e-3):
            continue
        h = 1e-7
        for j in range(2):
            for c in range(2):
                dp = np.zeros((2, 2))
                dp[j, c] = h
                fp, _ = _shortfalls(*(p + dp), a, False)
                fm, _ = _shortfalls(*(p - dp), a, False)
                np.testing.assert_allclose(g[:, j, c], (fp - fm) / (2 * h), atol=1e-5)
        checked += 1
    assert checked > 50


@pytest.mark.parametrize("seed", range(4))
def test_linearised_rows_of_the_lower_bound_and_prior_match_finite_differences(seed):
    obs = lower_bound(generate(SimOptions(n_boards=6), seed=seed, trial=0), [0.5, 1.5, 0.9, 1.3, 0.85, 1.5])
    rng = np.random.default_rng(seed)
    T = perturb(obs.T_lidar_cam_true, np.r_[rng.normal(scale=0.03, size=3), rng.normal(scale=0.05, size=3)])
    prior = MountingPrior(perturb(T, rng.normal(scale=0.1, size=6)), 0.1, 0.05)
    kw = {"range_sigma_m": 0.02, "prior": prior, "chord_cap": 1e6}
    r, J = lidarcam_linearised(obs, T, **kw)
    np.testing.assert_allclose(r, lidarcam_residuals(obs, T, **kw), atol=1e-12)
    h = 1e-7
    def res(x):
        return lidarcam_residuals(obs, perturb(T, x), **kw)

    Jn = np.stack([(res(h * e) - res(-h * e)) / (2 * h) for e in np.eye(6)], axis=1)
    rc, Jc, rm, Jm = lower_bound_rows(obs, T, board_frames(obs, T[None]), cap=1e6)
    assert np.any(rc > 0) and np.any(rm > 0)                 # the terms are live at this pose
    assert np.any((rm > 0) & (rm < np.sqrt(2 * MARGIN_CAP)))  # some margin rows below their cap (not flat)
    np.testing.assert_allclose(J, Jn, atol=1e-4 * max(1.0, np.abs(Jn).max()))


def test_prior_is_zero_at_its_pose_and_its_jacobian_matches_finite_differences():
    rng = np.random.default_rng(2)
    for _ in range(50):
        T0 = T_from_params(np.r_[rng.uniform(-np.pi, np.pi, 3) * [1, 0.4, 1], rng.normal(size=3)])
        p = MountingPrior(T0, rng.uniform(0.01, 0.3), rng.uniform(0.01, 0.3))
        np.testing.assert_allclose(p.residuals(T0), 0, atol=1e-12)
        T = perturb(T0, rng.normal(scale=0.3, size=6))
        h = 1e-7
        Jn = np.stack([(p.residuals(perturb(T, h * e)) - p.residuals(perturb(T, -h * e))) / (2 * h)
                       for e in np.eye(6)], axis=1)
        np.testing.assert_allclose(p.jacobian(T), Jn, atol=1e-5 * np.abs(Jn).max())


def test_prior_from_params_needs_all_six_and_positive_sigmas():
    pose = {"roll_deg": 0, "pitch_deg": 0, "yaw_deg": 90, "x_m": 0.1, "y_m": 0.0, "z_m": 0.05}
    p = MountingPrior.from_params(pose, 10.0, 0.05)
    np.testing.assert_allclose(params_from_T(p.T_lidar_cam), [0, 0, np.pi / 2, 0.1, 0, 0.05], atol=1e-12)
    with pytest.raises(CalibrationError, match="missing z_m"):
        MountingPrior.from_params({k: v for k, v in pose.items() if k != "z_m"}, 10.0, 0.05)
    with pytest.raises(CalibrationError, match="sigma_trans_m"):
        MountingPrior(p.T_lidar_cam, 0.1, 0.0)


@pytest.mark.parametrize("seed", range(6))
def test_the_truth_is_plausible_and_a_lidar_mirrored_through_a_board_plane_is_not(seed):
    obs = generate(SimOptions(n_boards=6), seed=seed, trial=0)
    T = obs.T_lidar_cam_true
    assert plausible_boards(obs, T[None]).all()
    n, d = obs.planes_cam()
    for i in range(obs.n_boards):   # move the lidar's origin to its mirror image through board i's plane
        o = -T[:3, :3].T @ T[:3, 3]                          # lidar origin in the camera frame
        o_m = o - 2 * (n[i] @ o - d[i]) * n[i]
        Tm = make_T(T[:3, :3], -T[:3, :3] @ o_m)
        assert not plausibility(obs, Tm[None])["same_side"][0, i]
    flipped = Observations(tuple(BoardObservation(b.T_cam_board @ np.diag([1.0, -1.0, -1.0, 1.0]), b.outline, b.scan)
                                 for b in obs.boards), T)   # the other face's pose: the same plane
    C = perturb(np.repeat(T[None], 30, axis=0), np.random.default_rng(seed).normal(scale=0.5, size=(30, 6)))
    np.testing.assert_array_equal(plausibility(obs, C)["same_side"], plausibility(flipped, C)["same_side"])


def nowicki_tie() -> tuple[Observations, tuple]:
    obs = load_observations(NOWICKI)
    return obs, (0, 4, 8)


def test_a_tie_is_refused_naming_its_alternatives_and_reaches_the_json(tmp_path):
    obs, s = nowicki_tie()
    res = calibrate(obs.subset(list(s)))
    assert not res.ok and "do not decide" in res.reason
    alts = res.info["alternatives"]
    assert len(alts) >= 2 and alts[1]["cost"] - alts[0]["cost"] < 0.1
    assert pose_errors(np.array(alts[0]["T_lidar_cam"]), np.array(alts[1]["T_lidar_cam"]))[0] > 1.0
    for a in alts:
        assert f"cost {a['cost']:.6g}" in res.reason
    res.save(tmp_path / "r.json")
    back = json.loads((tmp_path / "r.json").read_text())
    assert [a["cost"] for a in back["alternatives"]] == [a["cost"] for a in alts]


def test_a_mounting_prior_decides_a_tie_and_enters_the_covariance():
    obs, s = nowicki_tie()
    sub = obs.subset(list(s))
    alts = calibrate(sub).info["alternatives"]
    for a in alts[:2]:
        T = np.array(a["T_lidar_cam"])
        prior = MountingPrior(perturb(T, np.r_[0.02, -0.02, 0.01, 0.02, 0.01, -0.02]), np.radians(10), 0.05)
        res = calibrate(sub, prior=prior)
        assert res.ok, res.reason
        e_R, e_t = pose_errors(res.T_lidar_cam, T)
        assert e_R < 3 and e_t < 0.1
        assert res.info["prior"]["sigma_trans_m"] == 0.05
    full = calibrate(obs)
    weak = calibrate(obs, prior=MountingPrior(full.T_lidar_cam, np.radians(90), 100.0))
    np.testing.assert_allclose(weak.T_lidar_cam, full.T_lidar_cam, atol=1e-6)
    np.testing.assert_allclose(weak.covariance, full.covariance, rtol=1e-3, atol=1e-12)
    strong = calibrate(obs, prior=MountingPrior(full.T_lidar_cam, np.radians(0.01), 1e-4))
    assert np.all(np.linalg.eigvalsh(full.covariance - strong.covariance) > -1e-15)
    assert strong.sigma_trans_mm < 0.2 * full.sigma_trans_mm


def test_prior_refused_by_methods_that_do_not_model_it():
    obs = generate(SimOptions(n_boards=5), seed=0, trial=0)
    prior = MountingPrior(obs.T_lidar_cam_true, 0.1, 0.05)
    with pytest.raises(CalibrationError, match="takes no mounting prior"):
        calibrate(obs, "peng2022", prior=prior)
    with pytest.raises(CalibrationError, match="MountingPrior"):
        calibrate(obs, prior={"x_m": 0.1})


def test_the_same_three_boards_give_the_same_answer_or_refusal_in_two_processes():
    code = ("import json, sys; import numpy as np; from calib_core import calibrate; "
            "from calib_core.data.io import load_observations; "
            f"o = load_observations({str(NOWICKI)!r}); "
            "out = [];\nfor s in [(0, 1, 5), (0, 12, 13), (4, 7, 13), (1, 3, 5), (6, 8, 10)]:\n"
            "    r = calibrate(o.subset(list(s))); "
            "out.append([r.ok, r.reason, None if r.T_lidar_cam is None else r.T_lidar_cam.tolist()])\n"
            "print(json.dumps(out))")
    runs = [subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO,
                           env={"PYTHONHASHSEED": str(k), "OMP_NUM_THREADS": "1", "PATH": ""}).stdout
            for k in (1, 2)]
    a, b = (json.loads(r) for r in runs)
    assert [x[0] for x in a] == [x[0] for x in b] and [x[1] for x in a] == [x[1] for x in b]
    for x, y in zip(a, b, strict=True):
        if x[0]:
            np.testing.assert_allclose(x[2], y[2], atol=1e-9)


def test_exact_outlines_read_no_lower_bound_term():
    obs = generate(SimOptions(n_boards=4), seed=3, trial=0)
    assert np.all(chord_shortfalls(obs, obs.T_lidar_cam_true[None]) == 0)
    low = lower_bound(obs, 0.3)
    assert np.all(chord_shortfalls(low, obs.T_lidar_cam_true[None]) == 0)   # the pattern's chord is covered
    big = lower_bound(obs, 3.0)                                               # a "lower bound" larger than the board
    assert np.all(chord_shortfalls(big, obs.T_lidar_cam_true[None]) > 0.05)


def test_cli_prior_flags_parse_with_units_and_decide_the_tie(tmp_path, capsys):
    from lidarcam.cli import main, parse_prior

    p = parse_prior("x=0.1,y=0,z=0.05,roll=0,pitch=0,yaw=90", "50mm,10deg")
    assert p.sigma_trans_m == pytest.approx(0.05) and p.sigma_rot_rad == pytest.approx(np.radians(10))
    np.testing.assert_allclose(params_from_T(p.T_lidar_cam), [0, 0, np.pi / 2, 0.1, 0, 0.05], atol=1e-12)
    assert parse_prior("x_m=0.1,y=0,z=0.05,roll=0,pitch=0,yaw_deg=90", "0.2rad,5cm").sigma_trans_m == \
        pytest.approx(0.05)
    for pose, sigma, match in (("x=0.1", "50mm,10deg", "missing"), ("x=0.1,y=0,z=0,roll=0,pitch=0,yaw=0", "50mm",
                                                                    "one translation and one rotation"),
                               ("x=0.1,y=0,z=0,roll=0,pitch=0,yaw=0", "50,10deg", "bad item"),
                               ("x=0.1,y=0,z=0,roll=0,pitch=0,yaw=0", None, "go together")):
        with pytest.raises(CalibrationError, match=match):
            parse_prior(pose, sigma)
    obs, s = nowicki_tie()
    from calib_core.data.io import save_observations

    save_observations(obs.subset(list(s)), tmp_path / "o.json")
    assert main(["calibrate", str(tmp_path / "o.json"), "--out", str(tmp_path / "r.json")]) == 1
    alt = json.loads((tmp_path / "r.json").read_text())["alternatives"][1]["mounting"]
    guess = ",".join(f"{k.rsplit('_', 1)[0]}={v:.3f}" for k, v in alt.items())
    assert main(["calibrate", str(tmp_path / "o.json"), "--prior", guess, "--prior-sigma", "50mm,5deg",
                 "--out", str(tmp_path / "r2.json")]) == 0
    r2 = json.loads((tmp_path / "r2.json").read_text())
    assert r2["ok"] and r2["prior"]["sigma_rot_deg"] == pytest.approx(5.0)
    e_R, _ = pose_errors(np.array(r2["T_lidar_cam"]), np.array(json.loads((tmp_path / "r.json").read_text())
                                                               ["alternatives"][1]["T_lidar_cam"]))
    assert e_R < 3


def test_a_weakly_decided_answer_names_its_runners_up_in_a_warning_and_the_json():
    import itertools

    obs = load_observations(NOWICKI)
    for s in itertools.islice(itertools.combinations(range(obs.n_boards), 3), 60):
        res = calibrate(obs.subset(list(s)))
        if res.ok and res.info.get("alternatives"):
            break
    else:
        pytest.fail("no weakly decided three-board subset among the first 60")
    alts = res.info["alternatives"]
    np.testing.assert_allclose(alts[0]["T_lidar_cam"], res.T_lidar_cam, atol=0.2)  # the answer first (before joint)
    assert all(0.1 <= a["cost"] - alts[0]["cost"] < 3.0 for a in alts[1:])
    weak = [w for w in res.warnings if w.startswith("weakly decided")]
    assert len(weak) == 1 and all(f"cost {a['cost']:.6g}" in weak[0] for a in alts)
    assert res.to_dict()["alternatives"] == alts
