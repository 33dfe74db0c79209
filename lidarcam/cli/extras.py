"""The optional parts of the installation: ``pip install lidarcam`` is the library (numpy, scipy) and the verbs
that need nothing more (``methods``, ``calibrate``, ``plan`` with ``--from``); the real-rig verbs and the simulator
need ``lidarcam[rig]``. A verb that reaches a missing package is one line naming the extra, exit 2."""

from __future__ import annotations

import argparse

from calib_core.errors import LidarcamError

EXTRA_OF = {"cv2": "rig", "yaml": "rig", "rosbags": "rig", "matplotlib": "rig", "PIL": "rig"}
"""Top-level module -> the extra of pyproject.toml that installs it."""


class MissingExtra(LidarcamError):
    """A verb needs a package of an optional extra that is not installed."""


def missing_extra(err: ModuleNotFoundError) -> MissingExtra | None:
    """The one-line error for ``err`` when its module belongs to an extra (None: a genuine bug, re-raise)."""
    top = (err.name or "").split(".")[0]
    extra = EXTRA_OF.get(top)
    if extra is None:
        return None
    return MissingExtra(f"needs the optional package {top!r}, not installed: pip install 'lidarcam[{extra}]'")


def add_optional(subparsers, name: str, add_parsers) -> None:
    """``add_parsers(subparsers)``, or, where its imports need a missing extra, a stand-in verb ``name`` that
    accepts any arguments and fails with the one line of ``missing_extra``."""
    try:
        add_parsers(subparsers)
    except ModuleNotFoundError as err:
        error = missing_extra(err)
        if error is None:
            raise

        def fail(args, error=error) -> int:
            raise error

        p = subparsers.add_parser(name, help=f"(not installed: {error})", add_help=False, prefix_chars="\0")
        p.add_argument("rest", nargs=argparse.REMAINDER)
        p.set_defaults(func=fail)
