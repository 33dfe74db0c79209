"""What git keeps of the results: reports, summaries and figures, not the per-trial rows (the store and the
trial tables are ignored and recomputed); the notebook reads the summaries and skips the distributions with a line
when the rows are absent; ``verify`` on a folder of reports alone (a fresh clone) still tells a stale report."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _git(*args: str) -> subprocess.CompletedProcess:
    if shutil.which("git") is None or subprocess.run(["git", "rev-parse"], cwd=ROOT, capture_output=True).returncode:
        pytest.skip("not a git checkout")
    return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True)


def test_no_trial_rows_are_tracked():
    tracked = _git("ls-files", "results").stdout.splitlines()
    assert tracked, "no results tracked at all"
    rows = [p for p in tracked if Path(p).name.startswith("trials_") or "/trials/" in p]
    assert rows == []


@pytest.mark.parametrize("path", ["results/paper/trials_boards.csv", "results/explain/trials_ablation.csv",
                                  "results/paper-matched/default/trials_noise.csv",
                                  "results/boards/trials/nb3-noise20mm-0123456789/chunk-00000-00024-abcdef.csv",
                                  "results/paper/.inputs.json"])
def test_the_rows_and_the_drawing_state_are_ignored(path):
    assert _git("check-ignore", "-q", path).returncode == 0, path


def test_reports_summaries_and_figures_stay_tracked():
    for path in ("results/paper/REPORT.md", "results/paper/summary_boards.csv"):
        assert _git("check-ignore", "-q", path).returncode == 1, path


def test_the_notebook_reads_summaries_alone(tmp_path):
    import nbclient
    import nbformat
    import pandas as pd

    from experiments.summary.aggregate import write_summary

    tables = tmp_path / "paper"
    tables.mkdir()
    rows = [{"n_boards": nb, "method": m, "valid_rate": 0.5, "valid_lo95": 0.4, "valid_hi95": 0.6,
             "median_e_R_deg": 1.0} for nb in (3, 4) for m in ("peng2022", "lidarcam")]
    write_summary(pd.DataFrame(rows), tables / "summary_boards.csv")
    nb = nbformat.read(ROOT / "notebooks" / "results.ipynb", as_version=4)
    os.environ["LIDARCAM_RESULTS"] = str(tmp_path)
    try:
        nbclient.NotebookClient(nb, timeout=120, kernel_name="python3",
                                resources={"metadata": {"path": str(ROOT / "notebooks")}}).execute()
    finally:
        del os.environ["LIDARCAM_RESULTS"]
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not any(o.get("output_type") == "error" for o in outputs)
    text = "".join(o.get("text", "") for o in outputs if o.get("output_type") == "stream")
    assert "no trials_*.csv" in text and "skipped" in text


def test_verify_tells_a_stale_report_without_any_store(tmp_path):
    from experiments.engine.fingerprint import REPORT_MARK, write_stamped

    report = write_stamped(tmp_path / "paper" / "REPORT.md" if (tmp_path / "paper").mkdir() is None else None,
                           "# A report\n")
    cmd = [sys.executable, "-m", "experiments", "verify", str(tmp_path)]
    assert subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True).returncode == 0
    text = report.read_text()
    mark = next(ln for ln in text.splitlines() if ln.startswith(REPORT_MARK))
    stale = mark.replace("calib_core ", "calib_core 0", 1)
    report.write_text(text.replace(mark, stale))
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 1 and "stale report" in out.stdout
