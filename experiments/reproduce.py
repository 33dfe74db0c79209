"""``make reproduce-paper``: both paper sweeps, then tables, figures 3-7 and REPORT.md in ``results/paper/``.

    python -m experiments.reproduce [--trials 100] [--results results] [--n-jobs -1] [OVERRIDE ...]

The sweeps are the Hydra experiments ``conf/experiment/boards.yaml`` and ``noise.yaml``, composed here with
their ``hydra.sweeper.params`` expanded as ``-m`` would, and run in one process pool (no per-job start-up).
Hydra overrides (``scene.max_tilt_deg=30``, ``methods=seed``) apply to both sweeps. Re-running resumes:
finished trials are read back, not recomputed.
"""

from __future__ import annotations

import argparse
import itertools
import time
from collections.abc import Sequence
from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.override_parser.overrides_parser import OverridesParser

from .aggregate import write_tables
from .cell import Cell
from .config import cell_from_cfg, register_configs
from .figures import draw_sweep
from .overrides import check_overrides
from .report import write_paper_report
from .runner import run_cells
from .store import load_cell

CONF_DIR = Path(__file__).resolve().parent.parent / "conf"
PAPER_EXPERIMENTS = ("boards", "noise")


def expand_sweep_params(params) -> list[list[str]]:
    """The override lists of a basic-sweeper ``params`` mapping (cartesian product, as ``-m`` runs them)."""
    if not params:
        return [[]]
    parser = OverridesParser.create()
    axes = []
    for key, value in params.items():
        (ov,) = parser.parse_overrides([f"{key}={value}"])
        axes.append([f"{ov.get_key_element()}={v}" for v in ov.sweep_string_iterator()]
                    if ov.is_sweep_override() else [f"{key}={value}"])
    return [list(combo) for combo in itertools.product(*axes)]


def experiment_cells(experiment: str, overrides: Sequence[str] = ()) -> list[Cell]:
    """The cells of ``experiment`` (one per point of its sweep) with ``overrides`` applied to each."""
    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        base = [f"experiment={experiment}", *overrides]
        check_overrides(base, lambda choices: compose(config_name="config", overrides=choices))
        cfg = compose(config_name="config", overrides=base, return_hydra_config=True)
        swept = {k for k, _ in (o.split("=", 1) for o in overrides)}
        params = {k: v for k, v in (cfg.hydra.sweeper.params or {}).items() if k not in swept}
        return [cell_from_cfg(compose(config_name="config", overrides=[*base, *combo]))
                for combo in expand_sweep_params(params)]


def reproduce(trials: int = 100, results_dir: str = "results", n_jobs: int = -1, overrides: Sequence[str] = (),
              experiments: Sequence[str] = PAPER_EXPERIMENTS, progress: bool = True) -> dict:
    """Run the sweeps, write the tables, figures and report; return paths and timings."""
    t0 = time.perf_counter()
    extra = [f"n_trials={trials}", f"results_dir={results_dir}", *overrides]
    cells = {e: experiment_cells(e, extra) for e in experiments}
    all_cells = [c for cs in cells.values() for c in cs]
    run_cells(all_cells, n_jobs=n_jobs, progress=progress, label="reproduce-paper")
    t_run = time.perf_counter() - t0
    out = Path(results_dir) / "paper"
    import pandas as pd

    for sweep, cs in cells.items():
        write_tables(pd.concat([load_cell(c) for c in cs], ignore_index=True), sweep, out)
        draw_sweep(out, sweep)
    report = write_paper_report(out)
    return {"out": out, "report": report, "cells": len(all_cells), "trials": sum(c.n_trials for c in all_cells),
            "methods": all_cells[0].methods, "run_s": t_run, "total_s": time.perf_counter() - t0}


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("overrides", nargs="*", help="Hydra overrides applied to both sweeps")
    ap.add_argument("--trials", type=int, default=100, help="trials per setting (paper: 100)")
    ap.add_argument("--results", default="results", help="results folder (default: results)")
    ap.add_argument("--n-jobs", type=int, default=-1, help="worker processes (-1: all cores)")
    args = ap.parse_args(argv)
    r = reproduce(args.trials, args.results, args.n_jobs, args.overrides)
    print(f"{r['cells']} settings x {r['trials'] // r['cells']} trials, methods {', '.join(r['methods'])}: "
          f"simulated and solved in {r['run_s']:.1f} s, {r['total_s']:.1f} s with tables, figures and report.")
    print(f"Tables:  {r['out']}/summary_*.csv, {r['out']}/trials_*.csv")
    print(f"Figures: {r['out']}/figures/ (fig3a-fig7, PNG and PDF)")
    print(f"Report:  {r['report']}")


if __name__ == "__main__":
    from .entry import run_main

    run_main(main)
