"""The experiment layer: configs compose, the runner resumes and is deterministic, aggregation gives known
numbers, the report judges claims, a real ``-m`` sweep runs, the notebook executes."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from hydra.core.global_hydra import GlobalHydra

from experiments.config.schema import SIM_GROUPS, cell_from_cfg, register_configs, sim_group_of, sim_options
from experiments.config.sweeps import CONF_DIR, expand_sweep_params
from experiments.engine.cell import RESULT_COLUMNS, TIMING_COLUMNS, Cell
from experiments.engine.runner import run_cells
from experiments.engine.store import load_cell
from experiments.engine.trial import simulate_trial
from experiments.paper import claims, report
from experiments.paper.reproduce import reproduce
from experiments.summary import aggregate, figures
from simulate import SimOptions

ROOT = Path(__file__).resolve().parents[2]
CHEAP = ("zhang_pless_linear", "vasconcelos")


def _compose(overrides=(), hydra_cfg=False):
    register_configs()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides), return_hydra_config=hydra_cfg)


# ---------------------------------------------------------------------------------------------- configs

@pytest.mark.parametrize("experiment,sweep,param,values", [
    ("boards", "boards", "scene.n_boards", [3, 4, 5, 6, 7, 8]),
    ("noise", "noise", "noise.noise_mm", [5, 10, 15, 20, 25, 30]),
])
def test_experiment_configs_compose(experiment, sweep, param, values):
    cfg = _compose([f"experiment={experiment}"], hydra_cfg=True)
    assert cfg.sweep == sweep and cfg.n_trials == 100
    assert cfg.noise.noise_mm == 20.0 or experiment == "noise"
    assert cfg.scene.n_boards == 6 or experiment == "boards"
    combos = expand_sweep_params(cfg.hydra.sweeper.params)
    assert [float(c[0].split("=")[1]) for c in combos] == values and all(c[0].startswith(param) for c in combos)
    opts = sim_options(_compose([f"experiment={experiment}", combos[0][0]]))
    assert isinstance(opts, SimOptions) and opts.lidar_res_deg == 0.25 and (opts.dist_min_m, opts.dist_max_m) == (3, 6)


def test_primary_config_and_groups_compose():
    cfg = _compose(["camera=pixel", "lidar=lms291", "methods=seed", "scene.max_tilt_deg=30", "noise.noise_mm=7"])
    opts = sim_options(cfg)
    assert (opts.pose_mode, opts.lidar_res_deg, opts.max_tilt_deg, opts.noise_mm) == ("pixel", 0.5, 30.0, 7.0)
    cell = cell_from_cfg(cfg)
    assert cell.methods == ("zhang_pless_linear", "zhang_pless", "vasconcelos", "peng2022")
    launcher = _compose(["hydra/launcher=local_joblib"], hydra_cfg=True).hydra.launcher
    assert launcher._target_.endswith("JoblibLauncher")
    with pytest.raises(Exception, match="n_boards"):
        _compose(["scene.n_boards=many"])


def test_groups_cover_simoptions_once():
    cfg = _compose()
    names = [k for g in SIM_GROUPS for k in cfg[g]]
    assert sorted(names) == sorted(f.name for f in dataclasses.fields(SimOptions))
    assert sim_group_of("noise_mm") == "noise" and sim_group_of("lidar_res_deg") == "lidar"


def test_unknown_method_is_a_config_error():
    from calib_core import CalibrationError

    with pytest.raises(CalibrationError, match="unknown method"):
        cell_from_cfg(_compose(["methods.names=[no_such_method]"]))


# ----------------------------------------------------------------------------------------------- runner

def fake_trial(cell: Cell, trial: int, methods) -> list[dict]:
    """Stand-in trial: deterministic rows from (seed, trial, method), no simulation."""
    rows = []
    for k, m in enumerate(methods):
        rng = np.random.default_rng([cell.seed, trial, sum(map(ord, m))])
        ok = bool(rng.random() > 0.1)
        e_R, e_t = (float(rng.exponential(4.0)), float(rng.exponential(0.3))) if ok else (np.nan, np.nan)
        rows.append({**cell.columns(), "trial": trial, "method": m, "ok": ok, "reason": "" if ok else "fake failure",
                     "e_R_deg": e_R, "e_t_m": e_t, "valid": ok and e_R < 8 and e_t < 0.8, "n_candidates": k + 1,
                     "true_among_candidates": ok and e_R < 1, "some_candidate_valid": ok,
                     "best_candidate_e_R_deg": e_R, "best_candidate_e_t_m": e_t, "seconds": 0.001 * k,
                     "crlb_rot_deg": np.nan, "crlb_trans_mm": np.nan, "conditioning": np.nan})
    return rows


def _cell(tmp_path, name="a", n_trials=10, methods=("m1", "m2"), **sim) -> Cell:
    return Cell("fake", {"n_boards": 6, "noise_mm": 20.0, **sim}, seed=1, n_trials=n_trials, methods=methods,
                results_dir=str(tmp_path / name))


def test_interrupted_sweep_resumes_to_the_same_table(tmp_path):
    full = run_cells([_cell(tmp_path, "full")], n_jobs=1, chunk_size=3, trial_fn=fake_trial, progress=False)
    calls: list[int] = []

    def dies_at_7(cell, trial, methods):
        if trial == 7:
            raise KeyboardInterrupt
        calls.append(trial)
        return fake_trial(cell, trial, methods)

    cell = _cell(tmp_path, "resumed")
    with pytest.raises(KeyboardInterrupt):
        run_cells([cell], n_jobs=1, chunk_size=3, trial_fn=dies_at_7, progress=False)
    assert len(load_cell(cell)) == 2 * 6  # chunks 0-2 and 3-5 were written, 6-8 was lost whole
    calls.clear()
    resumed = run_cells([cell], n_jobs=1, chunk_size=3, trial_fn=lambda *a: (calls.append(a[1]), fake_trial(*a))[1],
                        progress=False)
    assert calls == [6, 7, 8, 9]
    pd.testing.assert_frame_equal(full, resumed)
    # an added method runs on the old trials only for itself
    calls.clear()
    more = dataclasses.replace(cell, methods=("m1", "m2", "m3"))
    out = run_cells([more], n_jobs=1, chunk_size=5, trial_fn=lambda *a: (calls.append(tuple(a[2])), fake_trial(*a))[1],
                    progress=False)
    assert set(calls) == {("m3",)} and len(out) == 30


def test_parallel_run_equals_serial_run(tmp_path):
    serial = run_cells([_cell(tmp_path, "s")], n_jobs=1, chunk_size=4, trial_fn=fake_trial, progress=False)
    par = run_cells([_cell(tmp_path, "p")], n_jobs=2, chunk_size=2, trial_fn=fake_trial, progress=False)
    pd.testing.assert_frame_equal(serial, par)


def test_real_trials_are_seeded_and_failures_are_rows(tmp_path):
    sim = dataclasses.asdict(SimOptions(n_boards=5))
    tables = []
    for name, seed in (("a", 0), ("b", 0), ("c", 1)):
        cell = Cell("real", sim, seed=seed, n_trials=3, methods=CHEAP, results_dir=str(tmp_path / name))
        tables.append(run_cells([cell], n_jobs=1, progress=False))
    assert list(tables[0].columns[-len(RESULT_COLUMNS):]) == list(RESULT_COLUMNS)
    tables = [t.drop(columns=list(TIMING_COLUMNS)) for t in tables]
    pd.testing.assert_frame_equal(tables[0], tables[1])
    assert not np.allclose(tables[0]["e_R_deg"].fillna(-1), tables[2]["e_R_deg"].fillna(-1))
    assert tables[0]["n_candidates"].gt(0).all() and set(tables[0]["method"]) == set(CHEAP)
    # a bad draw (here: options the simulator rejects) becomes rows with the reason, never an exception
    bad = Cell("real", {**sim, "n_boards": 0}, n_trials=1, methods=CHEAP, results_dir=str(tmp_path / "bad"))
    rows = simulate_trial(bad, 0, CHEAP)
    assert [r["ok"] for r in rows] == [False, False] and rows[0]["reason"].startswith("simulate: ValueError")


# ------------------------------------------------------------------------------------------- aggregation

def _hand_table() -> pd.DataFrame:
    """10 trials x 2 methods at one setting, known outcomes."""
    rows = []
    for t in range(10):
        # method A: always returns; valid in trials 0-6; e_R = t deg, e_t = 0.1 t m
        rows.append({"sweep": "h", "setting_key": "k", "n_boards": 6, "noise_mm": 20.0, "trial": t, "method": "A",
                     "ok": True, "reason": "", "e_R_deg": float(t), "e_t_m": 0.1 * t, "valid": t < 7,
                     "n_candidates": 4, "true_among_candidates": t < 5, "some_candidate_valid": t < 8,
                     "best_candidate_e_R_deg": 0.5, "best_candidate_e_t_m": 0.01, "seconds": 0.01,
                     "crlb_rot_deg": np.nan, "crlb_trans_mm": np.nan, "conditioning": np.nan})
        # method B: fails (returns nothing) in trials 0-2; otherwise e_R = 2 deg, valid
        ok = t >= 3
        rows.append({**rows[-1], "method": "B", "ok": ok, "reason": "" if ok else f"board {t}: too few points",
                     "e_R_deg": 2.0 if ok else np.nan, "e_t_m": 0.2 if ok else np.nan, "valid": ok,
                     "true_among_candidates": False, "some_candidate_valid": ok})
    return pd.DataFrame(rows)


def test_aggregation_of_a_known_table():
    s = aggregate.summarise(_hand_table()).set_index("method")
    a, b = s.loc["A"], s.loc["B"]
    assert (a.n_trials, a.n_valid, a.n_failed, b.n_trials, b.n_valid, b.n_failed) == (10, 7, 0, 10, 7, 3)
    assert a.valid_rate == pytest.approx(0.7) and b.valid_rate == pytest.approx(0.7)  # failures count invalid
    # Wilson in its other closed form: (2np + z^2 -+ z sqrt(z^2 + 4np(1-p))) / (2(n + z^2)) = 0.39678, 0.89221
    z = 1.959963984540054
    root = z * np.sqrt(z * z + 4 * 10 * 0.7 * 0.3)
    assert (a.valid_lo95, a.valid_hi95) == pytest.approx(((14 + z * z - root) / (2 * (10 + z * z)),
                                                          (14 + z * z + root) / (2 * (10 + z * z))), abs=1e-9)
    assert (a.valid_lo95, a.valid_hi95) == pytest.approx((0.396778, 0.892209), abs=1e-6)
    assert a.mean_e_R_deg == pytest.approx(4.5) and a.median_e_R_deg == pytest.approx(4.5)
    assert a.mean_e_t_m == pytest.approx(0.45) and a.mean_e_R_valid_deg == pytest.approx(3.0)
    assert b.mean_e_R_deg == pytest.approx(2.0)  # over the 7 returned results
    assert a.truth_among_rate == pytest.approx(0.5) and a.some_candidate_valid_rate == pytest.approx(0.8)
    assert b.top_failure == "board k: too few points"
    assert a.top_failure == ""
    lo, hi = aggregate.wilson_interval([0, 20], [20, 20])
    assert lo[0] == 0 and hi[0] == pytest.approx(0.161125, abs=1e-6) and hi[1] == 1 and lo[1] == pytest.approx(
        0.838875, abs=1e-6)


def test_claim_verdicts_on_point_values():
    """The summary report's reading: point values, no intervals (the same rule as the matched report's)."""
    c = claims.Claim("boards", "t", "s", "points", "x", 2, 20)
    assert claims.claim_holds(c, np.array([5.0, 0.0, 12.0])) == "holds"
    assert claims.claim_holds(c, np.array([30.0, 40.0])) == "direction only"
    assert claims.claim_holds(c, np.array([5.0, -3.0])) == "mixed"
    assert claims.claim_holds(c, np.array([0.0, -3.0])) == "does not hold"
    one = claims.Claim("noise", "t", "s", "relative", "x", 150, 150, at=30)
    assert claims.claim_holds(one, np.array([100.0])) == "holds"
    assert claims.claim_holds(one, np.array([20.0])) == "direction only"
    assert claims.claim_holds(claims.Claim("noise", "t", "s", "at_least", None, 90, 100), np.array([95, 89])) == \
        "does not hold"


def _fake_paper_tables(tmp_path) -> Path:
    """Tables, figures and report of both paper sweeps from the stand-in trial function."""
    methods = ("zhang_pless_linear", "zhang_pless", "vasconcelos", "peng2022")
    cells = {"boards": [Cell("boards", {"n_boards": n, "noise_mm": 20.0}, n_trials=12, methods=methods,
                             results_dir=str(tmp_path)) for n in range(3, 9)],
             "noise": [Cell("noise", {"n_boards": 6, "noise_mm": float(s)}, n_trials=12, methods=methods,
                            results_dir=str(tmp_path)) for s in range(5, 35, 5)]}
    out = tmp_path / "paper"
    for sweep, cs in cells.items():
        aggregate.write_tables(run_cells(cs, n_jobs=1, trial_fn=fake_trial, progress=False), sweep, out)
    return out


def test_tables_round_trip_with_no_failures(tmp_path):
    df = _hand_table()
    df = df[df["ok"]]
    aggregate.write_tables(df, "h", tmp_path)
    s = aggregate.load_summary(tmp_path, "h")
    assert s["top_failure"].tolist() == ["", ""] and (aggregate.load_trials(tmp_path, "h")["reason"] == "").all()


def test_tables_figures_report_from_a_small_sweep(tmp_path):
    out = _fake_paper_tables(tmp_path)
    paths = [p for s in ("boards", "noise") for p in figures.draw_sweep(out, s)]
    names = {p.name for p in paths}
    for fig in ("fig3a_valid_vs_boards", "fig4_mean_error_vs_boards", "fig5_error_distribution_vs_boards",
                "fig3b_valid_vs_noise", "fig6_mean_error_vs_noise", "fig7_error_distribution_vs_noise"):
        assert {f"{fig}.png", f"{fig}.pdf"} <= names
    text = report.write_paper_report(out).read_text()
    assert "valid-solution probability +2 to +20 points vs Francisco" in text
    assert text.count("| **") == len(claims.paper_claims())
    assert "## Where and why we differ" in text and "{" not in text.split("## Where and why we differ")[1]


def test_notebook_executes(tmp_path):
    import nbclient
    import nbformat
    _fake_paper_tables(tmp_path)
    nb = nbformat.read(ROOT / "notebooks" / "results.ipynb", as_version=4)
    os.environ["LIDARCAM_RESULTS"] = str(tmp_path)
    try:
        nbclient.NotebookClient(nb, timeout=120, kernel_name="python3",
                                resources={"metadata": {"path": str(ROOT / "notebooks")}}).execute()
    finally:
        del os.environ["LIDARCAM_RESULTS"]
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert any(o.get("output_type") == "display_data" for o in outputs)
    assert not any(o.get("output_type") == "error" for o in outputs)


# ------------------------------------------------------------------------------------------ end to end

def test_hydra_multirun_sweep(tmp_path):
    cmd = [sys.executable, "-m", "experiments.run", "-m", "experiment=boards", "scene.n_boards=3,5", "n_trials=3",
           f"results_dir={tmp_path}", "methods.names=[zhang_pless_linear,vasconcelos]",
           "n_jobs=1", "progress=false"]
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    from experiments.engine.store import load_sweep

    rows = load_sweep(tmp_path, "boards")
    assert sorted(rows["n_boards"].unique()) == [3, 5] and len(rows) == 2 * 3 * 2
    z3 = rows[(rows["n_boards"] == 3) & (rows["method"] == "zhang_pless_linear")]
    assert not z3["ok"].any() and z3["reason"].str.contains("at least 5 boards").all()


def test_reproduce_small(tmp_path):
    r = reproduce(trials=2, results_dir=str(tmp_path), n_jobs=1, progress=False,
                  overrides=["methods.names=[zhang_pless_linear,vasconcelos]"])
    assert r["cells"] == 12 and r["trials"] == 24
    assert (tmp_path / "paper" / "REPORT.md").exists()
    assert (tmp_path / "paper" / "figures" / "fig7_error_distribution_vs_noise.pdf").exists()
    s = aggregate.load_summary(tmp_path / "paper", "noise")
    assert len(s) == 12 and s["n_trials"].eq(2).all()


EXPERIMENTS = sorted(p.stem for p in (CONF_DIR / "experiment").glob("*.yaml"))


@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_every_experiment_config_runs_small(experiment, tmp_path):
    """Every experiment config composes into cells and one trial of its first cell runs, every method of it giving
    a row (lightning-hydra-template's sweep test)."""
    from experiments.config.sweeps import experiment_cells
    from experiments.engine.runner import run_cells

    cells = experiment_cells(experiment, ["n_trials=1", f"results_dir={tmp_path}"])
    assert cells and all(c.n_trials == 1 for c in cells)
    df = run_cells(cells[:1], n_jobs=1, progress=False)
    assert sorted(df["method"]) == sorted(cells[0].methods) and df["trial"].eq(0).all()
    assert (df["ok"] | df["reason"].astype(str).str.len().gt(0)).all(), "a failed row must say why"


def test_rig_like_rates_and_leaders_from_rows():
    from experiments.paper.rig_like import ACCURATE_ROT_DEG, leaders, rates

    rng = np.random.default_rng(5)
    rows = []
    for nb in (3, 4):
        for trial in range(40):
            for m in ("peng2022", "lidarcam"):
                ok = bool(rng.random() > 0.1)
                e_R = float(rng.uniform(0, 3)) if ok else np.nan
                rows.append({"n_boards": nb, "trial": trial, "method": m, "ok": ok, "valid": ok and e_R < 2,
                             "e_R_deg": e_R, "e_t_m": 0.01 if ok else np.nan,
                             "nees": 5.0 if m == "lidarcam" else np.nan})
    df = pd.DataFrame(rows)
    r = rates(df)
    for x in r.itertuples():
        g = df[(df["n_boards"] == x.n_boards) & (df["method"] == x.method)]
        acc = (g["ok"] & (g["e_R_deg"] < ACCURATE_ROT_DEG) & (g["e_t_m"] < 0.030)).mean()
        assert np.isclose(x.valid_rate, g["valid"].mean()) and np.isclose(x.accurate_rate, acc)
        assert x.valid_lo95 <= x.valid_rate <= x.valid_hi95 and np.isclose(x.refused_rate, (~g["ok"]).mean())
        assert (x.median_nees == 5.0) if x.method == "lidarcam" else np.isnan(x.median_nees)
    best = {nb: g.set_index("method")["valid_rate"] for nb, g in r.groupby("n_boards")}
    assert leaders(r, "valid") == [nb for nb, s in best.items() if s["lidarcam"] >= s["peng2022"]]


def _refusal_reason(axes: tuple[str, ...], geometric: bool) -> str:
    """A reason in the library's own wording (``Degeneracy.message``) for directions along ``axes``."""
    from calib_core.checks.degeneracy import AXES, Degeneracy

    dirs = np.eye(6)[[AXES.index(a) for a in axes]]
    deg = Degeneracy(dirs, np.full(len(axes), 0.5), axes, True, geometric, "every board stands vertical", 2.0,
                     0.01)
    return f"refinement: {deg.message()}"


def test_refused_axes_read_from_the_library_wording():
    from experiments.summary.tables import refused_axes

    assert refused_axes(_refusal_reason(("roll", "pitch", "z"), True)) == ("roll", "pitch", "z")
    assert refused_axes(_refusal_reason(("yaw",), True)) == ("yaw",)
    assert refused_axes(_refusal_reason(("x",), False)) == ()              # "poorly determined": answered
    assert refused_axes("no candidate: minimal solver: 1 triples, no real solution") == ()
    assert refused_axes("") == () and refused_axes(np.nan) == ()


def test_refused_axes_are_the_free_ones_not_the_hint():
    """A refusal whose analysis finds only z flat (roll and pitch rise within the span): the reason names z
    alone before "not determined"; roll and pitch stay in its fixed= hint and are said with their sigma."""
    from calib_core.checks.axis_words import flat_words
    from calib_core.checks.degeneracy import AXES, Degeneracy
    from experiments.summary.tables import refused_axes

    axes, prof = ("roll", "pitch", "z"), np.array([0.09, 0.1, np.inf])
    deg = Degeneracy(np.eye(6)[[AXES.index(a) for a in axes]], np.full(3, np.inf), axes, True, True,
                     "every board stands vertical" + flat_words(axes, prof, 2.0, True), 2.0, 0.01,
                     free_axes=("z",), free_directions=np.eye(6)[[5]], axis_sigmas=prof)
    reason = f"lidarcam: {deg.message()}"
    assert refused_axes(reason) == ("z",)
    assert "'roll_deg'" in reason and "roll 5.2 deg" in reason and "pitch 5.7 deg" in reason


def test_refusals_per_board_count_from_hand_made_rows():
    from experiments.summary.tables import refusal_table, refusals

    roll_pitch = _refusal_reason(("roll", "pitch"), True)
    rows = [  # 3 boards: 2 answers (NEES 2 and 10), one refusal naming roll and pitch, one other failure
        ("lidarcam", 3, True, "", 2.0), ("lidarcam", 3, True, "", 10.0), ("lidarcam", 3, False, roll_pitch, np.nan),
        ("lidarcam", 3, False, "no candidate: no real solution", np.nan),
        # 4 boards: 3 answers (NEES 3, 5, 100; one without a covariance), one refusal naming z
        ("lidarcam", 4, True, "", 3.0), ("lidarcam", 4, True, "", 5.0), ("lidarcam", 4, True, "", 100.0),
        ("lidarcam", 4, True, "", np.nan), ("lidarcam", 4, False, _refusal_reason(("z",), True), np.nan),
        ("peng2022", 3, False, roll_pitch, np.nan)]                          # another method: not counted
    df = pd.DataFrame(rows, columns=["method", "n_boards", "ok", "reason", "nees"])
    r = refusals(df, "lidarcam").set_index("n_boards")
    assert r.loc[3, ["n", "answered", "axis_refused", "n_nees"]].tolist() == [4, 2, 1, 2]
    assert r.loc[4, ["n", "answered", "axis_refused", "n_nees"]].tolist() == [5, 4, 1, 3]
    assert r.loc[3, "axes"] == "roll 1, pitch 1" and r.loc[4, "axes"] == "z 1"
    assert r.loc[3, "median_nees"] == 6.0 and r.loc[4, "median_nees"] == 5.0
    # the stored-axes column of the real experiment's rows gives the same counts
    stored = df.assign(refused_axes=["", "", "roll pitch", "", "", "", "", "", "z", "roll pitch"]).drop(
        columns="reason")
    assert refusals(stored, "lidarcam").equals(refusals(df, "lidarcam"))
    md = refusal_table(refusals(df, "lidarcam"), {"extra": ["a", "b"]})
    assert len(md) == 4 and md[2].startswith("| 3 | 4 | 2 (50%) | 1 (25%) | roll 1, pitch 1 | 6.0 (2) | a |")
