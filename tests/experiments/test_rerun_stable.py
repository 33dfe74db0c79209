"""A rerun of the same code rewrites the committed outputs byte for byte: wall times go to untracked
``timings_*.csv``, PDFs carry no creation date, the report's provenance names no commit and keeps its link to the
explain study."""

from __future__ import annotations

import subprocess

import matplotlib
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from test_experiments import fake_trial  # noqa: E402

from experiments.engine.cell import Cell  # noqa: E402
from experiments.engine.paths import ROOT  # noqa: E402
from experiments.paper import report  # noqa: E402
from experiments.summary.aggregate import write_tables  # noqa: E402
from experiments.summary.figures import save_figure  # noqa: E402


def _rows(scale: float):
    import pandas as pd

    cell = Cell("fake", {"n_boards": 6, "noise_mm": 20.0}, seed=1, n_trials=6, methods=("m1", "m2"), results_dir="x")
    rows = [r for t in range(6) for r in fake_trial(cell, t, cell.methods)]
    df = pd.DataFrame(rows).assign(sweep="fake", setting_key="k")
    return df.assign(seconds=df["seconds"] * scale + 0.01 * scale)


def test_tables_of_the_same_rows_with_other_wall_times_are_the_same_files(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    write_tables(_rows(1.0), "fake", a)
    write_tables(_rows(3.7), "fake", b)
    for name in ("summary_fake.csv", "trials_fake.csv", "settings_fake.json"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert (a / "timings_trials_fake.csv").read_bytes() != (b / "timings_trials_fake.csv").read_bytes()
    assert "seconds" in (a / "timings_trials_fake.csv").read_text().splitlines()[0]
    assert "median_seconds" in (a / "timings_summary_fake.csv").read_text().splitlines()[0]


def test_the_settings_file_is_strict_json_when_a_setting_is_empty_text(tmp_path):
    import json
    import math

    rows = _rows(1.0).assign(cam_params=math.nan)  # an empty text setting, read back from the store, is NaN
    write_tables(rows, "fake", tmp_path)
    settings = json.loads((tmp_path / "settings_fake.json").read_text(),
                          parse_constant=lambda c: pytest.fail(f"settings_fake.json holds {c}"))
    assert settings["cam_params"] is None and settings["noise_mm"] == 20.0


def test_timings_files_are_not_tracked():
    out = subprocess.run(["git", "check-ignore", "-q", "results/paper/timings_trials_boards.csv"], cwd=ROOT)
    assert out.returncode == 0


def test_the_same_figure_is_the_same_pdf(tmp_path):
    def draw(folder):
        fig, ax = plt.subplots()
        ax.plot([0, 1], [1, 0])
        return save_figure(fig, tmp_path / folder, "f")

    for p, q in zip(draw("a"), draw("b"), strict=True):
        assert p.read_bytes() == q.read_bytes(), p.name


def test_the_paper_report_keeps_its_link_to_the_explain_report(tmp_path, monkeypatch):
    monkeypatch.setattr(report, "build_paper_report", lambda tables: "# The paper\n")
    (tmp_path / "paper").mkdir()
    path = report.write_paper_report(tmp_path / "paper")
    assert "explain/REPORT.md" not in path.read_text()  # no explain report: no dead link
    (tmp_path / "explain").mkdir()
    (tmp_path / "explain" / "REPORT.md").write_text("# explain\n")
    first = report.write_paper_report(tmp_path / "paper").read_text()
    assert "[explain/REPORT.md](../explain/REPORT.md)" in first and "commit" not in first
    assert report.write_paper_report(tmp_path / "paper").read_text() == first


def test_the_leaderboard_report_of_a_rerun_differs_only_in_its_timing_line():
    import pandas as pd

    from experiments.suites.leaderboard import build_leaderboard_report

    info = {"suite_file": "conf/leaderboard/v1.yaml", "version": "1", "full": False, "cells": {}, "real": set(),
            "trials": {}, "suite_overrides": {}, "skipped": [], "methods": ["lidarcam"], "plugins": (),
            "overrides": ["scene.noise_mm=10"], "rows": 100, "rows_computed": 100, "run_s": 300.0, "cores": 2,
            "load": 5.0}
    rerun = {**info, "rows_computed": 0, "run_s": 8.0, "load": 1.2}
    a, b = (build_leaderboard_report(pd.DataFrame(), None, i, set()).splitlines() for i in (info, rerun))
    assert len(a) == len(b)
    changed = [x for x, y in zip(a, b, strict=True) if x != y]
    assert changed and all(x.startswith("- Timing of this run") for x in changed), changed
    assert any("scene.noise_mm=10" in x for x in a if not x.startswith("- Timing"))
