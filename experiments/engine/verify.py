"""Check a results folder: every chunk file of its stores parses in full (``engine.store.verify_store``), and
every generated ``REPORT.md`` under it states a code fingerprint equal to the current code's
(``engine.fingerprint.report_staleness``).

    python -m experiments verify [results_dir] [--sweep NAME]

Prints one line per problem (damaged chunk, stale report) and exits 1 when there is any (0 when all is sound); a
folder (or ``--sweep``) that holds neither a trial store nor a report is an error (exit 2), not "0 problems". A
rerun of the sweep recomputes the trials of a damaged chunk; rerunning the report's command regenerates it.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

from .cli import study_parser
from .fingerprint import report_staleness
from .store import verify_store


def main(argv: Sequence[str] | None = None) -> int:
    ap = study_parser(__doc__, prog="python -m experiments verify")
    ap.add_argument("results_dir", nargs="?", default="results")
    ap.add_argument("--sweep", default=None, help="one sweep (default: all)")
    args = ap.parse_args(argv)
    root = Path(args.results_dir) / (args.sweep or "")
    if not root.is_dir():
        print(f"{ap.prog}: error: {root}: not a folder", file=sys.stderr)
        return 2
    chunks = sorted(root.glob("trials/*/chunk-*.csv" if args.sweep else "*/trials/*/chunk-*.csv"))
    reports = sorted(p for p in root.rglob("REPORT.md") if "trials" not in p.parts)
    if not chunks and not reports:
        print(f"{ap.prog}: error: {root}: nothing to check (no trial store <sweep>/trials/ and no REPORT.md)",
              file=sys.stderr)
        return 2
    problems = verify_store(args.results_dir, args.sweep)
    problems += [f"{p}: stale report: {why}" for p in reports if (why := report_staleness(p))]
    for p in problems:
        print(p)
    print(f"{len(problems)} problem(s) in {args.results_dir}" + (f" ({args.sweep})" if args.sweep else "")
          + f": {len(chunks)} chunk file(s), {len(reports)} report(s) checked", file=sys.stderr)
    return 1 if problems else 0
