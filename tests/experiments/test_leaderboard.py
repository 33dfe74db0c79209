"""The leaderboard: its statistics on known rows, suites skipped when absent, real files found and run."""

import dataclasses
import json

import numpy as np
import pandas as pd
import pytest

from calib_core import save_observations
from experiments.suites.leaderboard import Suite, load_suites, plan, real_files, run_leaderboard
from experiments.suites.leaderboard_table import leaderboard_table, markdown_table
from experiments.summary.intervals import wilson_interval
from simulate import SimOptions, generate


def _rows(method, valid, e_R, e_t, crlb_rot=np.nan, crlb_trans=np.nan, nees=np.nan, seconds=0.01, boards=6):
    """Trial rows as the runner writes them (one setting per board count)."""
    n = len(valid)
    return pd.DataFrame({"sweep": "s", "setting_key": f"nb{boards}", "n_boards": boards, "noise_mm": 20.0,
                         "trial": np.arange(n), "method": method, "ok": True, "reason": "", "valid": valid,
                         "e_R_deg": e_R, "e_t_m": e_t, "n_candidates": 1, "true_among_candidates": valid,
                         "some_candidate_valid": valid, "best_candidate_e_R_deg": e_R, "best_candidate_e_t_m": e_t,
                         "seconds": np.full(n, seconds), "crlb_rot_deg": crlb_rot, "crlb_trans_mm": crlb_trans,
                         "conditioning": 0.1, "nees": nees})


def test_table_statistics_on_known_rows():
    # suite "clean": two settings, 3 boards (trials 0-2) and 6 boards (trial 3)
    a1 = pd.concat([_rows("a", [True, True, False], [1.0, 2.0, 30.0], [0.01, 0.02, 2.0], crlb_rot=1.0,
                          crlb_trans=10.0, nees=[4.0, 8.0, 99.0], boards=3),
                    _rows("a", [True], [2.0], [0.02], crlb_rot=2.0, crlb_trans=10.0, nees=np.nan)])
    a2 = _rows("a", [True, False], [3.0, 50.0], [0.03, 3.0], crlb_rot=0.001, crlb_trans=0.001, nees=[6.0, np.nan],
               boards=8)
    b1 = _rows("b", [True, True, True, True], [0.5] * 4, [0.005] * 4, crlb_rot=1.0, crlb_trans=10.0, seconds=0.002)
    b2 = _rows("b", [True, True], [0.5, 0.5], [0.005] * 2, crlb_rot=0.001, crlb_trans=0.001, seconds=0.002,
               boards=8)
    t = leaderboard_table({"clean": pd.concat([a1, b1]), "hard": pd.concat([a2, b2])}, {"clean"},
                          {"a": "lidarcam", "b": "my_lab.b"}).set_index("method")
    assert list(t.index) == ["b", "a"] and list(t["rank"]) == [1, 2]      # ranked by valid rate
    a = t.loc["a"]
    lo, hi = wilson_interval(4, 6)
    assert a.n_trials == 6 and a.valid_rate == pytest.approx(4 / 6)
    assert (a.valid_lo95, a.valid_hi95) == pytest.approx((float(lo), float(hi)))
    assert t.loc["b", "n_trials"] == 6
    assert a.valid_clean == pytest.approx(0.75) and a.valid_hard == pytest.approx(0.5)
    assert a.median_e_R_deg == pytest.approx(2.5)                            # over every returned solution
    assert a.rms_e_R_deg == pytest.approx(np.sqrt((1 + 4 + 4 + 9) / 4))      # over the valid ones
    # RMS / CRLB: per setting of the crlb suite (valid trials), then the RMS of those ratios weighted by valid trials
    rot_3, rot_6 = np.sqrt((1 + 4) / 2) / 1.0, 2.0 / 2.0
    assert a.rms_over_crlb_rot == pytest.approx(np.sqrt((2 * rot_3**2 + 1 * rot_6**2) / 3))
    trans_3, trans_6 = np.sqrt((100 + 400) / 2) / 10.0, 20.0 / 10.0
    assert a.rms_over_crlb_trans == pytest.approx(np.sqrt((2 * trans_3**2 + 1 * trans_6**2) / 3))
    assert a.mean_nees == pytest.approx(6.0) and a.n_nees == 3              # valid trials with a covariance
    assert np.isnan(t.loc["b", "mean_nees"]) and t.loc["b", "median_ms"] == pytest.approx(2.0)
    text = "\n".join(markdown_table(t.reset_index()))
    assert "| 1 | `b` | my_lab.b | 100 [" in text and "| - |" in text     # no covariance: NEES "-"


def test_a_setting_shared_by_two_suites_counts_once_in_the_pooled_figures():
    shared = _rows("a", [True, False], [1.0, 30.0], [0.01, 2.0], crlb_rot=1.0, crlb_trans=10.0)
    other = _rows("a", [True, True], [1.0, 1.0], [0.01, 0.01], crlb_rot=1.0, crlb_trans=10.0, boards=3)
    t = leaderboard_table({"boards": pd.concat([shared, other]), "noise": shared}, {"boards", "noise"}, {})
    r = t.iloc[0]
    assert r.n_trials == 4 and r.valid_rate == pytest.approx(3 / 4)
    assert r.valid_boards == pytest.approx(3 / 4) and r.valid_noise == pytest.approx(1 / 2)


def test_suite_file_is_versioned_and_names_the_paper_sweeps():
    from experiments.suites.leaderboard import DEFAULT_SUITE

    version, suites = load_suites(DEFAULT_SUITE)
    names = {s.name: s for s in suites}
    assert f"v{version}" == DEFAULT_SUITE.stem and {"boards", "noise", "corner_noise", "outliers", "rig_like",
                                                   "real"} <= set(names)
    assert not names["rig_like"].crlb          # the bound takes the intrinsics as exact
    assert names["boards"].crlb and names["boards"].trials < names["boards"].full_trials
    assert {"rig_like_fisheye", "rig_like_ds"} <= set(names)


def test_the_lens_rig_like_suites_run_through_their_lens(tmp_path):
    """The fisheye and double-sphere rig-like rows: one trial each of ``lidarcam`` through the lens of the suite
    (the trial's camera model recorded in its row), valid under rig conditions."""
    import yaml

    from experiments.suites.leaderboard import DEFAULT_SUITE

    suites = yaml.safe_load(DEFAULT_SUITE.read_text())["suites"]
    lens = {k: dict(suites[k], trials=1) for k in ("rig_like_fisheye", "rig_like_ds")}
    suite = tmp_path / "suite.yaml"
    suite.write_text(yaml.safe_dump({"version": "test", "suites": lens}))
    r = run_leaderboard(suite, overrides=["methods.names=[lidarcam]"], results_dir=str(tmp_path / "res"), n_jobs=1,
                        progress=False)
    assert r["rows_computed"] == 2
    table = pd.read_csv(r["report"].parent / "leaderboard.csv")
    assert table["valid_rig_like_fisheye"].iloc[0] == 1 and table["valid_rig_like_ds"].iloc[0] == 1
    for name, model in (("rig_like_fisheye", "pinhole-equidistant"), ("rig_like_ds", "ds")):
        cells = [p for p in (tmp_path / "res").rglob("*.json") if model in p.read_text()]
        assert cells, f"no stored cell of {name} names the {model} lens"


def _obs_files(folder, n, reference=True):
    folder.mkdir(parents=True)
    for k in range(n):
        obs = generate(SimOptions(n_boards=6, noise_mm=10), seed=3, trial=k)
        obs = obs if reference else dataclasses.replace(obs, T_lidar_cam_true=None)  # a real rig: no ground truth
        save_observations(obs, folder / f"pose{k}.json")
    (folder / "result.json").write_text(json.dumps({"schema": "lidarcam.result/1"}))  # not observations: ignored


def test_absent_suites_are_skipped_with_a_line_and_real_files_are_found(tmp_path):
    _obs_files(tmp_path / "real" / "rig", 2)
    suites = [Suite("ghost", experiment="no_such_experiment"), Suite("real", path=str(tmp_path / "real")),
              Suite("empty", path=str(tmp_path / "nothing")),
              Suite("noise30", experiment="noise", overrides=("noise.noise_mm=30",), trials=3, full_trials=7)]
    assert [f.name for f in real_files(suites[1])] == ["pose0.json", "pose1.json"]
    cells, skipped = plan(suites, ("peng2022",), (), (), str(tmp_path / "res"), False, None)
    assert list(cells) == ["real", "noise30"] and len(cells["real"]) == 2
    (c,) = cells["noise30"]  # the suite's override fixed the swept noise: one setting
    assert c.sim["noise_mm"] == 30 and c.n_trials == 3 and c.methods == ("peng2022",)
    assert plan(suites[3:], ("peng2022",), (), (), str(tmp_path / "res"), True, None)[0]["noise30"][0].n_trials == 7
    assert skipped[0] == "ghost: skipped, conf/experiment/no_such_experiment.yaml is absent"
    assert skipped[1].startswith("empty: skipped, no lidarcam.observations/1 file under")


def test_real_suite_runs_end_to_end_and_resumes(tmp_path):
    _obs_files(tmp_path / "real", 2)
    suite = tmp_path / "suite.yaml"
    suite.write_text(f"version: test\nsuites:\n  ghost:\n    experiment: no_such\n"
                     f"  real:\n    path: {tmp_path / 'real'}\n")
    kw = {"overrides": ["methods.names=[peng2022,zhang_pless]"], "results_dir": str(tmp_path / "res"),
          "n_jobs": 1, "progress": False}
    r = run_leaderboard(suite, **kw)
    assert r["rows_computed"] == 4 and r["skipped"] == ["ghost: skipped, conf/experiment/no_such.yaml is absent"]
    text = r["report"].read_text()
    assert "Suite ghost: skipped" in text and "## Real data" in text
    assert "| `peng2022` | 2/2 |" in text and "| `zhang_pless` | 2/2 |" in text
    assert run_leaderboard(suite, **kw)["rows_computed"] == 0          # read back from the store


def test_real_files_without_a_reference_are_stored_and_read_back(tmp_path):
    _obs_files(tmp_path / "real", 2, reference=False)
    suite = tmp_path / "suite.yaml"
    suite.write_text(f"version: test\nsuites:\n  real:\n    path: {tmp_path / 'real'}\n")
    kw = {"overrides": ["methods.names=[peng2022]"], "results_dir": str(tmp_path / "res"), "n_jobs": 1,
          "progress": False}
    assert run_leaderboard(suite, **kw)["rows_computed"] == 2       # no valid rate: the rows are not "damaged"
    assert run_leaderboard(suite, **kw)["rows_computed"] == 0


def test_a_mistyped_override_is_one_line_with_the_closest_key():
    """``make leaderboard ARGS=scene.n_board=3``: one line naming ``scene.n_boards``, exit 2, no Hydra traceback."""
    import subprocess
    import sys
    from pathlib import Path

    r = subprocess.run([sys.executable, "-m", "experiments", "leaderboard", "scene.n_board=3"],
                       cwd=Path(__file__).resolve().parents[2], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr[-500:]
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr[-500:]
    assert "did you mean 'scene.n_boards'" in r.stderr
