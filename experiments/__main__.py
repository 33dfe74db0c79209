"""The one door of the benchmark: ``python -m experiments <study> [ARGS ...]`` (``python -m experiments`` lists them).

Each study is one module's ``main(argv)``, imported only when asked for; every study ends as
``engine.entry.run_main`` says (Ctrl-C: one line, exit 130; a configuration or run error: one line, exit 2). The
Hydra runner stays ``python -m experiments.run`` (its overrides and ``-m`` sweeps are Hydra's command line).
"""

from __future__ import annotations

import difflib
import importlib
import sys

from .engine.entry import run_main

STUDIES = {
    "reproduce": ("paper.reproduce", "the paper's sweeps, figures 3-7 and REPORT.md (make reproduce-paper)"),
    "matched": ("paper.matched", "the paper's claims under a preset (make reproduce-paper PRESET=...)"),
    "matched-report": ("paper.matched_report", "rewrite the preset report from stored rows"),
    "report": ("paper.report", "rewrite results/paper/REPORT.md from stored rows"),
    "search": ("paper.settings_search", "search the paper's unstated settings (make search-paper)"),
    "explain": ("paper.explain", "ablations of peng2022 and unstated-setting sweeps (make explain-paper)"),
    "francisco": ("paper.francisco", "claim 1 under both readings of Francisco"),
    "rig-like": ("paper.rig_like", "every method at 3-8 boards under rig conditions (make rig-like)"),
    "leaderboard": ("suites.leaderboard", "every registered method on a leaderboard suite (make leaderboard)"),
    "outliers": ("suites.outliers", "wrong boards, outlier points, mixed pixels (make robustness)"),
    "corner-noise": ("suites.corner_noise", "camera-noise sweeps, joint model (make corner-noise)"),
    "plan-check": ("suites.plan_check", "the capture planner against the simulator (make plan-check)"),
    "clean-check": ("suites.clean_check", "lidarcam against the joint bound on clean data"),
    "real-data": ("real.real_data", "the public rigs end to end and the paper's real experiment (make real-data)"),
    "bench": ("bench.bench", "time calibrate() per method (make bench)"),
    "solvers": ("bench.solver_bench", "the minimal solvers per board triple"),
    "bag-recording": ("bench.bag_recording", "time the bag path on a simulated recording"),
    "aggregate": ("summary.aggregate", "a sweep's trial rows -> summary tables"),
    "figures": ("summary.figures", "a sweep's summary -> figures"),
    "verify": ("engine.verify", "check the stores and reports of a results folder (make verify-results)"),
}
"""Study name -> (module under ``experiments``, what it does)."""
PROG = "python -m experiments"


def usage() -> str:
    width = max(map(len, STUDIES))
    rows = [f"  {name:<{width}}  {what}" for name, (_, what) in STUDIES.items()]
    return "\n".join([f"usage: {PROG} <study> [ARGS ...]  ({PROG} <study> --help: its arguments)", "", "studies:",
                      *rows, "", "Hydra runner: python -m experiments.run [-m] [OVERRIDE ...]"])


def main(argv: list[str] | None = None) -> int | None:
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in STUDIES:
        close = difflib.get_close_matches(name, STUDIES, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else f" (studies: {', '.join(STUDIES)})"
        print(f"{PROG}: error: no study {name!r}{hint}", file=sys.stderr)
        return 2
    module = importlib.import_module(f"{__package__}.{STUDIES[name][0]}")
    sys.argv[0] = f"{PROG} {name}"  # argparse's prog in each study's usage line
    return module.main(rest)


if __name__ == "__main__":
    run_main(main, prog=PROG)
