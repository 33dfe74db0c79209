"""Check a results folder: every chunk file of its stores parses in full (``engine.store.verify_store``), and
every generated ``REPORT.md`` under it states a code fingerprint equal to the current code's
(``engine.fingerprint.report_staleness``).

    python -m experiments verify [results_dir] [--sweep NAME]

Prints one line per problem (damaged chunk, stale report) and exits 1 when there is any (0 when all is sound). A
rerun of the sweep recomputes the trials of a damaged chunk; rerunning the report's command regenerates it.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from .fingerprint import report_staleness
from .store import verify_store


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m experiments verify",
                                 description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("results_dir", nargs="?", default="results")
    ap.add_argument("--sweep", default=None, help="one sweep (default: all)")
    args = ap.parse_args(argv)
    if not Path(args.results_dir).is_dir():
        print(f"error: {args.results_dir}: not a folder", file=sys.stderr)
        return 2
    problems = verify_store(args.results_dir, args.sweep)
    root = Path(args.results_dir) / (args.sweep or "")
    reports = sorted(p for p in root.rglob("REPORT.md") if "trials" not in p.parts)
    problems += [f"{p}: stale report: {why}" for p in reports if (why := report_staleness(p))]
    for p in problems:
        print(p)
    print(f"{len(problems)} problem(s) in {args.results_dir}" + (f" ({args.sweep})" if args.sweep else ""),
          file=sys.stderr)
    return 1 if problems else 0
