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


def _use_lines() -> list[str]:
    """The ``lidarcam ...`` lines of the README's "Use" block, comments cut."""
    text = README.read_text()
    block = text[text.index("## Use"):]
    block = block[block.index("```bash") + len("```bash"):]
    block = block[:block.index("```")]
    return [ln.split("  #")[0].strip() for ln in block.splitlines() if ln.startswith("lidarcam ")]


PLACEHOLDERS = ("DATASET", "SRC", "REC", "OUT", "/tmp/demo", "|")
"""Words of the Use lines that stand for the reader's own data (those lines are run by test_real_rigs/test_demo)."""


def test_the_use_lines_on_the_readmes_own_obs_json_run_as_written(tmp_path, monkeypatch, capsys):
    import shlex

    from lidarcam.cli import main

    lines = [ln for ln in _use_lines() if not any(p in ln for p in PLACEHOLDERS)]
    assert lines[0].startswith("lidarcam simulate") and any("--fix" in ln for ln in lines)
    assert any("plan" in ln and "--from obs.json" in ln for ln in lines)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "conf").symlink_to(README.parent / "conf")
    for ln in lines:
        code = main(shlex.split(ln)[1:])
        out, err = capsys.readouterr()
        assert code == 0, f"{ln}: exit {code}: {err or out[-300:]}"
