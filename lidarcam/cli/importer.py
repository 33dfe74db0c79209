"""``lidarcam import FORMAT SRC ... --out OUT``: calibration data in the formats it comes in, to the project's inputs.

Formats with images and raw scans write a dataset folder for ``lidarcam extract`` (docs/dataset.md):

- ``radlocc LASER.txt --images DIR [--image-name 'RGB{n}.png'] [--lines 31-61]``: RADLOCC laser lines, line n
  paired with image n;
- ``pcd LASERS_DIR --images DIR``: one PCD scan per pose, paired with the images in sorted order;
- ``ranges SCANS_DIR --images DIR --start-deg A --step-deg S --unit mm``: one range per line, one file per pose.

They need the camera (``--camera FILE``, or ``--intrinsics fx,fy,cx,cy [--dist k1,k2,p1,p2,k3]``) and the board
(``--board-grid COLSxROWS --square M``, the printed pattern; its outline is a lower bound of the board's).
Formats with board poses and segmented scan points write ``lidarcam.observations/1``:

- ``bouguet Calib_Results.mat --points POINTS.csv``: board poses, corners and intrinsics from the toolbox file (the
  joint model runs on them), scan points ``pose,x_m,y_m``;
- ``segmented POINTS.csv --poses POSES.csv --board-grid COLSxROWS --square M``: board poses as a CSV
  (``pose``, ``R_cam_board_00..22``, ``t_cam_board_{x,y,z}_mm``).

``--outline-kind`` (default ``lower_bound``: none of these formats holds the physical board's outline) is written
into the observations; for a dataset folder give it to ``extract``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from calib_core.data.observations import OUTLINE_KINDS
from calib_core.errors import LidarcamError

FORMATS = ("radlocc", "pcd", "ranges", "bouguet", "segmented")
DATASET_FORMATS = ("radlocc", "pcd", "ranges")


class ImportUsageError(LidarcamError):
    """A flag missing or malformed for the format asked for."""


def _numbers(text: str | None, name: str, count: int | None = None) -> list[float] | None:
    if text is None:
        return None
    try:
        v = [float(t) for t in text.replace(" ", "").split(",") if t]
    except ValueError:
        raise ImportUsageError(f"{name}: expected comma-separated numbers, got {text!r}") from None
    if count is not None and len(v) != count:
        raise ImportUsageError(f"{name}: expected {count} numbers, got {len(v)}")
    return v


def _grid(args):
    from lidarcam.rig.importing import pattern_board

    if args.board_grid is None or args.square is None:
        return None
    try:
        cols, rows = (int(t) for t in args.board_grid.lower().split("x"))
    except ValueError:
        raise ImportUsageError(f"--board-grid: expected COLSxROWS inner corners, e.g. 9x6, got "
                               f"{args.board_grid!r}") from None
    return pattern_board(cols, rows, args.square)


def _lines(text: str | None) -> range | None:
    if text is None:
        return None
    a, _, b = text.partition("-")
    try:
        return range(int(a), int(b or a) + 1)
    except ValueError:
        raise ImportUsageError(f"--lines: expected FIRST-LAST (1-based), got {text!r}") from None


def _need(args, *names: str) -> None:
    missing = [n for n in names if getattr(args, n) is None]
    if missing:
        raise ImportUsageError(f"import {args.format} needs " + ", ".join("--" + n.replace("_", "-") for n in missing))


def _source_poses(args):
    from lidarcam.rig import importing

    if args.format == "radlocc":
        return importing.radlocc_poses(args.src, args.images, _lines(args.lines), args.image_name)
    if args.format == "pcd":
        return importing.pcd_poses(args.src, args.images)
    _need(args, "start_deg", "step_deg")
    return importing.range_log_poses(args.src, args.images, math.radians(args.start_deg),
                                     math.radians(args.step_deg), args.unit, args.suffix)


def cmd_import(args) -> int:
    from calib_core.data.io import save_observations
    from lidarcam.rig import importing

    from .outputs import writable_file, writable_folder

    if args.format in DATASET_FORMATS:
        _need(args, "images", "board_grid", "square")
        writable_folder(args.out, "--out")
        poses = _source_poses(args)
        size = importing.image_size(poses[0].image)
        camera = importing.source_camera(args.camera, _numbers(args.intrinsics, "--intrinsics", 4),
                                         _numbers(args.dist, "--dist"), size)
        out = importing.write_dataset_folder(args.out, poses, camera, _grid(args))
        print(f"wrote {out}/ ({len(poses)} poses: {', '.join(p.name for p in poses)}); next: lidarcam extract "
              f"{out} --outline-kind {args.outline_kind} --out obs.json")
        return 0
    writable_file(args.out, "--out", parents=True)
    if args.format == "bouguet":
        _need(args, "points")
        obs = importing.observations_from_bouguet(args.src, args.points, args.outline_kind,
                                                  corners=not args.no_corners)
    else:
        _need(args, "poses")
        obs = importing.observations_from_segmented(args.src, args.poses, _grid(args), args.outline_kind)
    for name, why in obs.meta.get("skipped", {}).items():
        print(f"skipped {name}: {why}")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    save_observations(obs, args.out)
    print(f"wrote {args.out} ({obs.n_boards} boards" + (", image corners and camera" if obs.has_corners else "")
          + f", outline {args.outline_kind})")
    return 0


def add_parsers(subparsers) -> None:
    """Register the ``import`` verb on an argparse subparsers object."""
    p = subparsers.add_parser("import", help="calibration data in other formats -> a dataset folder or observations",
                              description=__doc__.split("\n\n")[0], epilog="formats: " + ", ".join(FORMATS),
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("format", choices=FORMATS, help="the source's format")
    p.add_argument("src", help="the laser log (radlocc), scan folder (pcd, ranges), Calib_Results.mat (bouguet) or "
                   "segmented points CSV (segmented)")
    p.add_argument("--out", required=True, help="dataset folder (radlocc, pcd, ranges) or observation JSON to write")
    p.add_argument("--images", help="folder of the images (radlocc, pcd, ranges)")
    p.add_argument("--image-name", default="RGB{n}.png", help="radlocc: image file of laser line n "
                   "(default: %(default)s)")
    p.add_argument("--lines", help="radlocc: laser lines FIRST-LAST to read (1-based; default all)")
    p.add_argument("--start-deg", type=float, help="ranges: bearing of the first beam (deg, counter-clockwise)")
    p.add_argument("--step-deg", type=float, help="ranges: bearing step between beams (deg)")
    p.add_argument("--unit", default="mm", choices=("m", "cm", "mm"), help="ranges: range unit (default: %(default)s)")
    p.add_argument("--suffix", default=".log", help="ranges: scan file suffix (default: %(default)s)")
    p.add_argument("--camera", help="camera file: ROS / OpenCV YAML or XML, Kalibr, or MATLAB text "
                   "(K = [...]; kc = [...])")
    p.add_argument("--intrinsics", metavar="FX,FY,CX,CY", help="the camera matrix instead of --camera (pixels)")
    p.add_argument("--dist", metavar="K1,K2,P1,P2[,K3]", help="distortion with --intrinsics (OpenCV order)")
    p.add_argument("--board-grid", metavar="COLSxROWS", help="inner corners of the checkerboard, e.g. 9x6")
    p.add_argument("--square", type=float, metavar="M", help="side of one square (metres)")
    p.add_argument("--points", help="bouguet: segmented scan points CSV (pose,x_m,y_m; pose = image index)")
    p.add_argument("--poses", help="segmented: board poses CSV (pose, R_cam_board_00..22, t_cam_board_x/y/z_mm)")
    p.add_argument("--no-corners", action="store_true", help="bouguet: leave the detected corners out")
    p.add_argument("--outline-kind", choices=OUTLINE_KINDS, default="lower_bound",
                   help="what the pattern's outline says of the board (default: %(default)s)")
    p.set_defaults(func=cmd_import)
