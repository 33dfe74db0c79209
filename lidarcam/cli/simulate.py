"""The ``lidarcam simulate`` verb: write one simulated problem as a ``lidarcam.observations/1`` file."""

from __future__ import annotations

import argparse
import sys
from dataclasses import MISSING, fields

# Short spellings kept next to the generated one-flag-per-field names.
ALIASES = {"n_boards": ["--boards"]}


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def add_parsers(subparsers) -> argparse.ArgumentParser:
    """Register ``simulate`` on an argparse ``subparsers``; one flag per SimOptions field, plus
    ``--seed``, ``--trial`` and ``--out``. Sets ``func`` to ``run``."""
    from simulate.options import SimOptions  # the simulator needs lidarcam[rig] (OpenCV)

    p = subparsers.add_parser(
        "simulate", help="write one simulated lidar-camera calibration problem (observations JSON)",
        description="Simulate boards seen by a 2D lidar and a camera (docs/METHOD.md) and write them "
                    "with their ground truth as a lidarcam.observations/1 file.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--seed", type=int, default=0, help="base seed")
    p.add_argument("--trial", type=int, default=0, help="trial index (each trial has its own random stream)")
    p.add_argument("--out", required=True, help="output JSON path")
    g = p.add_argument_group("simulation options (SimOptions)")
    for f in fields(SimOptions):
        default = f.default if f.default is not MISSING else None
        names = [_flag(f.name)] + ALIASES.get(f.name, [])
        if f.type == "bool":
            g.add_argument(*names, dest=f.name, action=argparse.BooleanOptionalAction, default=default)
        else:
            kind = {"int": int, "float": float, "str": str}[f.type]
            g.add_argument(*names, dest=f.name, type=kind, default=default, metavar=f.type.upper())
    p.set_defaults(func=run)
    return p


def run(args: argparse.Namespace) -> int:
    """Generate and save; errors in the options or the sampling go to stderr with exit status 2."""
    from calib_core.data.io import save_observations
    from simulate import generate
    from simulate.options import SimOptions
    from simulate.scene import SceneError

    from .outputs import writable_file

    writable_file(args.out, "--out")
    try:
        options = SimOptions(**{f.name: getattr(args, f.name) for f in fields(SimOptions)})
        obs = generate(options, seed=args.seed, trial=args.trial)
    except (ValueError, SceneError) as exc:
        print(f"lidarcam simulate: {exc}", file=sys.stderr)
        return 2
    save_observations(obs, args.out)
    print(f"wrote {args.out}: {obs.n_boards} boards, {sum(len(b.scan) for b in obs.boards)} scan points")
    return 0
