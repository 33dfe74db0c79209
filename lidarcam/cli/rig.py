"""CLI verbs for real rigs: ``lidarcam import FORMAT SRC ... --out DATASET_OR_OBS``, ``lidarcam extract DATASET --out
obs.json`` and ``lidarcam report DATASET_OR_OBS RESULT``.

``add_parsers(subparsers)`` registers the verbs; each handler returns the exit code. Bad input raises a
LidarcamError, which ``lidarcam.cli.main`` prints as one line and exits 2. The assembling is
``lidarcam.rig.importing``'s
(``make real-data`` uses the same functions).
"""

from __future__ import annotations

import argparse

from calib_core.data.observations import OUTLINE_KINDS
from lidarcam.rig.extract_options import CURVATURE_CHI2, SCAN_DIRECTIONS


def check_noise_flags(args) -> None:
    """``--range-sigma`` and ``--max-curvature-chi2``, when given, must be positive finite numbers."""
    import math

    from lidarcam.rig.extract_options import ExtractionError

    for flag, v in (("--range-sigma", args.range_sigma), ("--max-curvature-chi2",
                                                          getattr(args, "max_curvature_chi2", None))):
        if v is not None and not (math.isfinite(v) and v > 0):
            raise ExtractionError(f"{flag} must be a positive number, got {v!r} (leave it out to estimate it from "
                                  "the boards' scan segments)")


def _options(args):
    from lidarcam.rig.extract import ExtractOptions

    check_noise_flags(args)
    return ExtractOptions(max_offset_m=args.max_offset, range_sigma_m=args.range_sigma,
                          max_reproj_px=args.max_reproj, outline_kind=args.outline_kind,
                          max_curvature_chi2=args.max_curvature_chi2, max_board_m=args.max_board)


def _dataset(args):
    """The dataset folder, its camera refitted from its images with ``--refit-intrinsics`` (the fit printed)."""
    from lidarcam.rig.dataset import load_dataset
    from lidarcam.rig.intrinsics import format_intrinsics, refit_camera

    ds = load_dataset(args.dataset, args.scan_direction)
    if args.refit_intrinsics:
        ds, fit = refit_camera(ds)
        print("intrinsics refitted from the images: " + format_intrinsics(fit)[0])
    return ds


def _add_extract_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--max-offset", type=float, default=0.5, metavar="M",
                   help="bound on the lidar-camera separation in metres (default: %(default)s)")
    p.add_argument("--range-sigma", type=float, default=None, metavar="M",
                   help="lidar range noise, 1 sigma, metres (default: estimated from the boards' scan segments, "
                   "their scatter about a line, colour bias included; 0.02 with fewer than 3 segments)")
    p.add_argument("--max-reproj", type=float, default=2.0, metavar="PX",
                   help="reject a board whose corner reprojection RMS exceeds this (default: %(default)s px)")
    p.add_argument("--outline-kind", choices=OUTLINE_KINDS, default="exact",
                   help="what board.yaml's outline is: the board's edge (exact, default), a lower bound (the "
                   "printed pattern on a larger board: the scan may run past it) or none (not known)")
    p.add_argument("--refit-intrinsics", action="store_true",
                   help="fit the camera from the dataset's own images instead of camera.yaml (rough intrinsics)")
    p.add_argument("--max-curvature-chi2", type=float, default=None, metavar="X",
                   help="refuse a segment as an arc above this curvature statistic (chi-square(1) units of the "
                   f"range noise; default: {CURVATURE_CHI2} times how much the boards' own segments bend, e.g. "
                   "a lidar whose range depends on the surface colour)")
    p.add_argument("--scan-direction", choices=SCAN_DIRECTIONS, default=None,
                   help="which way the scans count their bearings: ccw (counter-clockwise about the lidar's z axis, "
                   "up; ROS's convention) or cw (read mirrored); default: the dataset's lidar.yaml, else ccw")
    p.add_argument("--max-board", type=float, default=2.0, metavar="M",
                   help="longest accepted board segment when the outline is not exact (default: %(default)s m)")


def cmd_extract(args) -> int:
    """``lidarcam extract``: dataset -> observation JSON; prints per-pose diagnostics and skip reasons."""
    import json
    import sys
    from pathlib import Path

    from calib_core.data.io import save_observations
    from lidarcam.rig.extract import direction_line, extract, format_diagnostics, noise_line
    from lidarcam.rig.report import capture_advice

    from .hints import square_hint
    from .outputs import writable_file
    from .wording import cli_hint

    writable_file(args.out, "--out")
    writable_file(args.diagnostics, "--diagnostics")
    ds = _dataset(args)
    obs, diags = extract(ds, _options(args))
    print(format_diagnostics(diags))
    print(direction_line(obs.meta))
    print(noise_line(obs.meta))
    if obs.meta.get("camera_file_note"):
        print(f"note: {obs.meta['camera_file_note']}")
    if args.diagnostics:
        Path(args.diagnostics).write_text(json.dumps([d.to_dict() for d in diags], indent=1) + "\n")
        print(f"wrote {args.diagnostics}")
    hint = square_hint(ds, diags)
    if hint:
        print(hint)
    if obs.n_boards == 0:  # no answer, as calibrate's: exit 1 (docs/usage.md, lidarcam --help)
        print(f"lidarcam extract: {args.dataset}: no usable pose (see the skip reasons above); nothing written",
              file=sys.stderr)
        return 1
    save_observations(obs, args.out)
    print(f"wrote {args.out} ({obs.n_boards} boards)")
    print(f"capture plan: {cli_hint(capture_advice(obs))}")
    return 0


def cmd_report(args) -> int:
    """``lidarcam report``: the result checked against the observations (``rig.result_match``), then overlays,
    residual plots, report.md and report.html for it on a dataset or an observation file."""
    from pathlib import Path

    from calib_core.data.io import load_observations
    from calib_core.data.result import load_result
    from lidarcam.rig.extract import extract
    from lidarcam.rig.report import write_report
    from lidarcam.rig.result_match import result_fit

    from .outputs import writable_folder

    writable_folder(args.out, "--out")
    res = load_result(args.result)
    if Path(args.dataset).is_file():  # observations without images (imported board poses and points)
        ds, obs = None, load_observations(args.dataset)
    else:
        ds = _dataset(args)
        obs = load_observations(args.obs) if args.obs else extract(ds, _options(args))[0]
        if obs.camera is not None:  # the camera the observations were extracted with (e.g. refitted)
            from dataclasses import replace

            from lidarcam.rig.dataset import CameraModel

            ds = replace(ds, camera=CameraModel.from_core(obs.camera))
    fit = result_fit(res, obs, args.result, args.obs or args.dataset)
    summary = write_report(ds, obs, res, args.out, alerts=fit.warnings)
    from .wording import cli_hint

    for w in summary.warnings:
        print(f"warning: {cli_hint(w)}")
    views = f", {len(summary.board_views)} board views" if summary.board_views else ""
    print(f"wrote {summary.html} and {summary.markdown.name} ({len(summary.overlays)} overlays, "
          f"{len(summary.residual_plots)} residual plots{views})")
    return 0 if res.get("ok") and fit.fits else 1


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

    p = subparsers.add_parser("report", help="report.html (one self-contained page) and report.md of a calibration "
                              "result: overlays, residuals, verdict",
                              description="Check that the result belongs to these boards, project the scans into the "
                                          "images through the result's extrinsic (boards face-on for observations "
                                          "without images), plot residuals per board and write report.html and "
                                          "report.md. Exit 1 when the result failed or does not fit the boards.")
    p.add_argument("dataset", help="dataset folder, or an observation JSON (no overlays then)")
    p.add_argument("result", help="lidarcam.result/1 JSON (from lidarcam calibrate --out)")
    p.add_argument("--out", required=True, help="folder to write the report into")
    p.add_argument("--obs", help="observation JSON from lidarcam extract (default: extract again)")
    _add_extract_options(p)
    p.set_defaults(func=cmd_report)

