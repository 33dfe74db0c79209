"""The library's hints in the command line's words: ``calibrate(..., fixed={'z_m': ...})`` is ``--fix z=...``."""

from __future__ import annotations

import re

from calib_core.geometry.mounting import PARAMS, UNIT_NAMES

FIXED_HINT_RE = re.compile(r"fixed=\{((?:'[a-z_]+': \.\.\.(?:, )?)+)\}")
"""The hint of ``calib_core.checks.degeneracy`` (``fixed={'roll_deg': ..., 'z_m': ...}``)."""


def _as_fix(match: re.Match) -> str:
    keys = re.findall(r"'([a-z_]+)'", match.group(1))
    names = [PARAMS[UNIT_NAMES.index(k)] if k in UNIT_NAMES else k for k in keys]
    return "--fix " + ",".join(f"{n}=VALUE" for n in names) + " (degrees, metres)"


def cli_hint(text: str) -> str:
    """``text`` with each library ``fixed={...}`` hint rewritten as the ``--fix`` option of ``lidarcam calibrate``."""
    return FIXED_HINT_RE.sub(_as_fix, str(text))
