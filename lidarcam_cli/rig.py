"""CLI verbs for real rigs: ``lidarcam extract DATASET --out obs.json`` and ``lidarcam report DATASET RESULT``.

``add_parsers(subparsers)`` registers both verbs; each handler returns the exit code. Bad input raises a
LidarcamError, which ``lidarcam_cli.main`` prints as one line and exits 2.
"""

from __future__ import annotations

import argparse


def _options(args):
    from rig.extract import ExtractOptions

    return ExtractOptions(max_offset_m=args.max_offset, range_sigma_m=args.range_sigma,
                          max_reproj_px=args.max_reproj)


def _add_extract_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--max-offset", type=float, default=0.5, metavar="M",
                   help="bound on the lidar-camera separation in metres (default: %(default)s)")
    p.add_argument("--range-sigma", type=float, default=0.02, metavar="M",
                   help="lidar range noise, 1 sigma, metres (default: %(default)s)")
    p.add_argument("--max-reproj", type=float, default=2.0, metavar="PX",
                   help="reject a board whose corner reprojection RMS exceeds this (default: %(default)s px)")


def cmd_extract(args) -> int:
    """``lidarcam extract``: dataset -> observation JSON; prints per-pose diagnostics and skip reasons."""
    import json
    from pathlib import Path

    from calib_core.data.io import save_observations
    from rig.dataset import DatasetError, load_dataset
    from rig.extract import extract, format_diagnostics
    from rig.report import capture_verdict

    ds = load_dataset(args.dataset)
    obs, diags = extract(ds, _options(args))
    print(format_diagnostics(diags))
    if args.diagnostics:
        Path(args.diagnostics).write_text(json.dumps([d.to_dict() for d in diags], indent=1) + "\n")
        print(f"wrote {args.diagnostics}")
    if obs.n_boards == 0:
        raise DatasetError("no usable pose (see the skip reasons above)", file=args.dataset)
    save_observations(obs, args.out)
    print(f"wrote {args.out} ({obs.n_boards} boards)")
    print(f"capture plan: {capture_verdict(obs)}")
    return 0


def cmd_report(args) -> int:
    """``lidarcam report``: overlays, residual plots and report.md for a result on a dataset."""
    from calib_core.data.io import load_observations
    from calib_core.data.result import load_result
    from rig.dataset import load_dataset
    from rig.extract import extract
    from rig.report import write_report

    ds = load_dataset(args.dataset)
    res = load_result(args.result)
    obs = load_observations(args.obs) if args.obs else extract(ds, _options(args))[0]
    summary = write_report(ds, obs, res, args.out)
    for w in summary.warnings:
        print(f"warning: {w}")
    print(f"wrote {summary.markdown} ({len(summary.overlays)} overlays, {len(summary.residual_plots)} residual plots)")
    return 0 if res.get("ok") else 1


def add_parsers(subparsers) -> None:
    """Register the ``extract`` and ``report`` verbs on an argparse subparsers object."""
    p = subparsers.add_parser("extract", help="board poses and board scan points from a dataset folder",
                              description="Detect the board in each image, find its points in each scan, write "
                                          "lidarcam.observations/1 JSON. Layout: docs/dataset.md.")
    p.add_argument("dataset", help="dataset folder (camera.yaml, board.yaml, NNN.png + NNN.csv, ...)")
    p.add_argument("--out", required=True, help="observation JSON to write")
    p.add_argument("--diagnostics", help="also write the per-pose diagnostics as JSON here")
    _add_extract_options(p)
    p.set_defaults(func=cmd_extract)

    p = subparsers.add_parser("report", help="overlays, residual plots and report.md of a calibration result",
                              description="Project the scans into the images through the result's extrinsic, "
                                          "plot residuals per board and write report.md.")
    p.add_argument("dataset", help="dataset folder")
    p.add_argument("result", help="lidarcam.result/1 JSON (from lidarcam calibrate --out)")
    p.add_argument("--out", required=True, help="folder to write the report into")
    p.add_argument("--obs", help="observation JSON from lidarcam extract (default: extract again)")
    _add_extract_options(p)
    p.set_defaults(func=cmd_report)

