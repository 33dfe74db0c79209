"""``make reproduce-paper``: both paper sweeps, then tables, figures 3-7 and REPORT.md in ``results/paper/``.

    python -m experiments reproduce [--trials 100] [--results results] [--n-jobs -1] [OVERRIDE ...]

The sweeps are the Hydra experiments ``conf/experiment/boards.yaml`` and ``noise.yaml``, composed here with
their ``hydra.sweeper.params`` expanded as ``-m`` would, and run in one process pool (no per-job start-up).
Hydra overrides (``scene.max_tilt_deg=30``, ``methods=seed``) apply to both sweeps. Re-running resumes:
finished trials are read back, not recomputed.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

from ..config.overrides import refuse_flag_overrides
from ..config.sweeps import experiment_cells
from ..engine.cli import n_jobs, positive_int, study_parser
from ..engine.runner import run_cells
from ..summary.unchanged import inputs_digest, record, unchanged

PAPER_EXPERIMENTS = ("boards", "noise")


def reproduce(trials: int = 100, results_dir: str = "results", n_jobs: int = -1, overrides: Sequence[str] = (),
              experiments: Sequence[str] = PAPER_EXPERIMENTS, progress: bool = True) -> dict:
    """Run the sweeps, write the tables, figures and report; return paths and timings."""
    t0 = time.perf_counter()
    extra = [f"n_trials={trials}", f"results_dir={results_dir}", *overrides]
    cells = {e: experiment_cells(e, extra) for e in experiments}
    all_cells = [c for cs in cells.values() for c in cs]
    rows = run_cells(all_cells, n_jobs=n_jobs, progress=progress, label="reproduce-paper")
    t_run = time.perf_counter() - t0
    out = Path(results_dir) / "paper"
    report = out / "REPORT.md"
    digest = inputs_digest(rows, experiments=list(cells))
    redrawn = not unchanged(out, digest)
    if redrawn:  # the tables, figures and report of these very rows and code are there already otherwise
        from ..summary.aggregate import write_tables
        from ..summary.figures import draw_sweep
        from .report import write_paper_report

        for sweep, cs in cells.items():
            mine = rows["sweep"].isin({c.sweep for c in cs}) & rows["setting_key"].isin([c.key for c in cs])
            write_tables(rows[mine].reset_index(drop=True), sweep, out)  # a key may be in both sweeps
            draw_sweep(out, sweep)
        report = write_paper_report(out)
        record(out, digest)
    return {"out": out, "report": report, "cells": len(all_cells), "trials": sum(c.n_trials for c in all_cells),
            "methods": all_cells[0].methods, "run_s": t_run, "total_s": time.perf_counter() - t0,
            "redrawn": redrawn}


def main(argv: Sequence[str] | None = None) -> None:
    ap = study_parser(__doc__)
    ap.add_argument("overrides", nargs="*", help="Hydra overrides applied to both sweeps")
    ap.add_argument("--trials", type=positive_int, default=100, help="trials per setting (paper: 100)")
    ap.add_argument("--results", default="results", help="results folder (default: results)")
    ap.add_argument("--n-jobs", type=n_jobs, default=-1, help="worker processes (-1: all cores)")
    args = ap.parse_args(argv)
    refuse_flag_overrides(args.overrides, {"results_dir": "--results", "n_trials": "--trials"})
    r = reproduce(args.trials, args.results, args.n_jobs, args.overrides)
    print(f"{r['cells']} settings x {r['trials'] // r['cells']} trials, methods {', '.join(r['methods'])}: "
          f"simulated and solved in {r['run_s']:.1f} s, {r['total_s']:.1f} s with tables, figures and report"
          + ("." if r["redrawn"] else " (unchanged: the same rows and code drew them; not redrawn)."))
    print(f"Tables:  {r['out']}/summary_*.csv, {r['out']}/trials_*.csv")
    print(f"Figures: {r['out']}/figures/ (fig3a-fig7, PNG and PDF)")
    print(f"Report:  {r['report']}")
