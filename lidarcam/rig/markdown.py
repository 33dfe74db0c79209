"""Markdown for the generated reports (rig's and the experiments'): one table builder and the number cells.

Tables are GitHub-flavoured: a header row, a separator row (``---`` left, ``---:`` right-aligned) and one row per
item, every cell already a string. Number cells print ``-`` (or the ``missing`` text) where a value is None, NaN or
infinite, so a table never shows ``nan``.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence


def md_table(header: Sequence[str], rows: Iterable[Sequence[object]], align: str | None = None) -> list[str]:
    """The lines of a markdown table. ``align``: one letter per column, ``l`` (default) or ``r``; None: all left.

    A row with another number of cells than the header raises ValueError (a table that would render shifted).
    """
    header = [str(h) for h in header]
    align = align or "l" * len(header)
    if len(align) != len(header) or set(align) - {"l", "r"}:
        raise ValueError(f"align {align!r} does not give l or r for each of the {len(header)} columns")
    lines = ["| " + " | ".join(header) + " |", "|" + "".join("---:|" if a == "r" else "---|" for a in align)]
    for row in rows:
        cells = [str(c) for c in row]
        if len(cells) != len(header):
            raise ValueError(f"a row of {len(cells)} cells in a table of {len(header)} columns: {cells[:3]}")
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def is_number(v) -> bool:
    """True for a finite real number (not None, NaN or infinite)."""
    try:
        return v is not None and math.isfinite(float(v))
    except (TypeError, ValueError):
        return False


def num(v, spec: str = ".2f", missing: str = "-") -> str:
    """``v`` formatted with the format spec ``spec`` (e.g. ``.1f``, ``+.0f``, ``.0%``), or ``missing``."""
    return format(float(v), spec) if is_number(v) else missing


def pct(v, digits: int = 0, missing: str = "-", sign: str = "%") -> str:
    """A fraction ``v`` (0..1) as a percentage with ``digits`` decimals followed by ``sign``, or ``missing``."""
    return f"{100 * float(v):.{digits}f}{sign}" if is_number(v) else missing
