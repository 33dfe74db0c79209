"""How a path is written into a committed file: never as the absolute path of the machine that wrote it."""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
"""The repository's root."""


def repo_relative(path) -> str:
    """``path`` as a committed file shows it: relative to the repository inside it or beside it (``results/x``,
    ``../shared/real-data``), else its last name only (a scratch folder such as ``/tmp/rec120`` -> ``rec120``)."""
    p = Path(path).resolve()
    for base, prefix in ((ROOT, ""), (ROOT.parent, "..")):
        try:
            rel = p.relative_to(base)
        except ValueError:
            continue
        return os.path.join(prefix, str(rel)) if prefix else (str(rel) or ".")
    return p.name
