"""The ``lidarcam`` command line: thin verbs over the library. Bad input exits 2 with one line."""

from __future__ import annotations

import argparse
import sys

from calib_core.errors import LidarcamError

from . import bag, rig, simulate


def _cmd_methods(args) -> int:
    from calib_core.registry import METHODS as table

    w = max(len(n) for n in table)
    print(f"{'method':<{w}}  min boards  citation / summary")
    for m in table.values():
        print(f"{m.name:<{w}}  {m.min_boards:>10}  {m.citation}\n{'':<{w}}  {'':>10}  {m.summary}")
        if m.cost:
            print(f"{'':<{w}}  {'':>10}  cost: {m.cost}")
    return 0


def _cmd_calibrate(args) -> int:
    from calib_core import calibrate
    from calib_core.io import extrinsic_yaml, load_observations
    from calib_core.metrics import pose_errors

    obs = load_observations(args.observations)
    res = calibrate(obs, method=args.method)
    if not res.ok:
        print(f"{args.method}: failed: {res.reason}")
    else:
        print(f"{args.method}: ok, {res.n_candidates} candidates, {1000 * res.seconds:.1f} ms")
        print("T_lidar_cam (maps camera points into the lidar frame, metres):")
        for row in res.T_lidar_cam:
            print("  " + "  ".join(f"{v: .6f}" for v in row))
        if res.covariance is not None:
            model = res.info.get("covariance_model")
            print(f"1-sigma: rotation {res.sigma_rot_deg:.3f} deg, translation {res.sigma_trans_mm:.1f} mm"
                  + (f" (covariance model: {model})" if model else ""))
        if "conditioning" in res.info:
            print(f"conditioning (inverse condition number, 1 = ideal, < 1e-3 poor): {res.info['conditioning']:.2e}")
        if res.boards_used is not None:
            print(f"boards used ({len(res.boards_used)} of {obs.n_boards}): "
                  + ", ".join(map(str, res.boards_used)))
            for r in res.boards_rejected:
                stat = "" if r.get("statistic") is None else f" (statistic {r['statistic']:.3g})"
                print(f"board {r['index']} rejected{stat}: {r['reason']}")
        for w in res.warnings:
            if not (res.boards_rejected and w.startswith("board ") and " left out: " in w):
                print(f"warning: {w}")
        if obs.T_lidar_cam_true is not None:
            e_R, e_t = pose_errors(res.T_lidar_cam, obs.T_lidar_cam_true)
            print(f"against ground truth: e_R = {float(e_R):.4f} deg, e_t = {1000 * float(e_t):.1f} mm")
    if args.out:
        res.save(args.out)
        print(f"wrote {args.out}")
    if args.yaml:
        if not res.ok:
            print(f"no YAML written: {args.method} failed", file=sys.stderr)
        else:
            extra = {"method": res.method}
            if res.covariance is not None:
                extra.update(sigma_rot_deg=res.sigma_rot_deg, sigma_trans_mm=res.sigma_trans_mm)
                if "covariance_model" in res.info:
                    extra["covariance_model"] = f"'{res.info['covariance_model']}'"
            if "conditioning" in res.info:
                extra["conditioning"] = float(res.info["conditioning"])
            with open(args.yaml, "w") as f:
                f.write(extrinsic_yaml(res.T_lidar_cam, extra, covariance=res.covariance))
            print(f"wrote {args.yaml}")
    return 0 if res.ok else 1


def build_parser() -> argparse.ArgumentParser:
    from calib_core.registry import METHODS

    p = argparse.ArgumentParser(prog="lidarcam", description="2D lidar - camera extrinsic calibration")
    sub = p.add_subparsers(dest="verb", required=True, metavar="VERB")
    sp = sub.add_parser("methods", help="list the calibration methods")
    sp.set_defaults(func=_cmd_methods)
    sp = sub.add_parser("calibrate", help="calibrate from an observation JSON file")
    sp.add_argument("observations", help="lidarcam.observations/1 JSON file")
    sp.add_argument("--method", default="lidarcam", choices=list(METHODS), help="method (default: %(default)s)")
    sp.add_argument("--out", help="write the result JSON (lidarcam.result/1) here")
    sp.add_argument("--yaml", help="write the extrinsic as YAML here")
    sp.set_defaults(func=_cmd_calibrate)
    simulate.add_parsers(sub)
    rig.add_parsers(sub)
    bag.add_parsers(sub)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except LidarcamError as err:
        print(f"lidarcam {args.verb}: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
