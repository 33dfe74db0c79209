"""``make reproduce-paper PRESET=paper-matched``: the paper's sweeps under a preset, judged beside the default.

    python -m experiments matched [--preset paper-matched] [--trials 500] [--compare-trials 500 | 0]
                                  [--results results] [--n-jobs -1] [OVERRIDE ...]

Runs ``conf/experiment/boards.yaml`` and ``noise.yaml`` with ``preset=<preset>`` (``conf/preset/``) and the
paper's four methods and Francisco as its authors' code runs it (``methods=readings``: the claims compare only
those), writes tables and figures into
``<results>/<preset>/``; then, unless ``--compare-trials 0``, the same sweeps under the default preset into
``<results>/<preset>/default/`` (seeded as ``make reproduce-paper``: the same simulated
trials, so its first 100 trials give the default report's valid rates). ``REPORT.md`` judges every claim under
both with paired 95% bootstrap intervals (``experiments.paper.claim_stats``) and reads the search's tables
(``<results>/search/``) for the sensitivity. Every setting runs at least ``--trials`` trials, more where a valid
rate's or a paired valid-rate gap's 95% interval would be wider than +-5 points (``needed_trials``). Re-running
resumes; ``timings.json`` keeps the measured wall
times of each part.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..config.overrides import refuse_flag_overrides
from ..config.sweeps import experiment_cells
from ..engine.cell import Cell
from ..engine.cli import n_jobs, nonnegative_int, positive_int, study_parser
from ..engine.runner import run_cells
from ..engine.store import load_cell
from ..summary.aggregate import write_tables
from ..summary.figures import draw_sweep
from ..summary.intervals import paired_half_width, wilson_interval
from .claims import PAPER
from .reproduce import PAPER_EXPERIMENTS

RUN_OVERRIDES = ("methods=readings", "metrics.uncertainty=false")  # the claims read neither the others nor CRLBs
TARGET_HALF_WIDTH_PTS = 5.0
"""Widest 95% interval (+- percentage points) allowed for a valid rate, and for a paired valid-rate gap of the
paper's method over another, at any setting: cells wider than this get more trials."""
SIZING_MARGIN = 0.95
"""Trials are sized for this fraction of the target (the report's bootstrap intervals are a little wider or
narrower than the normal approximation used to size them)."""
MAX_TRIALS = 3000
"""No setting runs more trials than this, whatever its interval."""


def needed_trials(rows: pd.DataFrame, target_pts: float = TARGET_HALF_WIDTH_PTS) -> int:
    """Trials one setting needs so that every method's valid rate (Wilson) and every paired gap ``peng2022 - m``
    (normal approximation of the paired difference) has a 95% half-width of at most ``target_pts`` points,
    judged on the ``rows`` already run (never fewer than their count; at most ``MAX_TRIALS``)."""
    v = rows.pivot(index="trial", columns="method", values="valid").astype(float).fillna(0.0)
    n = len(v)
    if n < 2:
        return n
    lo, hi = wilson_interval(v.sum().to_numpy(), n)
    widths = list(100 * (hi - lo) / 2)
    if PAPER in v.columns:
        gaps = v[PAPER].to_numpy()[:, None] - v.drop(columns=PAPER).to_numpy()
        widths += list(100 * paired_half_width(gaps))
    worst, goal = max(widths, default=0.0), SIZING_MARGIN * target_pts
    return n if worst <= goal else int(min(MAX_TRIALS, max(n, np.ceil(n * (worst / goal) ** 2))))


def run_sized(cells: list[Cell], n_jobs: int, label: str, rounds: int = 3, run: bool = True) -> list[Cell]:
    """Run ``cells``, then give every setting whose intervals are wider than the target the trials it needs
    (``needed_trials``; the runner extends a cell, its earlier trials kept), up to ``rounds`` times; returns the
    cells with their final trial counts. ``run=False``: the same sizing on the trials already stored."""
    if run:
        run_cells(cells, n_jobs=n_jobs, label=label)
    for _ in range(rounds):
        grown = [dataclasses.replace(c, n_trials=max(c.n_trials, needed_trials(load_cell(c)))) for c in cells]
        more = [g for c, g in zip(cells, grown, strict=True) if g.n_trials > c.n_trials]
        cells = grown
        if not more:
            break
        if run:
            run_cells(more, n_jobs=n_jobs, label=f"{label}, more trials where an interval is wide")
    return cells


def run_preset(preset: str | None, trials: int, results_dir: str, out: Path, n_jobs: int,
               overrides: Sequence[str] = (), figures: bool = True, run: bool = True) -> float:
    """Run both paper sweeps under ``preset`` (None: the default), write their tables into ``out``; seconds.
    ``run=False``: tables of the trials already stored (up to ``trials`` per setting), nothing computed."""
    t0 = time.perf_counter()
    extra = [f"n_trials={trials}", f"results_dir={results_dir}", *RUN_OVERRIDES, *overrides]
    if preset:
        extra.append(f"preset={preset}")
    cells = {e: experiment_cells(e, extra) for e in PAPER_EXPERIMENTS}
    sweeps = [e for e, cs in cells.items() for _ in cs]
    flat = run_sized([c for cs in cells.values() for c in cs], n_jobs, f"reproduce {preset or 'default'}", run=run)
    cells = {e: [c for s, c in zip(sweeps, flat, strict=True) if s == e] for e in cells}
    for sweep, cs in cells.items():
        write_tables(pd.concat([load_cell(c) for c in cs], ignore_index=True), sweep, out)
        if figures:
            draw_sweep(out, sweep)
            for pdf in (out / "figures").glob("*.pdf"):
                pdf.unlink()  # PNG only: the PDFs of the default report are enough
    return time.perf_counter() - t0


def matched(preset: str = "paper-matched", trials: int = 500, compare_trials: int = 500,
            results_dir: str = "results", n_jobs: int = -1, overrides: Sequence[str] = (), run: bool = True,
            compare_from: str | None = None) -> dict:
    from .matched_report import write_matched_report

    out = Path(results_dir) / preset
    out.mkdir(parents=True, exist_ok=True)
    timings_path = out / "timings.json"
    timings = json.loads(timings_path.read_text()) if timings_path.exists() else {}
    if run:
        timings[f"{preset}_s"] = run_preset(preset, trials, results_dir, out, n_jobs, overrides)
        timings[f"{preset}_trials"] = trials
    else:
        run_preset(preset, trials, results_dir, out, n_jobs, overrides, run=False)
    if compare_from:  # the default's tables of an earlier run (e.g. results/paper), copied as they are
        (out / "default").mkdir(exist_ok=True)
        for f in Path(compare_from).glob("*_*.*"):
            if f.name.startswith(("summary_", "trials_", "settings_")):
                shutil.copy(f, out / "default" / f.name)
    elif compare_trials:
        wall = run_preset(None, compare_trials, results_dir, out / "default", n_jobs, overrides, figures=False,
                          run=run)
        if run:
            timings["default_s"], timings["default_trials"] = wall, compare_trials
    timings_path.write_text(json.dumps(timings, indent=1) + "\n")
    t0 = time.perf_counter()
    report = write_matched_report(out, preset, Path(results_dir) / "search")
    return {"out": out, "report": report, "report_s": time.perf_counter() - t0, **timings}


def main(argv: Sequence[str] | None = None) -> None:
    ap = study_parser(__doc__)
    ap.add_argument("overrides", nargs="*", help="Hydra overrides applied to every sweep")
    ap.add_argument("--preset", default="paper-matched", help="conf/preset/<name>.yaml")
    ap.add_argument("--trials", type=positive_int, default=500, help="trials per setting under the preset")
    ap.add_argument("--compare-trials", type=nonnegative_int, default=500,
                    help="trials per setting under the default (0: skip)")
    ap.add_argument("--results", default="results")
    ap.add_argument("--n-jobs", type=n_jobs, default=-1)
    ap.add_argument("--no-run", action="store_true", help="tables and report of the stored trials only")
    ap.add_argument("--compare-from", default=None, help="take the default's tables from this folder instead")
    a = ap.parse_args(argv)
    refuse_flag_overrides(a.overrides, {"results_dir": "--results", "n_trials": "--trials and --compare-trials"})
    r = matched(a.preset, a.trials, a.compare_trials, a.results, a.n_jobs, a.overrides, not a.no_run,
                a.compare_from)
    print(", ".join(f"{k} {v:.1f}" for k, v in r.items() if k.endswith("_s")))
    print(f"Report: {r['report']}")
