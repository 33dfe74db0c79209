"""``lidarcam plan RIG.yaml`` / ``lidarcam plan --from OBS.json``: which board poses to take next, how many, and
what they will give (``calib_core.planning.capture``); a table, an operator's checklist, a figure and ``--json``.

Bad input raises a LidarcamError, which ``lidarcam_cli.main`` prints as one line and exits 2.
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


def _current(args):
    """(rig, current observations or None, per-board information or None) of the command line."""
    import numpy as np

    from calib_core import calibrate
    from calib_core.data.io import load_observations
    from calib_core.data.lines import scan_noise_estimate
    from calib_core.errors import CalibrationError
    from calib_core.planning.capture import set_informations
    from calib_core.planning.views import rig_from_observations

    base = None
    if args.rig:
        from rig.plan_rig import load_plan_rig  # YAML: lidarcam[rig]

        base = load_plan_rig(args.rig)
    if not args.from_obs:
        if base is None:
            raise CalibrationError("give a rig description (RIG.yaml) or --from OBS.json")
        return base, None, None
    obs = load_observations(args.from_obs)
    res = calibrate(obs, method=args.method)
    if not res.ok:
        if base is None:
            raise CalibrationError(f"{args.from_obs}: {args.method} cannot calibrate these boards ({res.reason}); "
                                   "give a rig description with a rough mounting")
        print(f"note: {args.method} failed ({res.reason}); planning at the rig description's mounting")
        T = base.T_lidar_cam
    else:
        T = res.T_lidar_cam
    sr = float(res.info.get("range_sigma_m") or scan_noise_estimate(obs))
    sc = float(res.info.get("corner_sigma_px") or (base.corner_sigma_px if base else 0.5)) if obs.has_corners \
        else 0.0
    try:
        rig = rig_from_observations(obs, np.asarray(T, float), sr, sc, base)
    except ValueError as err:
        raise CalibrationError(f"{args.from_obs}: {err}") from None
    return rig, obs, set_informations(obs, rig.T_lidar_cam, sr, sc)


def _fmt(v, unit: str) -> str:
    return "   undet." if v is None else f"{v:8.3f}" if unit == "deg" else f"{v:8.1f}"


def print_plan(rig, plan) -> None:
    """The plan as text: the current prediction, the table of proposed poses, the operator's checklist."""
    import numpy as np

    from calib_core.planning.capture import SIGMA_NAMES, describe_pose, verdict
    from calib_core.planning.views import feasibility

    cur = plan.current
    print(f"current: {plan.current_n} boards; range noise {1000 * rig.range_sigma_m:.1f} mm, corner noise "
          f"{rig.corner_sigma_px:.2g} px")
    print("  1-sigma: rotation " + ("undetermined" if not np.isfinite(cur.rot_sigma_deg) else
                                   f"{cur.rot_sigma_deg:.3f} deg") + ", translation "
          + ("undetermined" if not np.isfinite(cur.trans_sigma_mm) else f"{cur.trans_sigma_mm:.1f} mm"))
    print("  per axis (rotations about the lidar axes; translation of T_lidar_cam): "
          + ", ".join(f"{k} {'undet.' if v is None else f'{v:.3g}'}" for k, v in cur.sigma_dict().items()))
    print(f"  {plan.message}")
    print(f"\nnext {len(plan.poses)} boards ({plan.criterion}-optimal), predicted 1-sigma after each:")
    head = " #  dist_m  bear_deg  height_m  turn_deg  lean_deg  roll_deg |  rot_deg  trans_mm |" + "".join(
        f" {k:>9}" for k in SIGMA_NAMES)
    print(head)
    for i, (q, p) in enumerate(zip(plan.poses, plan.after, strict=True)):
        sd = p.sigma_dict()
        rot = None if not np.isfinite(p.rot_sigma_deg) else p.rot_sigma_deg
        tr = None if not np.isfinite(p.trans_sigma_mm) else p.trans_sigma_mm
        print(f"{i + 1:2d}  {q[0]:6.2f}  {q[1]:8.1f}  {q[2]:8.2f}  {q[3]:8.1f}  {q[4]:8.1f}  {q[5]:8.1f} |"
              f" {_fmt(rot, 'deg')}  {_fmt(tr, 'mm')} |"
              + "".join(f" {_fmt(sd[k], 'deg' if k.endswith('deg') else 'mm'):>9}" for k in SIGMA_NAMES))
    if plan.plan_undetermined:
        print(f"after these boards: {plan.plan_message}")
    print("to reach the target " + f"({plan.target[0]:g} deg, {plan.target[1]:g} mm): "
          + (f"{plan.to_target} boards in all" if plan.to_target is not None else
             "not within the planner's limit of boards; lower the noise or widen the workspace"))
    _, ranges, _ = feasibility(rig, plan.T_lidar_board)
    print("\nchecklist at the rig:")
    for i, (q, r) in enumerate(zip(plan.poses, ranges, strict=True)):
        print(f"  [ ] {i + 1}. board {describe_pose(q)}; check: the whole board in the image with "
              f"{rig.image_margin_px:g} px to spare, the scan line across it (about {int(np.isfinite(r).sum())} "
              "points)")
    print(f"\nverdict: {verdict(plan)}")


def cmd_plan(args) -> int:
    """``lidarcam plan``: prints the plan; ``--json`` and ``--figure`` write it."""
    import json
    from pathlib import Path

    from calib_core.errors import CalibrationError
    from calib_core.planning.capture import plan_capture, plan_to_dict

    from .outputs import writable_file

    if args.next < 1:
        raise CalibrationError(f"--next must be at least 1, got {args.next}")
    writable_file(args.json, "--json")
    writable_file(args.figure, "--figure")
    rig, obs, info = _current(args)
    criterion = "z" if args.criterion == "height" else args.criterion
    plan = plan_capture(rig, args.next, current=obs, current_info=info, target=parse_target(args.target),
                        criterion=criterion)
    print_plan(rig, plan)
    if args.json:
        Path(args.json).write_text(json.dumps(plan_to_dict(plan), indent=1) + "\n")
        print(f"wrote {args.json}")
    if args.figure:
        from rig.plan_figure import save_plan_figure

        print(f"wrote {save_plan_figure(args.figure, rig, plan, obs)}")
    return 0


def add_parsers(subparsers) -> None:
    """Register the ``plan`` verb on an argparse subparsers object."""
    from calib_core.planning.capture import CRITERIA

    p = subparsers.add_parser("plan", help="which board poses to capture next, and what they will give",
                              description="Predict the 1-sigma of each mounting axis from the joint Cramer-Rao "
                              "bound, name what is undetermined, and propose the next board poses. Rig description: "
                              "docs/planning.md.")
    p.add_argument("rig", nargs="?", help="rig description YAML (camera, lidar, mounting, board, workspace)")
    p.add_argument("--from", dest="from_obs", metavar="OBS.json",
                   help="observations captured so far (from extract or bag); their calibration gives the mounting")
    p.add_argument("--next", type=int, default=6, metavar="K", help="board poses to propose (default: %(default)s)")
    p.add_argument("--target", default="0.1deg,5mm", help="1-sigma target, rotation and translation "
                   "(default: %(default)s)")
    p.add_argument("--criterion", default="D", choices=list(CRITERIA) + ["height"],
                   help="D-optimal (default), rot / trans (their traces) or one axis (roll ... z; height = z)")
    p.add_argument("--method", default="lidarcam", help="calibration of --from (default: %(default)s)")
    p.add_argument("--json", metavar="OUT", help="write the plan as JSON here")
    p.add_argument("--figure", metavar="OUT.png", help="write the top view and sigma-vs-boards figure here")
    p.set_defaults(func=cmd_plan)
