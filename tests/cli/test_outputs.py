"""Every verb that writes, given an output it cannot write (a missing folder, a read-only folder, a file in the
way): one line on stderr, exit 2, no traceback, and nothing done first (calibrate prints no answer)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import pytest

from lidarcam.cli import build_parser, main

# How each verb is called with its output at {out}; {obs}/{tmp} are a valid observation file and a scratch folder.
CALLS = {
    "simulate --out": "simulate --boards 6 --out {out}/obs.json",
    "calibrate --out": "calibrate {obs} --out {out}/r.json",
    "calibrate --yaml": "calibrate {obs} --yaml {out}/e.yaml",
    "extract --out": "extract {tmp} --out {out}/obs.json",
    "extract --diagnostics": "extract {tmp} --out {tmp}/o.json --diagnostics {out}/d.json",
    "report --out": "report {obs} {tmp}/r.json --out {out}/report",
    "import --out (dataset)": "import pcd {tmp} --images {tmp} --board-grid 9x6 --square 0.1 --out {out}/ds",
    "import --out (observations)": "import bouguet {tmp}/c.mat --points {tmp}/p.csv --out {out}/obs.json",
    "bag --out": "bag {tmp}/rec --image-topic /i --scan-topic /s --board {tmp}/b.yaml --out {out}/ds",
    "demo OUT": "demo {out}/demo",
    "plan --json": "plan --from {obs} --json {out}/p.json",
    "plan --figure": "plan --from {obs} --figure {out}/p.png",
}
OUTPUT_DESTS = {"out", "yaml", "json", "figure", "diagnostics"}


@pytest.fixture(scope="module")
def obs_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("obs") / "obs.json"
    assert main(["simulate", "--boards", "6", "--noise-mm", "20", "--seed", "1", "--out", str(path)]) == 0
    return path


def _unwritable_folder(tmp_path: Path) -> Path:
    """A folder where no file can be created: read-only bits, or (as root, who ignores them) a read-only mount."""
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    for cand in (ro, Path("/sys"), Path("/proc/self")):
        try:
            (cand / ".lidarcam-write-test").write_text("x")
        except OSError:
            return cand
        (cand / ".lidarcam-write-test").unlink()
    pytest.skip("no unwritable folder on this machine")


@pytest.fixture(params=["missing", "read-only", "file"])
def bad_out(request, tmp_path):
    if request.param == "missing":
        return tmp_path / "no" / "such" / "folder"
    if request.param == "file":
        (tmp_path / "a_file").write_text("x")
        return tmp_path / "a_file"
    return _unwritable_folder(tmp_path)


@pytest.mark.parametrize("call", sorted(CALLS))
def test_an_unwritable_output_is_one_line_and_exit_2(call, bad_out, obs_path, tmp_path, capsys):
    argv = CALLS[call].format(out=bad_out, obs=obs_path, tmp=tmp_path).split()
    folder_output = call in ("demo OUT", "report --out", "bag --out", "import --out (dataset)",
                             "import --out (observations)")
    if folder_output and not bad_out.exists():
        pytest.skip("this verb creates a missing folder (test_a_missing_folder_for_a_folder_output_is_created)")
    code = main(argv)
    out, err = capsys.readouterr()
    assert code == 2, (code, err)
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert str(bad_out) in err
    assert out == "", f"{call} printed before failing: {out[:200]}"


def test_every_writing_option_of_every_verb_is_checked():
    """The table above covers each verb's output options (a new verb that writes must join it)."""
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    needed = set()
    for verb, parser in sub.choices.items():
        for a in parser._actions:
            if a.dest in OUTPUT_DESTS or (verb == "demo" and a.dest == "out"):
                needed.add((verb, a.dest))
    covered = {(c.split()[0], "out" if c.split()[1] in ("OUT", "--out") else c.split()[1].lstrip("-"))
               for c in CALLS}
    assert needed <= covered, needed - covered


def test_a_missing_folder_for_a_folder_output_is_created(obs_path, tmp_path, capsys):
    out = tmp_path / "new" / "report"
    assert main(["report", str(obs_path), str(tmp_path / "nothing.json"), "--out", str(out)]) == 2
    assert "nothing.json" in capsys.readouterr().err  # got past the output check to the missing result
    assert os.path.isdir(tmp_path) and not out.exists()
