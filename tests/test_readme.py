"""The method table (docs/METHOD.md) agrees with the registry: every project method is listed with its minimum
boards; the README's Use block and docs/usage.md's, which goes on from it, run as written."""

from __future__ import annotations

import re
from pathlib import Path

from calib_core import METHODS

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
USAGE = ROOT / "docs" / "usage.md"
METHOD_TABLE = ROOT / "docs" / "METHOD.md"
"""The method table's home (its section ``## The methods``)."""


def _table_rows() -> dict[str, str]:
    text = METHOD_TABLE.read_text()
    section = text[text.index("## The methods"):]
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


def test_every_base_method_is_in_the_method_table_with_its_minimum_boards():
    rows = _table_rows()
    base = [m for m in METHODS.values() if "+" not in m.name and "/" not in m.name and m.origin == "lidarcam"]
    assert base, "no project methods registered"
    for m in base:
        assert m.name in rows, f"the method table lacks {m.name}"
        assert rows[m.name] == str(m.min_boards), f"{m.name}: the table says {rows[m.name]}, registry {m.min_boards}"


def test_every_method_table_row_is_a_method():
    names = [n for n in _table_rows() if n not in ("X+ml", "X+plane", "X+joint", "peng2022/...")]
    assert names and all(n in METHODS for n in names), names


def _use_lines(path: Path = README, heading: str = "## Use") -> list[str]:
    """The ``lidarcam ...`` lines of the first ``bash`` block after ``heading`` in ``path``, comments cut."""
    text = path.read_text()
    block = text[text.index(heading):]
    block = block[block.index("```bash") + len("```bash"):]
    block = block[:block.index("```")]
    return [ln.split("  #")[0].strip() for ln in block.splitlines() if ln.startswith("lidarcam ")]


PLACEHOLDERS = ("DATASET", "SRC", "REC", "OUT", "|", "conf/")
"""Words that would stand for the reader's own data or the checkout: none may be left in the Use blocks."""


def test_the_readme_use_block_is_a_short_start():
    lines = _use_lines()
    assert 4 <= len(lines) <= 8 and lines[0].startswith("lidarcam demo /tmp/demo"), lines
    assert any(ln.startswith("lidarcam calibrate") for ln in lines) and any("report" in ln for ln in lines)


def test_the_use_blocks_run_top_to_bottom_on_the_files_they_make(tmp_path, monkeypatch, capsys):
    """Every line of the README's Use block, then of docs/usage.md's, in order, in an empty folder (no checkout
    files), ``/tmp/demo`` moved under it; ``> FILE`` writes the line's output there, as a shell would."""
    import shlex

    from lidarcam.cli import main

    lines = _use_lines() + _use_lines(USAGE, "## More of the command line")
    assert len(lines) >= 15 and not [ln for ln in lines if any(p in ln for p in PLACEHOLDERS)]
    assert lines[0].startswith("lidarcam demo /tmp/demo") and any("--fix" in ln for ln in lines)
    assert any("plan --template >" in ln for ln in lines) and any("--std-intrinsics" in ln for ln in lines)
    monkeypatch.chdir(tmp_path)
    for ln in lines:
        argv, _, target = ln.replace("/tmp/demo", str(tmp_path / "demo")).partition(" > ")
        code = main(shlex.split(argv)[1:])
        out, err = capsys.readouterr()
        assert code == 0, f"{ln}: exit {code}: {err or out[-300:]}"
        if target:
            (tmp_path / target.strip()).write_text(out)
