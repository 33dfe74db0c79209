"""The ``lidarcam`` command line: thin verbs over the library. Bad input exits 2 with one line."""

from __future__ import annotations

import argparse
import difflib
import re
import sys

from calib_core.errors import LidarcamError

from . import bag, demo, formats, importer, plan, rig, simulate
from .argtypes import check_numbers
from .extras import add_optional, mark_missing, missing_extra
from .intrinsics_flag import STD_INTRINSICS_HELP, with_std_intrinsics
from .outputs import not_an_input, writable_file
from .wording import cli_hint


def _cmd_methods(args) -> int:
    from calib_core.registry import METHODS as table
    from calib_core.registry import accepted_options

    w = max(len(n) for n in table)
    print(f"{'method':<{w}}  min boards  origin / citation / summary / cost / options")
    for m in table.values():
        pad = f"{'':<{w}}  {'':>10}  "
        print(f"{m.name:<{w}}  {m.min_boards:>10}  from {m.origin}: {m.citation}\n{pad}{m.summary}")
        if m.cost:
            print(f"{pad}cost: {m.cost}")
        accepted = accepted_options(m)
        names = "any keyword" if accepted is None else ", ".join(sorted(accepted)) or "none"
        print(f"{pad}options: {names}{'; a mounting prior (--prior)' if m.takes_prior else ''}")
    return 0


def _frames(args):
    """The ROS export asked for on the command line, or None (one frame name alone is an error)."""
    from calib_core.errors import CalibrationError

    if args.parent_frame is None and args.child_frame is None:
        return None
    if args.parent_frame is None or args.child_frame is None:
        raise CalibrationError("--parent-frame and --child-frame go together")
    return args.parent_frame, args.child_frame, args.parent_sensor


def _print_ros(ros) -> None:
    print(f"ROS: {ros.parent} -> {ros.child} is {ros.source}: it maps {ros.child} points into the {ros.parent} "
          "frame (static_transform_publisher arguments: x y z qx qy qz qw parent child, metres)")
    print(f"  ROS 1: {ros.ros1}")
    print(f"  ROS 2: {ros.ros2}")
    print("  URDF:  " + ros.urdf_joint().replace("\n", "\n         "))


def _sigmas(std) -> str:
    """``fx 1.2, fy 1.2, cx 2, cy 2 px[, dist 0.01, ...]`` of a std_intrinsics vector."""
    px = ", ".join(f"{n} {v:.3g}" for n, v in zip(("fx", "fy", "cx", "cy"), std[:4], strict=False)) + " px"
    return px + (", dist " + ", ".join(f"{v:.3g}" for v in std[4:]) if len(std) > 4 else "")


def _cmd_calibrate(args) -> int:
    from calib_core import calibrate, get_method
    from calib_core.data.exports import frame_export
    from calib_core.data.io import load_observations

    frames = _frames(args)
    for flag, path in (("--out", args.out), ("--yaml", args.yaml)):
        writable_file(path, flag)
        not_an_input(path, flag, args.observations)
    obs = load_observations(args.observations)
    if args.std_intrinsics:
        stated = None if obs.camera is None else obs.camera.std_intrinsics
        obs = with_std_intrinsics(obs, args.std_intrinsics)
        if stated is not None:
            print(f"intrinsics' 1-sigma: --std-intrinsics {args.std_intrinsics} used "
                  f"({_sigmas(obs.camera.std_intrinsics)}), not the file's camera.std_intrinsics ({_sigmas(stated)})")
    options = {"fixed": parse_fix(args.fix)} if args.fix else {}
    if args.prior or args.prior_sigma:
        options["prior"] = parse_prior(args.prior, args.prior_sigma)
    res = calibrate(obs, method=get_method(args.method).name, **options)
    print(cli_hint("\n".join(res.summary_lines(obs.n_boards, obs.T_lidar_cam_true))))
    ros = frame_export(res.T_lidar_cam, *frames) if res.ok and frames else None
    if ros is not None:
        _print_ros(ros)
    if args.out:
        res.save(args.out)
        print(f"wrote {args.out}")
    if args.yaml:
        if not res.ok:
            print(f"no YAML written: {args.method} failed", file=sys.stderr)
        else:
            with open(args.yaml, "w") as f:
                f.write(res.to_yaml(ros))
            print(f"wrote {args.yaml}")
    return 0 if res.ok else 1


FIX_HELP = ("hold mounting parameters at given values and calibrate the rest, e.g. z=11cm,roll=0,pitch=0 "
            "(the camera's pose in the lidar frame: roll, pitch, yaw in degrees, Z-Y-X, of the camera body "
            "frame x forward y left z up; x, y, z (z also 'height') in metres, the camera centre; a value may carry "
            "its unit: deg, rad, m, cm, mm); for lidarcam and X+ml / X+plane")


def parse_fix(text: str, flag: str = "--fix") -> dict:
    """``"z=11cm,roll=0"`` -> ``{"z_m": 0.11, "roll_deg": 0.0}`` (``calib_core.geometry.mounting.parse_text``:
    degrees and metres unless a value carries its unit); CalibrationError naming ``flag`` and a bad item."""
    from calib_core.geometry.mounting import parse_text

    return parse_text(text, flag)


def parse_prior(pose: str | None, sigma: str | None):
    """``--prior x=0.1,...,yaw=90`` (all six, as ``--fix`` reads them) and ``--prior-sigma 50mm,10deg`` (one
    translation and one rotation sigma, each with its unit: m, cm, mm, deg, rad) -> ``MountingPrior``;
    CalibrationError naming what is missing or bad."""
    import math

    from calib_core.errors import CalibrationError
    from calib_core.geometry.mounting import PRIOR_SIGMA_RANGE, MountingPrior, parse_quantity

    if not pose or not sigma:
        raise CalibrationError("--prior and --prior-sigma go together (e.g. --prior x=0.1,y=0,z=0.05,roll=0,"
                               "pitch=0,yaw=90 --prior-sigma 50mm,10deg)")
    sig: dict = {}
    for item in filter(None, (p.strip() for p in sigma.split(","))):
        kind, value = parse_quantity(item, "--prior-sigma")
        if kind is None:
            raise CalibrationError(f"--prior-sigma: bad item {item!r}: no unit; expected e.g. 50mm,10deg")
        which = ("rotation", "translation")[kind]
        if which in sig:
            raise CalibrationError(f"--prior-sigma: two {which} sigmas")
        lo, hi = PRIOR_SIGMA_RANGE[("sigma_rot_rad", "sigma_trans_m")[kind]]
        lo, hi, unit = (math.degrees(lo), math.degrees(hi), "deg") if kind == 0 else (lo * 1000, hi * 1000, "mm")
        shown = value if kind == 0 else value * 1000
        if not lo <= shown <= hi:
            raise CalibrationError(f"--prior-sigma: the {which} 1-sigma {shown:g} {unit} is outside [{lo:.3g}, "
                                   f"{hi:.3g}] {unit} (tighter: --fix the value; looser: leave the prior out)")
        sig[which] = value
    if set(sig) != {"translation", "rotation"}:
        raise CalibrationError("--prior-sigma: one translation and one rotation sigma are needed, e.g. 50mm,10deg")
    return MountingPrior.from_params(parse_fix(pose, "--prior"), sig["rotation"], sig["translation"])


def _plugin_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--plugin", action="append", default=[], metavar="MODULE",
                   help="import this module first: its methods join the registry (repeatable; installed "
                   "'lidarcam.methods' entry points are always loaded)")


def load_plugins(argv) -> None:
    """Load the installed method plugins and those named by ``--plugin`` in ``argv`` (PluginError: one line)."""
    from calib_core.plugins import load_plugins as load

    pre = argparse.ArgumentParser(add_help=False)
    _plugin_option(pre)
    load(pre.parse_known_args(argv)[0].plugin)


EXIT_CODES = ("exit status: 0 an answer (or the verb's output), 1 no answer (the method could not solve, or no pose "
              "passed), 2 bad input (file, option, method name), 130 interrupted (Ctrl-C)")


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors: a mistyped verb or choice gets the closest name ("did you mean ...")."""

    def error(self, message: str):
        m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if m:
            names = [c.strip(" '") for c in m.group(2).split(",")]
            close = difflib.get_close_matches(m.group(1), names, n=1)
            message = (f"unknown {'verb' if message.startswith('argument VERB') else 'choice'} {m.group(1)!r}"
                       + (f"; did you mean {close[0]!r}?" if close else f"; one of {', '.join(names)}"))
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="lidarcam", description="2D lidar - camera extrinsic calibration", epilog=EXIT_CODES)
    _plugin_option(p)
    sub = p.add_subparsers(dest="verb", required=True, metavar="VERB")
    sp = sub.add_parser("methods", help="list the calibration methods")
    sp.set_defaults(func=_cmd_methods)
    formats.add_parsers(sub)
    sp = sub.add_parser("calibrate", help="calibrate from an observation JSON file", epilog=EXIT_CODES)
    sp.add_argument("observations", help="lidarcam.observations/1 JSON file")
    sp.add_argument("--method", default="lidarcam", help="any name of `lidarcam methods`, X+ml, X+plane, X+joint, "
                    "a plugin's method (default: %(default)s)")
    sp.add_argument("--out", help="write the result JSON (lidarcam.result/1) here")
    sp.add_argument("--yaml", help="write the extrinsic as YAML here")
    sp.add_argument("--fix", metavar="NAME=VALUE,...", help=FIX_HELP)
    sp.add_argument("--prior", metavar="NAME=VALUE,...", help="a rough guess of the mounting (CAD, a tape measure), "
                    "all six as --fix reads them, e.g. x=0.1,y=0,z=0.05,roll=0,pitch=0,yaw=90; it decides between "
                    "answers the boards leave tied and enters the covariance (lidarcam only)")
    sp.add_argument("--prior-sigma", metavar="TRANS,ROT", help="the prior's 1-sigma, each with its unit, e.g. "
                    "50mm,10deg (the same along every axis)")
    sp.add_argument("--std-intrinsics", metavar="FX,FY,CX,CY[,K1..]|F%,Cpx", help=STD_INTRINSICS_HELP)
    sp.add_argument("--parent-frame", help="ROS frame name of the parent sensor (the lidar unless --parent-sensor "
                    "camera): prints static_transform_publisher lines and a URDF joint, adds them to the YAML")
    sp.add_argument("--child-frame", help="ROS frame name of the other sensor (the camera by default)")
    sp.add_argument("--parent-sensor", choices=("lidar", "camera"), default="lidar",
                    help="which sensor --parent-frame names (default: %(default)s, publishing T_lidar_cam)")
    sp.set_defaults(func=_cmd_calibrate)
    add_optional(sub, "simulate", simulate.add_parsers, simulate.SUMMARY)
    rig.add_parsers(sub)
    importer.add_parsers(sub)
    bag.add_parsers(sub)
    demo.add_parsers(sub)
    plan.add_parsers(sub)
    mark_missing(sub)
    check_numbers(p)
    return p


def _value_options(parser: argparse.ArgumentParser) -> set[str]:
    """The option strings of ``parser`` and its verbs that take one value."""
    out, todo = set(), [parser]
    while todo:
        p = todo.pop()
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                todo.extend(a.choices.values())
            elif a.option_strings and a.nargs is None and isinstance(a, argparse._StoreAction):
                out.update(a.option_strings)
    return out


def joined_negative_values(argv: list[str], options: set[str]) -> list[str]:
    """``--prior-sigma -50mm,10deg`` as ``--prior-sigma=-50mm,10deg``: argparse reads a value that starts with
    '-' and is not a plain number as an option; the value's own check then says what is wrong with it."""
    out, i = [], 0
    while i < len(argv):
        a = argv[i]
        if a in options and i + 1 < len(argv) and re.match(r"-\.?\d", argv[i + 1]):
            out.append(f"{a}={argv[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        load_plugins(argv)
    except LidarcamError as err:
        print(f"lidarcam: error: {err}", file=sys.stderr)
        return 2
    parser = build_parser()
    args = parser.parse_args(joined_negative_values(argv, _value_options(parser)))
    try:
        return args.func(args)
    except LidarcamError as err:
        print(f"lidarcam {args.verb}: error: {err}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as err:  # a verb of an extra that is not installed: one line naming it
        error = missing_extra(err)
        if error is None:
            raise
        print(f"lidarcam {args.verb}: error: {error}", file=sys.stderr)
        return 2
    except OSError as err:  # a write the checks before the work could not foresee (disk full, a race)
        where = f"{err.filename}: " if err.filename else ""
        print(f"lidarcam {args.verb}: error: {where}{err.strerror or err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"lidarcam {args.verb}: interrupted; nothing half-written is kept, run the same command again",
              file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
