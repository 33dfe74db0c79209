"""The real-data experiment's pieces: eq. 15, seeded subsets, validity against a reference, the jackknife spread."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd

from calib_core.evaluate.crossval import jackknife_covariance, leave_one_out
from calib_core.geometry.transforms import make_T, rotvec_to_matrix
from experiments.real import real_subsets as sub
from experiments.summary.intervals import wilson_interval
from simulate import SimOptions, generate


def test_theta_mu_is_eq_15():
    w = np.array([0.1, -0.2, 0.3])
    T = make_T(rotvec_to_matrix(w), [3.0, 4.0, 12.0])
    th, mu = sub.theta_mu(T)
    assert np.isclose(th, np.degrees(np.linalg.norm(w))) and np.isclose(mu, 13.0)


def test_subsets_are_seeded_distinct_boards_per_count():
    a, b = sub.subsets("x", 12, n=5), sub.subsets("x", 12, n=5)
    assert a == b and a != sub.subsets("y", 12, n=5)
    assert [len(s) for s in a] == [k for k in sub.BOARD_COUNTS for _ in range(5)]
    assert all(len(set(s)) == len(s) and max(s) < 12 for s in a)
    assert all(len(s) <= 5 for s in sub.subsets("x", 5, n=2))          # counts above the boards are left out


def test_valid_columns_against_the_reference():
    T_ref = make_T(np.eye(3), [0.1, 0.0, 0.0])
    near = make_T(rotvec_to_matrix([np.radians(1.0), 0, 0]), [0.12, 0.0, 0.0])
    far = make_T(rotvec_to_matrix([np.radians(20.0), 0, 0]), [0.1, 0.0, 0.0])
    df = pd.DataFrame({"ok": [True, True, False], "T": [json.dumps(near.tolist()), json.dumps(far.tolist()), ""],
                       "n_boards": [3, 3, 3], "method": ["m"] * 3})
    v = sub.valid_columns(df, T_ref, sigma_rot_deg=0.5, sigma_trans_m=0.01)
    assert v["valid"].tolist() == [True, False, False]
    assert v["valid_3sigma"].tolist() == [True, False, False]     # 1 deg < 1.5 deg, 20 mm < 30 mm
    v = sub.valid_columns(df, T_ref, sigma_rot_deg=0.2, sigma_trans_m=0.01)
    assert v["valid_3sigma"].tolist() == [False, False, False]
    lo, hi = wilson_interval(1, 3)
    table = " ".join(sub.valid_table(v, ["m"]))
    assert f"33% [{100 * lo:.0f}, {100 * hi:.0f}] / 0%" in table and "67%" not in table and 0 < lo < 1 / 3 < hi < 1


def test_fair_reference_never_the_method_judged():
    from experiments.real.real_data import METHODS, fair_references

    rng = np.random.default_rng(3)
    for _ in range(20):
        rms = rng.uniform(1, 20, len(METHODS))
        ok = rng.random(len(METHODS)) > 0.2
        rows = [{"method": m, "ok": bool(o), "cv": {"rms_mm": float(r)}}
                for m, r, o in zip(METHODS, rms, ok, strict=True)]
        refs = fair_references(rows)
        for m in METHODS:
            others = [(r["cv"]["rms_mm"], r["method"]) for r in rows if r["ok"] and r["method"] != m]
            assert (refs[m]["method"] if m in refs else None) == (min(others)[1] if others else None)


def test_jackknife_covariance_of_known_folds_and_against_the_reported_one():
    T = make_T(np.eye(3), [1.0, 2.0, 3.0])
    folds = np.array([make_T(np.eye(3), [1.0 + d, 2.0, 3.0]) for d in (-0.01, 0.0, 0.01)] + [np.full((4, 4), np.nan)])
    cov = jackknife_covariance(T, folds)
    assert np.isclose(cov[3, 3], 2 / 3 * 2e-4) and np.allclose(np.delete(np.delete(cov, 3, 0), 3, 1), 0)
    assert jackknife_covariance(T, folds[:2]) is None
    # on simulated data with the noise model right, the jackknife spread and the reported sigma agree
    obs = generate(SimOptions(n_boards=10, noise_mm=20.0), seed=7, trial=0)
    from calib_core import calibrate
    from calib_core.geometry.metrics import sigma_trans_m

    res = calibrate(obs, "zhang_pless+ml")
    cv = leave_one_out(obs, "zhang_pless+ml")
    jk = jackknife_covariance(res.T_lidar_cam, cv.T_lidar_cam)
    ratio = sigma_trans_m(jk) / sigma_trans_m(res.covariance)
    assert 0.4 < ratio < 2.5, ratio


def test_fig8_title_fits_inside_the_figure(tmp_path):
    """A title longer than the image is wide wraps above the image: every text of Fig. 8 lies inside the figure."""
    from experiments.real.real_subsets import fig8
    from lidarcam.rig.dataset import CameraModel

    obs = generate(SimOptions(n_boards=3), seed=0)
    K = np.array([[800.0, 0, 399.5], [0, 800.0, 299.5], [0, 0, 1]])
    title = "hokuyo-utm30lx-lifecam-nowicki pose 000: boards 0 5 7 12 (4), laser points through peng2022 (red) " \
            "and lidarcam (cyan) " * 2
    fig = fig8(np.full((480, 640), 128, np.uint8), CameraModel(800, 600, K, np.zeros(5)), obs.boards[0],
               {"peng2022": obs.T_lidar_cam_true, "lidarcam": obs.T_lidar_cam_true}, tmp_path / "f.png", title)
    renderer = fig.canvas.get_renderer()
    box = fig.bbox
    texts = fig.texts
    assert texts and "cyan" in "".join(t.get_text() for t in texts)
    for t in texts:
        e = t.get_window_extent(renderer)
        assert e.x0 >= box.x0 - 0.5 and e.x1 <= box.x1 + 0.5 and e.y0 >= box.y0 - 0.5 and e.y1 <= box.y1 + 0.5, e
    ax = fig.axes[0].get_window_extent(renderer)
    assert all(t.get_window_extent(renderer).y0 >= ax.y1 - 0.5 for t in texts)  # above the image, not over it


def test_the_covariance_line_says_what_each_model_did():
    from calib_core.refine.joint import JOINT_INTRINSICS_MODEL, JOINT_MODEL, RANGE_ONLY_MODEL
    from experiments.real.real_data import _covariance_md

    said = {m: _covariance_md([{"method": "lidarcam", "ok": True, "covariance_model": m}])[0]
            for m in (JOINT_MODEL, JOINT_INTRINSICS_MODEL, RANGE_ONLY_MODEL)}
    assert "intrinsics taken as exact" in said[JOINT_MODEL] and "under that prior" in said[JOINT_INTRINSICS_MODEL]
    assert "range-only" in said[RANGE_ONLY_MODEL] and "no image corners" in said[RANGE_ONLY_MODEL]
    assert len(set(said.values())) == 3


def test_drawn_prior_is_seeded_per_subset_and_spread_as_stated():
    T_ref = make_T(rotvec_to_matrix([0.3, -0.1, 1.2]), [0.1, -0.05, 0.2])
    a, b = sub.drawn_prior("x", (0, 1, 2), T_ref), sub.drawn_prior("x", (0, 1, 2), T_ref)
    assert np.array_equal(a.T_lidar_cam, b.T_lidar_cam)
    assert not np.array_equal(a.T_lidar_cam, sub.drawn_prior("x", (0, 1, 3), T_ref).T_lidar_cam)
    assert not np.array_equal(a.T_lidar_cam, sub.drawn_prior("y", (0, 1, 2), T_ref).T_lidar_cam)
    assert np.isclose(a.sigma_rot_rad, np.radians(sub.PRIOR_SIGMA_DEG))
    assert np.isclose(a.sigma_trans_m, sub.PRIOR_SIGMA_MM / 1000)
    # over many subsets the guesses' errors have the stated spread: the normalised squared error ~ chi-square(6)
    from calib_core.geometry.transforms import matrix_to_rotvec

    e = []
    for i in range(2000):
        T = sub.drawn_prior("x", (i, i + 1, i + 2), T_ref).T_lidar_cam
        w = matrix_to_rotvec(T[:3, :3] @ T_ref[:3, :3].T) / np.radians(sub.PRIOR_SIGMA_DEG)
        t = (T[:3, 3] - T_ref[:3, 3]) / (sub.PRIOR_SIGMA_MM / 1000)
        e.append(np.concatenate([w, t]))
    e = np.array(e)
    assert np.allclose(e.mean(axis=0), 0, atol=0.08) and np.allclose(e.std(axis=0), 1, atol=0.05)
    assert abs(np.mean(np.sum(e**2, axis=1)) - 6) < 0.2


def test_subset_run_with_a_prior_adds_its_labelled_row():
    from calib_core import calibrate

    obs = generate(SimOptions(n_boards=5), seed=11, trial=0)
    prior = sub.drawn_prior("x", (0, 1, 2), obs.T_lidar_cam_true)
    rows = sub._run(obs, (0, 1, 2), ["peng2022"], prior)
    assert [r["method"] for r in rows] == ["peng2022", sub.PRIOR_LABEL]
    res = calibrate(obs.subset([0, 1, 2]), sub.PRIOR_METHOD, prior=prior)
    assert rows[1]["ok"] == res.ok
    if res.ok:
        assert json.loads(rows[1]["T"]) == np.round(res.T_lidar_cam, 9).tolist()
    assert [r["method"] for r in sub._run(obs, (0, 1, 2), ["peng2022"])] == ["peng2022"]


def test_cov_text_round_trip():
    A = np.random.default_rng(2).normal(size=(6, 6))
    C = A @ A.T * 1e-5
    assert np.allclose(sub.cov_from_text(sub.cov_text(C)), C, rtol=1e-6)
    assert sub.cov_from_text("") is None and sub.cov_from_text(np.nan) is None


def test_uncertainty_table_from_hand_made_rows():
    s_r, s_t = np.radians(0.5), 0.01
    C = sub.cov_text(np.diag([s_r ** 2] * 3 + [s_t ** 2] * 3))
    rot = make_T(rotvec_to_matrix([2 * s_r, 0, 0]), [0, 0, 0])            # 2 sigma in roll: NEES 4
    shift = make_T(np.eye(3), [0, 3 * s_t, 0])                              # 3 sigma along y: NEES 9
    rows = [(3, True, json.dumps(rot.tolist()), C, "", True, True),
            (3, True, json.dumps(shift.tolist()), C, "", True, False),
            (3, False, "", "", "roll pitch", False, False),
            (4, True, json.dumps(rot.tolist()), "", "", False, False)]     # no covariance: no NEES
    df = pd.DataFrame(rows, columns=["n_boards", "ok", "T", "cov", "refused_axes", "valid", "valid_3sigma"])
    df["method"] = "lidarcam"
    md, r = sub.uncertainty_table(df, "lidarcam", np.eye(4))
    r = r.set_index("n_boards")
    assert np.isclose(r.loc[3, "median_nees"], 6.5) and r.loc[3, "n_nees"] == 2 and r.loc[4, "n_nees"] == 0
    assert r.loc[3, "axis_refused"] == 1 and r.loc[3, "axes"] == "roll 1, pitch 1"
    assert np.isclose(r.loc[3, "valid_rate"], 2 / 3) and np.isclose(r.loc[3, "ratio_3sigma_valid"], 0.5)
    assert np.isnan(r.loc[4, "ratio_3sigma_valid"])                       # no valid answer: no ratio
    # against the method's own all-board answer (identity here): both answers within 3 of their own 1-sigma
    # (roll 1 deg < 3 x 0.87 deg, y 30 mm < 3 x 17 mm); the 4-board answer is valid but has no covariance
    assert np.isclose(r.loc[3, "valid_own_rate"], 2 / 3) and np.isclose(r.loc[3, "own_3sigma_rate"], 2 / 3)
    assert np.isclose(r.loc[3, "ratio_own_3sigma_valid"], 1.0)
    assert r.loc[4, "valid_own_rate"] == 1.0 and r.loc[4, "own_3sigma_rate"] == 0.0
    assert md[2].endswith("| 67% | 33% | 0.50 | 67% | 67% | 1.00 |")
    assert md[3].endswith("| 0% | 0% | - | 100% | 0% | 0.00 |")
    assert np.isnan(sub.uncertainty_table(df, "lidarcam", None)[1]["median_nees"]).all()


def test_subset_rows_store_the_covariance_and_refused_axes():
    from calib_core import calibrate

    obs = generate(SimOptions(n_boards=5), seed=11, trial=0)
    row = sub._run(obs, (0, 1, 2, 3), ["lidarcam"])[0]
    assert tuple(row) == sub.ROW_COLUMNS
    res = calibrate(obs.subset([0, 1, 2, 3]), "lidarcam")
    assert row["ok"] == res.ok and row["refused_axes"] == ""
    if res.ok and res.covariance is not None:
        assert np.allclose(sub.cov_from_text(row["cov"]), res.covariance, rtol=1e-6)
