"""Every stored row carries a checksum: a row edited after it was written (one digit, one ``valid`` flipped, text
or bytes where a number belongs) or a folder in a chunk's place is found by ``verify``, never served, and its
chunk is recomputed to the table of an undamaged run."""

from __future__ import annotations

import re
import shutil

import numpy as np
import pandas as pd
import pytest

from experiments.engine.cell import Cell
from experiments.engine.runner import run_cells
from experiments.engine.store import CHECK_COLUMN, DamagedChunk, load_cell_dir, verify_store


def fake_trial(cell: Cell, trial: int, methods) -> list[dict]:
    rows = []
    for m in methods:
        rng = np.random.default_rng([cell.seed, trial, sum(map(ord, m))])
        e_R, e_t = float(rng.exponential(4.0)), float(rng.exponential(0.3))
        rows.append({**cell.columns(), "trial": trial, "method": m, "ok": True, "reason": "",
                     "e_R_deg": e_R, "e_t_m": e_t, "valid": e_R < 8 and e_t < 0.8, "n_candidates": 2,
                     "seconds": 0.0})
    return rows


def _cell(root) -> Cell:
    return Cell("fake", {"n_boards": 6, "noise_mm": 20.0}, seed=5, n_trials=9, methods=("m1", "m2"),
                results_dir=str(root))


def _one_digit(text: str) -> str:
    """The first e_R_deg value of the last row with one digit changed."""
    lines = text.splitlines(keepends=True)
    col = lines[0].rstrip("\n").split(",").index("e_R_deg")
    fields = lines[-1].split(",")
    digits = [i for i, ch in enumerate(fields[col]) if ch.isdigit() and ch != "0"]
    i = digits[-1]
    fields[col] = fields[col][:i] + str((int(fields[col][i]) + 1) % 10) + fields[col][i + 1:]
    return "".join(lines[:-1]) + ",".join(fields)


def _flip_valid(text: str) -> str:
    lines = text.splitlines(keepends=True)
    col = lines[0].rstrip("\n").split(",").index("valid")
    fields = lines[1].split(",")
    fields[col] = {"True": "False", "False": "True"}[fields[col]]
    return lines[0] + ",".join(fields) + "".join(lines[2:])


def _number_to(text: str, what: str) -> str:
    lines = text.splitlines(keepends=True)
    col = lines[0].rstrip("\n").split(",").index("e_t_m")
    fields = lines[1].split(",")
    fields[col] = what
    return lines[0] + ",".join(fields) + "".join(lines[2:])


DAMAGE = {
    "one_digit": _one_digit,
    "valid_flipped": _flip_valid,
    "text_for_number": lambda t: _number_to(t, "twelve"),
    "bytes_for_number": lambda t: _number_to(t, "\x00\x7f\x01"),
}


@pytest.mark.parametrize("kind", [*DAMAGE, "folder"])
def test_an_edited_row_is_found_and_recomputed(tmp_path, kind):
    full = run_cells([_cell(tmp_path / "full")], n_jobs=1, chunk_size=3, trial_fn=fake_trial, progress=False)
    cell = _cell(tmp_path / "hurt")
    run_cells([cell], n_jobs=1, chunk_size=3, trial_fn=fake_trial, progress=False)
    chunk = sorted(cell.dir.glob("chunk-*.csv"))[1]
    if kind == "folder":
        chunk.unlink()
        (chunk / "inner").mkdir(parents=True)
    else:
        text = chunk.read_text()
        chunk.write_text(DAMAGE[kind](text))
        assert chunk.read_text() != text
    problems = verify_store(tmp_path / "hurt")
    assert len(problems) == 1 and chunk.name in problems[0], problems
    with pytest.raises(DamagedChunk):
        load_cell_dir(cell.dir)
    calls: list[int] = []
    healed = run_cells([cell], n_jobs=1, chunk_size=3, progress=False,
                       trial_fn=lambda *a: (calls.append(a[1]), fake_trial(*a))[1])
    assert calls == [3, 4, 5]
    pd.testing.assert_frame_equal(full, healed)
    assert verify_store(tmp_path / "hurt") == []


def test_rows_carry_their_checksum_and_readers_do_not_see_it(tmp_path):
    cell = _cell(tmp_path)
    df = run_cells([cell], n_jobs=1, chunk_size=3, trial_fn=fake_trial, progress=False)
    assert CHECK_COLUMN not in df
    for f in cell.dir.glob("chunk-*.csv"):
        raw = pd.read_csv(f, dtype=str)
        assert raw[CHECK_COLUMN].map(lambda v: bool(re.fullmatch(r"[0-9a-f]{16}", v))).all()
        assert raw[CHECK_COLUMN].nunique() == len(raw)


def test_a_chunk_written_before_checksums_is_recomputed(tmp_path, capsys):
    cell = _cell(tmp_path)
    run_cells([cell], n_jobs=1, chunk_size=3, trial_fn=fake_trial, progress=False)
    old = sorted(cell.dir.glob("chunk-*.csv"))[0]
    pd.read_csv(old).drop(columns=CHECK_COLUMN).to_csv(old, index=False)
    calls: list[int] = []
    run_cells([cell], n_jobs=1, chunk_size=3, progress=False,
              trial_fn=lambda *a: (calls.append(a[1]), fake_trial(*a))[1])
    assert calls == [0, 1, 2]
    assert "written before rows carried checksums" in capsys.readouterr().err
    shutil.rmtree(tmp_path)
