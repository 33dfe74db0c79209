"""``make search-paper``: search the settings the paper left unstated for those closest to its numbers.

    python -m experiments search [--stage coarse|fine|sensitivity|all] [--coarse-trials 16] [--fine-trials 1000]
                                 [--best 3] [--sensitivity-trials 100] [--results results] [--n-jobs -1]
                                 [--write-preset]

Everything is fixed in ``conf/search/paper.yaml`` before the run: the objective (``experiments.paper.objective``),
the space, the stages. Coarse: a scrambled Sobol design over the space plus the default preset, few trials
per point; fine: the best coarse points and the default with many trials; sensitivity: one setting at a time
through the winner, each over its whole range, judged with paired intervals. Each point is the paper's two
sweeps (``conf/experiment/boards.yaml`` and ``noise.yaml`` composed by Hydra, the point's settings on top), run
by the ordinary runner in one process pool with common random numbers (``crn_stream``: trial t draws the
same numbers at every point), so a fine stage extends the coarse cells and an interrupted run resumes.

Writes ``<results>/search/``: ``points_<stage>.csv`` (settings, objective per Zhang variant, the terms),
``verdicts_<stage>.csv`` (each claim's point verdict per point: the sensitivity of the verdicts) and
``best.json``; ``--write-preset`` writes the winner to ``conf/preset/paper-matched.yaml``.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import qmc

from simulate import SimOptions

from ..config.sweeps import CONF_DIR, experiment_cells
from ..engine.cell import Cell
from ..engine.cli import n_jobs, positive_int, study_parser
from ..engine.runner import run_cells
from ..engine.store import load_cell
from ..summary.figures import PAPER_SWEEPS
from .claim_stats import claim_values, sweep_arrays
from .claims import claim_holds, paper_claims
from .objective import load_search_conf, score
from .reproduce import PAPER_EXPERIMENTS

SPACE_KEYS = ("max_tilt_deg", "board_size_m", "bearing_spread_deg", "corner_noise_px")
DEFAULT_POINT = {"max_tilt_deg": 45.0, "board_size_m": 1.0, "bearing_spread_deg": 60.0, "corner_noise_px": 0.0}
PRESET = CONF_DIR / "preset" / "paper-matched.yaml"


def design(conf) -> list[dict]:
    """The coarse points: ``default`` (our preset) then ``s00``.. (scrambled Sobol over the space, rounded)."""
    space = conf.space
    lo = np.array([space[k][0] for k in SPACE_KEYS])
    hi = np.array([space[k][1] for k in SPACE_KEYS])
    u = qmc.Sobol(len(SPACE_KEYS), scramble=True, seed=int(conf.coarse.sobol_seed)).random(int(conf.coarse.points))
    x = qmc.scale(u, lo, hi)
    points = [{"point": "default", **DEFAULT_POINT}]
    for i, row in enumerate(x):
        pt = {k: float(np.round(v / conf.rounding[k]) * conf.rounding[k]) for k, v in zip(SPACE_KEYS, row, strict=True)}
        points.append({"point": f"s{i:02d}", **{k: round(v, 4) for k, v in pt.items()}})
    return points


def sensitivity_points(conf, centre: dict) -> list[dict]:
    """One setting at a time through ``centre`` (the winner): ``conf.sensitivity.levels`` evenly spaced values
    over each setting's range (rounded as the design), the others at the centre's values; the centre first, as
    ``centre``, and each other point named ``<setting>=<value>``."""
    points = [{"point": "centre", **{k: float(centre[k]) for k in SPACE_KEYS}}]
    for k in SPACE_KEYS:
        lo, hi = conf.space[k]
        for v in np.linspace(lo, hi, int(conf.sensitivity.levels)):
            v = round(float(np.round(v / conf.rounding[k]) * conf.rounding[k]), 4)
            if not np.isclose(v, float(centre[k])):
                points.append({"point": f"{k}={v:g}", **{q: float(centre[q]) for q in SPACE_KEYS}, k: v})
    return points


def sensitivity_ranges(verdicts: pd.DataFrame) -> pd.DataFrame:
    """Per claim and setting, the values of that setting (others at the centre) at which the claim holds, from
    the sensitivity stage's verdicts: columns ``claim``, ``setting``, ``holds_at`` (list), ``tried`` (list)."""
    rows = []
    for claim, v in verdicts.groupby("claim", sort=True):
        centre = v[v["point"] == "centre"]
        for k in SPACE_KEYS:
            g = pd.concat([centre, v[v["point"].str.startswith(f"{k}=")]]).sort_values(k)
            rows.append({"claim": claim, "setting": k, "tried": g[k].tolist(),
                         "holds_at": g.loc[g["verdict"] == "holds", k].tolist()})
    return pd.DataFrame(rows, columns=["claim", "setting", "tried", "holds_at"])


def sim_fields(point: dict, conf) -> dict:
    """The ``SimOptions`` fields a point sets (scene, camera and noise groups)."""
    exact = point["corner_noise_px"] < float(conf.exact_below_px)
    out = {"max_tilt_deg": point["max_tilt_deg"], "board_size_m": point["board_size_m"],
           "checker_square_m": round(float(conf.checker_per_board) * point["board_size_m"], 4),
           "bearing_spread_deg": point["bearing_spread_deg"], "pose_mode": "exact" if exact else "pixel"}
    if not exact:
        out["pixel_noise_px"] = point["corner_noise_px"]
    return out


def hydra_overrides(point: dict, conf) -> list[str]:
    """The point as Hydra overrides (``scene.max_tilt_deg=...``), the form of ``conf/preset/*.yaml``."""
    from ..config.schema import sim_group_of

    return [f"{sim_group_of(k)}.{k}={v}" for k, v in sim_fields(point, conf).items()]


def base_cells(conf, trials: int, results_dir: str) -> dict[str, list[Cell]]:
    """The paper's two sweeps composed once by Hydra with the search's run settings (no point applied)."""
    ov = [f"n_trials={trials}", f"results_dir={results_dir}", f"sweep={conf.sweep}", f"methods={conf.methods}",
          f"metrics.uncertainty={str(bool(conf.uncertainty)).lower()}", f"crn_stream={int(conf.crn_stream)}"]
    return {e: experiment_cells(e, ov) for e in PAPER_EXPERIMENTS}


def point_cells(point: dict, conf, base: dict[str, list[Cell]]) -> dict[str, list[Cell]]:
    """The point's cells: each base cell with the point's simulator fields (validated by ``SimOptions``)."""
    fields = sim_fields(point, conf)
    out = {}
    for e, cells in base.items():
        out[e] = [dataclasses.replace(c, sim=dataclasses.asdict(SimOptions(**{**c.sim, **fields}))) for c in cells]
    return out


def run_points(points: list[dict], conf, trials: int, results_dir: str, n_jobs: int, label: str) -> list[dict]:
    """Run every point's cells in one pool (cells shared between the sweeps run once); return the cells."""
    base = base_cells(conf, trials, results_dir)
    per_point = [point_cells(p, conf, base) for p in points]
    unique = {c.dir: c for pc in per_point for cs in pc.values() for c in cs}
    run_cells(list(unique.values()), n_jobs=n_jobs, label=label)
    return per_point


def evaluate_points(points: list[dict], per_point: list[dict], conf, stage: str,
                    n_boot: int = 0) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The objective per point (one row per point, best Zhang variant first) and each claim's verdict per point:
    on point values, or with ``n_boot`` resamples on paired 95% intervals (as the matched report judges)."""
    rows, verdicts = [], []
    claims = paper_claims()
    for p, cells in zip(points, per_point, strict=True):
        trials = {e: pd.concat([load_cell(c) for c in cs], ignore_index=True) for e, cs in cells.items()}
        sc = score(trials, conf.objective).sort_values("objective")
        best = sc.iloc[0]
        n = min(c.n_trials for cs in cells.values() for c in cs)
        rows.append({"stage": stage, **p, **sim_fields(p, conf), "trials": n, "zhang": best["zhang"],
                     "objective": best["objective"],
                     **{f"objective_{z}": float(sc.loc[sc["zhang"] == z, "objective"].iloc[0]) for z in sc["zhang"]},
                     **{k: best[k] for k in sc.columns if ":" in k and pd.notna(best[k])}})
        arrays = {e: sweep_arrays(t, PAPER_SWEEPS[e].x) for e, t in trials.items()}
        for i, claim in enumerate(claims, 1):
            vals = claim_values(None, claim, PAPER_SWEEPS[claim.sweep].x, n_boot=n_boot, arrays=arrays[claim.sweep])
            verdict = (claim_holds(claim, vals["value"], vals["lo95"], vals["hi95"]) if n_boot else
                       claim_holds(claim, vals["value"].to_numpy()))
            verdicts.append({"stage": stage, "point": p["point"], **{k: p[k] for k in SPACE_KEYS}, "claim": i,
                             "verdict": verdict})
    table = pd.DataFrame(rows).sort_values("objective").reset_index(drop=True)
    return table, pd.DataFrame(verdicts)


def write_preset(row: pd.Series, conf, path: Path = PRESET) -> Path:
    """``conf/preset/paper-matched.yaml``: the winning point as a Hydra preset (``preset=paper-matched``)."""
    groups: dict[str, dict] = {}
    for ov in hydra_overrides(row.to_dict(), conf):
        key, value = ov.split("=", 1)
        group, name = key.split(".", 1)
        groups.setdefault(group, {})[name] = value
    lines = ["# @package _global_",
             "# The paper-matched preset: the settings closest to the paper's numbers found by make search-paper",
             f"# (conf/search/paper.yaml; point {row['point']}, objective {row['objective']:.3f} at {row['trials']} "
             f"trials per point,", f"# Zhang played by {row['zhang']}). Generated by python -m experiments search "
             "--write-preset;",
             "# use: make reproduce-paper PRESET=paper-matched (or the override preset=paper-matched)."]
    for group, kv in groups.items():
        lines.append(f"{group}:")
        lines += [f"  {k}: {v}" for k, v in kv.items()]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def search(stage: str = "all", coarse_trials: int | None = None, fine_trials: int | None = None,
           best: int | None = None, results_dir: str = "results", n_jobs: int = -1, preset: bool = False,
           sens_trials: int | None = None) -> dict:
    conf = load_search_conf()
    out = Path(results_dir) / str(conf.sweep)
    out.mkdir(parents=True, exist_ok=True)
    points = design(conf)
    timings = {}
    if stage in ("coarse", "all"):
        t0 = time.perf_counter()
        per = run_points(points, conf, coarse_trials or int(conf.coarse.trials), results_dir, n_jobs, "search coarse")
        table, verdicts = evaluate_points(points, per, conf, "coarse")
        table.to_csv(out / "points_coarse.csv", index=False, float_format="%.6g")
        verdicts.to_csv(out / "verdicts_coarse.csv", index=False)
        timings["coarse_s"] = time.perf_counter() - t0
    if stage in ("fine", "all"):
        t0 = time.perf_counter()
        coarse = pd.read_csv(out / "points_coarse.csv")
        names = list(dict.fromkeys([*coarse["point"].head(best or int(conf.fine.best)), "default"]))
        chosen = [p for p in points if p["point"] in names]
        per = run_points(chosen, conf, fine_trials or int(conf.fine.trials), results_dir, n_jobs, "search fine")
        table, verdicts = evaluate_points(chosen, per, conf, "fine")
        table.to_csv(out / "points_fine.csv", index=False, float_format="%.6g")
        verdicts.to_csv(out / "verdicts_fine.csv", index=False)
        win = table.iloc[0]
        (out / "best.json").write_text(json.dumps({k: (v.item() if hasattr(v, "item") else v)
                                                   for k, v in win.items()}, indent=1) + "\n")
        if preset:
            write_preset(win, conf)
        timings["fine_s"] = time.perf_counter() - t0
    if stage in ("sensitivity", "all"):
        t0 = time.perf_counter()
        centre = json.loads((out / "best.json").read_text())
        chosen = sensitivity_points(conf, centre)
        per = run_points(chosen, conf, sens_trials or int(conf.sensitivity.trials), results_dir, n_jobs,
                         "search sensitivity")
        table, verdicts = evaluate_points(chosen, per, conf, "sensitivity", n_boot=int(conf.sensitivity.n_boot))
        table.to_csv(out / "points_sensitivity.csv", index=False, float_format="%.6g")
        verdicts.to_csv(out / "verdicts_sensitivity.csv", index=False)
        timings["sensitivity_s"] = time.perf_counter() - t0
    path = out / "timings.json"  # measured wall times of the stages, kept across runs of single stages
    path.write_text(json.dumps({**(json.loads(path.read_text()) if path.exists() else {}), **timings}, indent=1) + "\n")
    return {"out": out, **timings}


def main(argv: Sequence[str] | None = None) -> None:
    ap = study_parser(__doc__)
    ap.add_argument("--stage", choices=("coarse", "fine", "sensitivity", "all"), default="all")
    ap.add_argument("--coarse-trials", type=positive_int, default=None, help="trials per coarse point (config: 16)")
    ap.add_argument("--fine-trials", type=positive_int, default=None, help="trials per fine point (config: 1000)")
    ap.add_argument("--best", type=positive_int, default=None, help="coarse points taken to the fine stage (config: 3)")
    ap.add_argument("--sensitivity-trials", type=positive_int, default=None,
                    help="trials per point of the one-at-a-time lines through the winner (config: 100)")
    ap.add_argument("--results", default="results")
    ap.add_argument("--n-jobs", type=n_jobs, default=-1)
    ap.add_argument("--write-preset", action="store_true", help="write conf/preset/paper-matched.yaml")
    a = ap.parse_args(argv)
    r = search(a.stage, a.coarse_trials, a.fine_trials, a.best, a.results, a.n_jobs, a.write_preset,
               a.sensitivity_trials)
    print(", ".join(f"{k} {v:.1f}" for k, v in r.items() if k.endswith("_s")), f"-> {r['out']}")
