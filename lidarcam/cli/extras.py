"""The optional parts of the installation: ``pip install lidarcam`` is the library (numpy, scipy) and the verbs
that need nothing more (``methods``, ``calibrate``, ``plan`` with ``--from``); the real-rig verbs and the simulator
need ``lidarcam[rig]``. A verb that reaches a missing package is one line naming the extra, exit 2."""

from __future__ import annotations

import argparse

from calib_core.errors import LidarcamError

EXTRA_OF = {"cv2": "rig", "yaml": "rig", "rosbags": "rig", "matplotlib": "rig", "PIL": "rig"}
"""Top-level module -> the extra of pyproject.toml that installs it."""

VERB_NEEDS = {"simulate": ("cv2",), "extract": ("cv2", "yaml"), "report": ("cv2", "yaml", "matplotlib"),
              "import": ("cv2", "yaml"), "bag": ("rosbags", "cv2", "yaml"), "demo": ("cv2", "yaml", "rosbags"),
              "plan": ("yaml", "matplotlib"), "formats": ("yaml",)}
"""The modules each verb reaches (``plan`` with ``--from`` alone and no ``--figure`` needs neither)."""
PARTLY = {"plan": " for a rig file or --figure; --from OBS.json alone runs without"}
"""Verbs that run in part without their extra: what needs it."""


def _installed(module: str) -> bool:
    import importlib.util

    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def missing_extras(verb: str) -> list[str]:
    """The extras whose modules ``verb`` needs and this installation lacks (``VERB_NEEDS``)."""
    return sorted({EXTRA_OF[m] for m in VERB_NEEDS.get(verb, ()) if not _installed(m)})


def mark_missing(subparsers) -> None:
    """Name, in the verb list of ``--help``, the extra each verb needs where it is not installed."""
    for action in subparsers._choices_actions:
        extras = missing_extras(action.dest)
        if extras:
            names = ",".join(extras)
            action.help = (f"[needs lidarcam[{names}]{PARTLY.get(action.dest, '')}: pip install "
                           f"'lidarcam[{names}]'] {action.help}")


class MissingExtra(LidarcamError):
    """A verb needs a package of an optional extra that is not installed."""


def missing_extra(err: ModuleNotFoundError) -> MissingExtra | None:
    """The one-line error for ``err`` when its module belongs to an extra (None: a genuine bug, re-raise)."""
    top = (err.name or "").split(".")[0]
    extra = EXTRA_OF.get(top)
    if extra is None:
        return None
    return MissingExtra(f"needs the optional package {top!r}, not installed: pip install 'lidarcam[{extra}]'")


def add_optional(subparsers, name: str, add_parsers, summary: str) -> None:
    """``add_parsers(subparsers)``, or, where its imports need a missing extra, a stand-in verb ``name`` that
    accepts any arguments and fails with the one line of ``missing_extra`` (``summary``: its line in ``--help``)."""
    try:
        add_parsers(subparsers)
    except ModuleNotFoundError as err:
        error = missing_extra(err)
        if error is None:
            raise

        def fail(args, error=error) -> int:
            raise error

        p = subparsers.add_parser(name, help=summary, add_help=False, prefix_chars="\0")
        p.add_argument("rest", nargs=argparse.REMAINDER)
        p.set_defaults(func=fail)
