"""``lidarcam plan RIG.yaml`` / ``lidarcam plan --from OBS.json``: which board poses to take next, how many, and
what they will give (``calib_core.planning.capture``); a table, an operator's checklist, a figure and ``--json``.

Bad input raises a LidarcamError, which ``lidarcam.cli.main`` prints as one line and exits 2.
"""

from __future__ import annotations

import re

TARGET_RE = re.compile(r"^\s*([0-9.eE+-]+)\s*deg\s*,\s*([0-9.eE+-]+)\s*mm\s*$")


def parse_target(text: str) -> tuple[float, float]:
    """``"0.1deg,5mm"`` -> (0.1, 5.0); CalibrationError on anything else."""
    from calib_core.errors import CalibrationError

    m = TARGET_RE.match(text)
    try:
        out = (float(m.group(1)), float(m.group(2))) if m else None
    except ValueError:
        out = None
    if out is None or min(out) <= 0:
        raise CalibrationError(f"--target: expected e.g. 0.1deg,5mm (positive numbers), got {text!r}")
    return out


def _current(args, k: int, target, criterion):
    """(rig, current observations or None, plan) of the command line."""
    import numpy as np

    from calib_core import calibrate
    from calib_core.data.io import load_observations
    from calib_core.errors import CalibrationError
    from calib_core.planning.capture import plan_capture
    from calib_core.planning.observed import plan_from_observations

    base = None
    if args.rig:
        from lidarcam.rig.plan_rig import load_plan_rig  # YAML: lidarcam[rig]

        base = load_plan_rig(args.rig)
    if not args.from_obs:
        if base is None:
            raise CalibrationError("give a rig description (RIG.yaml) or --from OBS.json")
        return base, None, plan_capture(base, k, target=target, criterion=criterion)
    obs = load_observations(args.from_obs)
    res = calibrate(obs, method=args.method)
    if not res.ok:
        if base is None:
            raise CalibrationError(f"{args.from_obs}: {args.method} cannot calibrate these boards ({res.reason}); "
                                   "give a rig description with a rough mounting")
        print(f"note: {args.method} failed ({res.reason}); planning at the rig description's mounting")
    T = res.T_lidar_cam if res.ok else base.T_lidar_cam
    try:
        p = plan_from_observations(obs, np.asarray(T, float), k, info=res.info, base=base, target=target,
                                   criterion=criterion)
    except ValueError as err:
        raise CalibrationError(f"{args.from_obs}: {err}") from None
    return p.rig, obs, p.plan


def cmd_plan(args) -> int:
    """``lidarcam plan``: prints the plan; ``--json`` and ``--figure`` write it."""
    import json
    from pathlib import Path

    from calib_core.errors import CalibrationError
    from calib_core.planning.capture import plan_to_dict

    from .outputs import writable_file

    if args.next < 1:
        raise CalibrationError(f"--next must be at least 1, got {args.next}")
    writable_file(args.json, "--json")
    writable_file(args.figure, "--figure")
    criterion = "z" if args.criterion == "height" else args.criterion
    rig, obs, plan = _current(args, args.next, parse_target(args.target), criterion)
    print("\n".join(plan.summary_lines(rig)))
    if args.json:
        Path(args.json).write_text(json.dumps(plan_to_dict(plan), indent=1) + "\n")
        print(f"wrote {args.json}")
    if args.figure:
        from lidarcam.rig.plan_figure import save_plan_figure

        print(f"wrote {save_plan_figure(args.figure, rig, plan, obs)}")
    return 0


def add_parsers(subparsers) -> None:
    """Register the ``plan`` verb on an argparse subparsers object."""
    from calib_core.planning.capture import CRITERIA, DEFAULT_TARGET

    p = subparsers.add_parser("plan", help="which board poses to capture next, and what they will give",
                              description="Predict the 1-sigma of each mounting axis from the joint Cramer-Rao "
                              "bound, name what is undetermined, and propose the next board poses. Rig description: "
                              "docs/planning.md.")
    p.add_argument("rig", nargs="?", help="rig description YAML (camera, lidar, mounting, board, workspace)")
    p.add_argument("--from", dest="from_obs", metavar="OBS.json",
                   help="observations captured so far (from extract or bag); their calibration gives the mounting")
    p.add_argument("--next", type=int, default=6, metavar="K", help="board poses to propose (default: %(default)s)")
    p.add_argument("--target", default="{:g}deg,{:g}mm".format(*DEFAULT_TARGET),
                   help="1-sigma target, rotation and translation (default: %(default)s)")
    p.add_argument("--criterion", default="D", choices=list(CRITERIA) + ["height"],
                   help="D-optimal (default), rot / trans (their traces) or one axis (roll ... z; height = z)")
    p.add_argument("--method", default="lidarcam", help="calibration of --from (default: %(default)s)")
    p.add_argument("--json", metavar="OUT", help="write the plan as JSON here")
    p.add_argument("--figure", metavar="OUT.png", help="write the top view and sigma-vs-boards figure here")
    p.set_defaults(func=cmd_plan)
