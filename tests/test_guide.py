"""docs/adding-a-method.md, run as written: its ``python file=...`` block is written into a temporary folder and
its ``bash`` blocks run there in order (``lidarcam`` and ``python`` are this checkout's), through a small Hydra
multirun, the report step and a small leaderboard; then the outputs are checked."""

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
GUIDE = ROOT / "docs" / "adding-a-method.md"
BLOCK = re.compile(r"^```(\w+)([^\n]*)\n(.*?)^```", re.S | re.M)


def blocks():
    return [(lang, info.strip(), body) for lang, info, body in BLOCK.findall(GUIDE.read_text())]


def _local(script: str) -> str:
    """The guide's commands with ``lidarcam`` / ``python`` pointing at this interpreter and checkout."""
    py = sys.executable
    script = re.sub(r"(?m)^lidarcam ", f"{py} -m lidarcam.cli ", script)
    return re.sub(r"(?m)^python ", f"{py} ", script)


def test_the_guide_runs_as_written(tmp_path):
    files = [(info, body) for lang, info, body in blocks() if lang == "python" and info.startswith("file=")]
    scripts = [body for lang, _, body in blocks() if lang == "bash"]
    assert len(files) == 1 and len(scripts) >= 4
    for info, body in files:
        path = tmp_path / info.removeprefix("file=")
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(body)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    for script in scripts:
        r = subprocess.run(["bash", "-c", "set -eo pipefail\n" + _local(script)], cwd=tmp_path, env=env,
                           capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, f"{script}\n--- stdout\n{r.stdout[-3000:]}\n--- stderr\n{r.stderr[-3000:]}"
    # 3. one problem
    res = json.loads((tmp_path / "result.json").read_text())
    assert res["method"] == "median_plane" and res["ok"] is True
    # 4-5. the sweep, as the report step tabled it (before the leaderboard added settings to the store)
    summary = pd.read_csv(tmp_path / "byom" / "tables" / "summary_boards.csv")
    assert set(summary["method"]) == {"peng2022", "median_plane"} and sorted(set(summary["n_boards"])) == [4, 6]
    mine = summary[summary["method"] == "median_plane"]
    # an answer the consistency verdict contradicts is a refusal (ok=False), not a failure of the guide
    assert (mine["n_trials"] == 5).all() and mine["valid_rate"].mean() > 0.5
    assert (tmp_path / "byom" / "tables" / "figures" / "fig3a_valid_vs_boards.png").exists()
    # 6. the leaderboard: the plugin ranked beside the others, its origin named
    board = pd.read_csv(tmp_path / "byom" / "leaderboard" / "leaderboard.csv")
    assert set(board["method"]) == {"peng2022", "vasconcelos", "median_plane"}
    assert board.set_index("method").loc["median_plane", "origin"] == "my_lab.median_plane"
    report = (tmp_path / "byom" / "leaderboard" / "REPORT.md").read_text()
    assert "`median_plane` | my_lab.median_plane |" in report
    assert (tmp_path / "byom" / "leaderboard" / "leaderboard.png").exists()
