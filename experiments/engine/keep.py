"""Committed outputs that a rerun rewrites only when something other than a timing changed: wall times differ
between any two runs, so a report whose only differences are its timing cells, timing sentences or timing keys
is kept as it is (``make bench`` and ``make real-data`` on unchanged code leave ``git status`` clean)."""

from __future__ import annotations

import json
import re
from collections.abc import Iterable
from pathlib import Path

MASK = "~"


def _cells(line: str) -> list[str]:
    return line.strip().strip("|").split("|")


def mask_timings(text: str, columns: Iterable[str] = (), patterns: Iterable[str] = ()) -> str:
    """``text`` with the cells of the Markdown table columns headed ``columns`` and the matches of the regular
    expressions ``patterns`` replaced by one mark."""
    columns = {c.strip() for c in columns}
    lines = text.splitlines()
    masked: list[int] = []
    for i, line in enumerate(lines):
        is_row = line.lstrip().startswith("|")
        if not is_row:
            masked = []
            continue
        nxt = lines[i + 1] if i + 1 < len(lines) else ""
        if not masked and re.fullmatch(r"\s*\|(\s*:?-+:?\s*\|)+\s*", nxt):
            masked = [k for k, c in enumerate(_cells(line)) if c.strip() in columns] or [-1]
            continue
        cells = _cells(line)
        if set("".join(cells).strip()) <= set("-: "):
            continue
        for k in masked:
            if 0 <= k < len(cells):
                cells[k] = f" {MASK} "
        lines[i] = "|" + "|".join(cells) + "|"
    out = "\n".join(lines)
    for p in patterns:
        out = re.sub(p, MASK, out)
    return out


def write_unless_timings(path: str | Path, text: str, columns: Iterable[str] = (),
                         patterns: Iterable[str] = ()) -> bool:
    """Write ``text`` to ``path`` unless the file there differs from it only in timings (see ``mask_timings``);
    True when written."""
    path = Path(path)
    columns, patterns = list(columns), list(patterns)
    if path.is_file():
        try:
            old = path.read_text()
        except (OSError, UnicodeDecodeError):
            old = None
        if old is not None and mask_timings(old, columns, patterns) == mask_timings(text, columns, patterns):
            return False
    path.write_text(text)
    return True


def _drop_keys(obj, keys: set[str]):
    if isinstance(obj, dict):
        return {k: _drop_keys(v, keys) for k, v in obj.items() if k not in keys}
    if isinstance(obj, list):
        return [_drop_keys(v, keys) for v in obj]
    return obj


def write_json_unless_timings(path: str | Path, obj, keys: Iterable[str] = ("seconds",)) -> bool:
    """Write ``obj`` as indented JSON unless the file there holds the same content but for the values of the
    timing ``keys`` (at any depth); True when written."""
    path = Path(path)
    text = json.dumps(obj, indent=1, default=str) + "\n"
    keys = set(keys)
    if path.is_file():
        try:
            old = json.loads(path.read_text())
        except (OSError, UnicodeDecodeError, ValueError):
            old = None
        if old is not None and _drop_keys(old, keys) == _drop_keys(json.loads(text), keys):
            return False
    path.write_text(text)
    return True
