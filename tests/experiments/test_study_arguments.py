"""Hostile arguments to ``python -m experiments <study>``: each is one line ``...: error: ...``, exit status 2, no
traceback, and nothing computed -- a file as the results folder, an override that does not parse or merge or
deletes a group, an override of what a flag sets, a missing or binary suite file, missing tables folders, counts
and scales out of range, an empty or missing folder to verify."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from experiments.__main__ import PROG, main
from experiments.engine.entry import run_main

ROOT = Path(__file__).resolve().parents[2]


def _study(argv: list[str], capsys) -> tuple[int, str]:
    with pytest.raises(SystemExit) as stop:
        run_main(lambda: main(argv), prog=PROG)
    cap = capsys.readouterr()
    return stop.value.code, cap.err


CASES = {
    "file_as_results": (["reproduce", "--trials", "1", "--results", "{file}"], "not a folder"),
    "override_not_an_integer": (["reproduce", "--trials", "1", "--results", "{tmp}", "scene.n_boards=abc"],
                                "scene.n_boards=abc"),
    "override_beside_flag": (["reproduce", "--trials", "1", "--results", "{tmp}", "results_dir={tmp}/other"],
                             "--results"),
    "trials_negative": (["reproduce", "--trials", "-1", "--results", "{tmp}"], "--trials"),
    "n_jobs_zero": (["reproduce", "--n-jobs", "0", "--results", "{tmp}"], "--n-jobs"),
    "suite_missing": (["leaderboard", "--results", "{tmp}", "--suite", "{tmp}/none.yaml"], "none.yaml"),
    "suite_binary": (["leaderboard", "--results", "{tmp}", "--suite", "{binary}"], "binary.yaml"),
    "override_unparsable": (["leaderboard", "--results", "{tmp}", "scene.n_boards=["], "scene.n_boards=["),
    "override_deletes_group": (["leaderboard", "--results", "{tmp}", "~scene"], "~scene"),
    "report_no_tables": (["report", "--tables", "{tmp}/none"], "none"),
    "matched_report_no_tables": (["matched-report", "--tables", "{tmp}/none"], "summary_"),
    "figures_no_tables": (["figures", "--tables", "{tmp}/none"], "summary_boards.csv"),
    "plan_check_scale_nan": (["plan-check", "--scale", "nan", "--out", "{tmp}"], "--scale"),
    "real_data_no_workers": (["real-data", "--jobs", "0", "--out", "{tmp}"], "--jobs"),
    "real_data_subsets_negative": (["real-data", "--subsets", "-1", "--out", "{tmp}"], "--subsets"),
    "clean_check_boards_text": (["clean-check", "--boards", "abc"], "--boards"),
    "clean_check_one_board": (["clean-check", "--boards", "1"], "--boards"),
    "bench_no_problems": (["bench", "--problems", "0"], "--problems"),
    "bench_boards_text": (["bench", "--boards", "abc"], "--boards"),
    "bag_no_fps": (["bag-recording", "--fps", "0", "--out", "{tmp}"], "--fps"),
    "bag_negative_seconds": (["bag-recording", "--seconds", "-1", "--out", "{tmp}"], "--seconds"),
    "outliers_negative_chunks": (["outliers", "--chunk-size", "-1", "--results", "{tmp}"], "--chunk-size"),
    "verify_missing": (["verify", "{tmp}/none"], "not a folder"),
    "verify_empty": (["verify", "{tmp}"], "nothing to check"),
    "verify_missing_sweep": (["verify", "{tmp}", "--sweep", "nope"], "not a folder"),
}


@pytest.mark.parametrize("case", CASES)
def test_a_hostile_argument_is_one_line_and_exit_2(tmp_path, capsys, case):
    argv, needle = CASES[case]
    work = tmp_path / "work"
    work.mkdir()
    (tmp_path / "file").write_text("a file, not a folder\n")
    (tmp_path / "binary.yaml").write_bytes(bytes(range(256)) * 3)
    fill = {"tmp": str(work), "file": str(tmp_path / "file"), "binary": str(tmp_path / "binary.yaml")}
    code, err = _study([a.format(**fill) for a in argv], capsys)
    lines = err.strip().splitlines()
    assert code == 2, err
    assert len(lines) == 1 and "error: " in lines[0] and needle in lines[0], err
    assert not list(work.rglob("chunk-*.csv")) and not list(work.rglob("REPORT.md"))


def test_the_command_line_shows_no_traceback(tmp_path):
    out = subprocess.run([sys.executable, "-m", "experiments", "leaderboard", "--results", str(tmp_path),
                          "scene.n_boards=["], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert out.stderr.strip().splitlines() == [
        f"{PROG}: error: scene.n_boards=[: not a Hydra override (no viable alternative at input '[')"]
