"""The ``lidarcam`` console script: a thin argparse front over the verbs (``simulate``, ...)."""

from __future__ import annotations

import argparse


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with every verb registered."""
    from simulate.cli import add_parser as add_simulate

    parser = argparse.ArgumentParser(prog="lidarcam", description="2D lidar - camera extrinsic calibration.")
    sub = parser.add_subparsers(dest="verb", required=True)
    add_simulate(sub)
    return parser


def main(argv=None) -> int:
    """Entry point: parse ``argv`` (default ``sys.argv[1:]``) and run the verb; returns the exit status."""
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    raise SystemExit(main())
