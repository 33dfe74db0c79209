"""``make real-data`` with a mistyped data root is one line and exit 2 and writes nothing; a set absent under an
existing root is skipped."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from experiments.real.real_data import LOADERS, present_sets
from lidarcam.rig.dataset import DatasetError

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("kind", ["missing", "empty"])
def test_a_bad_data_root_is_one_line_exit_2_and_nothing_written(kind, tmp_path):
    data, out = tmp_path / "real-dta", tmp_path / "out"
    if kind == "empty":
        data.mkdir()
    r = subprocess.run([sys.executable, "-m", "experiments", "real-data", "--data", str(data), "--out", str(out)],
                       cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and str(data) in r.stderr, r.stderr
    assert not out.exists()


def test_sets_absent_under_an_existing_root_are_left_out(tmp_path):
    first = next(iter(LOADERS))
    (tmp_path / "root" / first).mkdir(parents=True)
    assert present_sets(tmp_path / "root") == [first]
    (tmp_path / "other").mkdir()
    with pytest.raises(DatasetError, match="none of the data sets"):
        present_sets(tmp_path / "other")
