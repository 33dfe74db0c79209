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

``--scan-direction cw`` declares a lidar that counts its bearings clockwise: a dataset folder gets ``lidar.yaml``
(``extract`` then reads its scans mirrored), observations get their points mirrored. For ``radlocc`` it is read,
when not given, from a settings file beside the laser log or the camera file that states ``Laser_Direction``
(1 clockwise, 2 counter-clockwise).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from calib_core.data.observations import OUTLINE_KINDS
from calib_core.errors import LidarcamError
from lidarcam.rig.extract_options import SCAN_DIRECTIONS

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


SQUARE_M = (0.004, 0.5)
"""Plausible side of a checkerboard square (metres): a square outside is a unit mistake, named as one."""
UNIT_M = {"m": 1.0, "cm": 0.01, "mm": 0.001}
"""``--unit`` choices of ``import ranges``, in metres."""
RANGE_MEDIAN_M = (0.1, 100.0)
"""Plausible median range of a 2D lidar's returns (metres) on a calibration capture."""


def _likely_unit(value: float, plausible: tuple[float, float], units=(("mm", 1e-3), ("cm", 1e-2), ("m", 1.0),
                                                                         ("km", 1e3))) -> str:
    """``'; millimetres? ...'``-like hint when ``value`` (read as metres) is plausible in another unit."""
    lo, hi = plausible
    for name, f in units:
        if f != 1.0 and lo <= value * f <= hi:
            return f" ({value:g} {name} would be {value * f:g} m)"
    return ""


def _square(value: float) -> float:
    lo, hi = SQUARE_M
    if not (math.isfinite(value) and value > 0):
        raise ImportUsageError(f"--square: expected the side of one square in metres (> 0), got {value}")
    if not lo <= value <= hi:
        raise ImportUsageError(f"--square {value:g}: a square of {value:g} m is not plausible (a checkerboard's is "
                               f"{lo * 1000:g} mm to {hi:g} m); the value is in metres"
                               + _likely_unit(value, SQUARE_M))
    return value


def _grid(args):
    from lidarcam.rig.importing import pattern_board

    if args.board_grid is None or args.square is None:
        return None
    try:
        cols, rows = (int(t) for t in args.board_grid.lower().split("x"))
    except ValueError:
        cols = rows = 0
    if cols < 2 or rows < 2:
        raise ImportUsageError(f"--board-grid: expected COLSxROWS inner corners (each at least 2), e.g. 9x6, got "
                               f"{args.board_grid!r}")
    return pattern_board(cols, rows, _square(args.square))


def _image_name(text: str) -> str:
    """``--image-name`` once it formats with the line number ``n`` alone."""
    try:
        if text.format(n=1) == text.format(n=2):
            raise KeyError
    except (KeyError, IndexError, ValueError, AttributeError):
        raise ImportUsageError(f"--image-name: expected a file name holding {{n}} (the laser line's number, e.g. "
                               f"RGB{{n}}.png or img{{n:04d}}.jpg), got {text!r}") from None
    return text


def check_range_units(poses, unit: str | None) -> None:
    """ImportUsageError when the median return over the poses is not a plausible lidar range in metres: a unit
    mistake. ``unit``: the ``--unit`` that scaled the ranges (the unit that would fit is named), or None when the
    source states its own unit."""
    import numpy as np

    r = np.concatenate([p.scan.range for p in poses]) if poses else np.zeros(0)
    r = r[np.isfinite(r) & (r > 0)]
    lo, hi = RANGE_MEDIAN_M
    med = float(np.median(r)) if r.size else lo
    if lo <= med <= hi:
        return
    if unit is None:
        hint = "; check the unit the source states"
    else:
        raw = med / UNIT_M[unit]
        fits = [n for n in UNIT_M if lo <= raw * UNIT_M[n] <= hi]  # the likeliest: nearest a few metres
        best = min(fits, key=lambda n: abs(math.log(raw * UNIT_M[n] / math.sqrt(lo * hi))), default=None)
        hint = f"; the ranges look like {best}: --unit {best}" if best else ""
        unit = f"--unit {unit}"
    raise ImportUsageError(f"median range {med:g} m{f' with {unit}' if unit else ''} is not a plausible lidar "
                           f"range ({lo:g} to {hi:g} m){hint}")


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
        return importing.radlocc_poses(args.src, args.images, _lines(args.lines), _image_name(args.image_name))
    if args.format == "pcd":
        return importing.pcd_poses(args.src, args.images)
    _need(args, "start_deg", "step_deg")
    return importing.range_log_poses(args.src, args.images, math.radians(args.start_deg),
                                     math.radians(args.step_deg), args.unit, args.suffix)


def is_dataset_folder(folder: Path) -> bool:
    """Whether ``folder`` holds a dataset folder and nothing else (``camera.yaml``, ``board.yaml``, pose images and
    scans, ``lidar.yaml``, the bag verb's ``picking.json``): an earlier import, which a new import replaces whole."""
    from lidarcam.rig.dataset import IMAGE_SUFFIXES

    names = {e.name for e in folder.iterdir()}
    return {"camera.yaml", "board.yaml"} <= names and all(
        e.is_file() and e.suffix.lower() in (*IMAGE_SUFFIXES, ".csv", ".yaml", ".json") for e in folder.iterdir())


def _not_inside(out: Path, **sources) -> None:
    """ImportUsageError when a source path lies in the folder the import replaces."""
    for flag, src in sources.items():
        if src is not None and Path(src).resolve().is_relative_to(out.resolve()):
            raise ImportUsageError(f"--out {out}: holds the source {flag} {src}; write the dataset elsewhere")


def _direction(args) -> tuple[str | None, str]:
    """(declared scan direction or None, where it comes from): ``--scan-direction``, else for radlocc a settings
    file's ``Laser_Direction`` beside the laser log or the camera file."""
    if args.scan_direction is not None:
        return args.scan_direction, f"--scan-direction {args.scan_direction} of lidarcam import"
    if args.format == "radlocc":
        from lidarcam.rig.importers.radlocc import laser_direction

        folders = [Path(args.src).parent] + ([Path(args.camera).parent] if args.camera else [])
        found = laser_direction(folders)
        if found is not None:
            direction, path, value = found
            return direction, f"Laser_Direction {value} in {path}"
    return None, ""


def cmd_import(args) -> int:
    from calib_core.data.io import save_observations
    from lidarcam.rig import importing

    from .outputs import not_an_input, replaceable_folder, replaced_folder, writable_file

    if args.format in DATASET_FORMATS:
        _need(args, "images", "board_grid", "square")
        out = replaceable_folder(args.out, "--out", is_dataset_folder, "a dataset folder")
        _not_inside(out, SRC=args.src, **{"--images": args.images, "--camera": args.camera})
        grid = _grid(args)
        poses = _source_poses(args)
        check_range_units(poses, args.unit if args.format == "ranges" else None)
        size = importing.image_size(poses[0].image)
        camera = importing.source_camera(args.camera, _numbers(args.intrinsics, "--intrinsics", 4),
                                         _numbers(args.dist, "--dist"), size)
        direction, why = _direction(args)
        with replaced_folder(out, "--out", is_dataset_folder, "a dataset folder") as scratch:
            importing.write_dataset_folder(scratch, poses, camera, grid, direction, why)
        if direction is not None:
            print(f"scan direction {direction} ({why}): written to {out}/lidar.yaml")
        print(f"wrote {out}/ ({len(poses)} poses: {', '.join(p.name for p in poses)}); next: lidarcam extract "
              f"{out} --outline-kind {args.outline_kind} --out obs.json")
        return 0
    writable_file(args.out, "--out", parents=True)
    not_an_input(args.out, "--out", args.src, args.points, args.poses)
    if args.format == "bouguet":
        _need(args, "points")
        obs = importing.observations_from_bouguet(args.src, args.points, args.outline_kind,
                                                  corners=not args.no_corners)
    else:
        _need(args, "poses")
        obs = importing.observations_from_segmented(args.src, args.poses, _grid(args), args.outline_kind)
    if args.scan_direction == "cw":
        obs = importing.mirror_observations(obs, "--scan-direction cw of lidarcam import")
        print("scan direction cw (--scan-direction): the scan points read mirrored (y -> -y)")
    for name, why in obs.meta.get("skipped", {}).items():
        print(f"skipped {name}: {why}")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    save_observations(obs, args.out)
    print(f"wrote {args.out} ({obs.n_boards} boards" + (", image corners and camera" if obs.has_corners else "")
          + f", outline {args.outline_kind})")
    return 0


def add_parsers(subparsers) -> None:
    """Register the ``import`` verb on an argparse subparsers object."""
    from .argtypes import finite_float

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
    p.add_argument("--start-deg", type=finite_float, help="ranges: bearing of the first beam (deg, counter-clockwise)")
    p.add_argument("--step-deg", type=finite_float, help="ranges: bearing step between beams (deg)")
    p.add_argument("--unit", default="mm", choices=tuple(UNIT_M), help="ranges: range unit (default: %(default)s)")
    p.add_argument("--suffix", default=".log", help="ranges: scan file suffix (default: %(default)s)")
    p.add_argument("--camera", help="camera file: OpenCV keys (YAML or XML), ROS camera_info YAML, Kalibr camchain "
                   "(FILE:camN for a camera other than cam0), or MATLAB text (K = [...]; kc = [...]); docs/dataset.md")
    p.add_argument("--intrinsics", metavar="FX,FY,CX,CY", help="the camera matrix instead of --camera (pixels)")
    p.add_argument("--dist", metavar="K1,K2,P1,P2[,K3]", help="distortion with --intrinsics (OpenCV order)")
    p.add_argument("--board-grid", metavar="COLSxROWS", help="inner corners of the checkerboard, e.g. 9x6")
    p.add_argument("--square", type=finite_float, metavar="M", help="side of one square (metres)")
    p.add_argument("--points", help="bouguet: segmented scan points CSV (pose,x_m,y_m; pose = image index)")
    p.add_argument("--poses", help="segmented: board poses CSV (pose, R_cam_board_00..22, t_cam_board_x/y/z_mm)")
    p.add_argument("--no-corners", action="store_true", help="bouguet: leave the detected corners out")
    p.add_argument("--outline-kind", choices=OUTLINE_KINDS, default="lower_bound",
                   help="what the pattern's outline says of the board (default: %(default)s)")
    p.add_argument("--scan-direction", choices=SCAN_DIRECTIONS, default=None,
                   help="which way the lidar counts its bearings: ccw (counter-clockwise about its z axis, up) or "
                   "cw (read mirrored); a dataset folder gets lidar.yaml; default: radlocc's Laser_Direction from a "
                   "settings file beside the laser log or camera file, else nothing declared (ccw)")
    p.set_defaults(func=cmd_import)
