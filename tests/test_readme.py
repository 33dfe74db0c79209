"""The README's method table agrees with the registry: every project method is listed with its minimum boards."""

from __future__ import annotations

import re
from pathlib import Path

from calib_core import METHODS

README = Path(__file__).resolve().parents[1] / "README.md"


def _table_rows() -> dict[str, str]:
    text = README.read_text()
    section = text[text.index("### Methods"):]
    rows = {}
    for line in section.splitlines()[2:]:
        if not line.startswith("|"):
            if rows:
                break
            continue
        cells = [c.strip() for c in line.strip("|").split("|")]
        for name in re.findall(r"`([^`]+)`", cells[0]):
            rows[name] = cells[1]
    return rows


def test_every_base_method_is_in_the_readme_with_its_minimum_boards():
    rows = _table_rows()
    base = [m for m in METHODS.values() if "+" not in m.name and "/" not in m.name and m.origin == "lidarcam"]
    assert base, "no project methods registered"
    for m in base:
        assert m.name in rows, f"README method table lacks {m.name}"
        assert rows[m.name] == str(m.min_boards), f"{m.name}: README says {rows[m.name]}, registry {m.min_boards}"


def test_every_readme_row_is_a_method():
    names = [n for n in _table_rows() if n not in ("X+ml", "X+plane", "X+joint", "peng2022/...")]
    assert names and all(n in METHODS for n in names), names
