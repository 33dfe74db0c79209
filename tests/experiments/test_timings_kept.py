"""A rerun of unchanged code leaves committed reports alone where only wall times differ (``make bench``'s
solvers.md, ``make real-data``'s REPORT.md and summary.json), and rewrites them when anything else changed."""

from __future__ import annotations

import json
import re

from experiments.bench import solver_bench
from experiments.engine.keep import mask_timings, write_json_unless_timings, write_unless_timings
from experiments.real import real_data

REPORT = """# Real data

| method | ok | fit RMS (mm) | time (s) |
|---|---|---|---|
| `lidarcam` | yes | 7.5 | 2.87 |
| `peng2022` | yes | 16.7 | 1.28 |

(rig-a: 47 s in one worker)

Total: 173 s wall (2 workers, one data set each at a time).
"""


def _report_write(path, text) -> bool:
    return write_unless_timings(path, text, real_data.REPORT_TIMING_COLUMNS, real_data.REPORT_TIMING_PATTERNS)


def test_a_report_differing_only_in_timings_is_kept(tmp_path):
    path = tmp_path / "REPORT.md"
    assert _report_write(path, REPORT)
    slower = REPORT.replace("2.87", "3.91").replace("47 s", "52 s").replace("173 s", "190 s")
    assert not _report_write(path, slower) and path.read_text() == REPORT
    changed = slower.replace("| 7.5 |", "| 7.6 |")
    assert _report_write(path, changed) and path.read_text() == changed
    assert _report_write(path, changed.replace("| yes | 16.7", "| no | 16.7"))


def test_masking_touches_only_the_timing_column():
    masked = mask_timings(REPORT, ["time (s)"], [])
    assert "2.87" not in masked and "1.28" not in masked and "7.5" in masked and "16.7" in masked
    assert "| time (s) |" in masked and "47 s in one worker" in masked


def test_a_summary_differing_only_in_seconds_is_kept(tmp_path):
    path = tmp_path / "summary.json"
    d = {"rig": {"rows": [{"method": "lidarcam", "rms_mm": 7.5, "seconds": 2.9, "cv": {"seconds": 0.1}}],
                 "seconds": 47.0}}
    assert write_json_unless_timings(path, d)
    first = path.read_text()
    d["rig"]["seconds"], d["rig"]["rows"][0]["cv"]["seconds"] = 52.0, 0.2
    assert not write_json_unless_timings(path, d) and path.read_text() == first
    d["rig"]["rows"][0]["rms_mm"] = 7.6
    assert write_json_unless_timings(path, d) and json.loads(path.read_text())["rig"]["rows"][0]["rms_mm"] == 7.6


def test_the_solver_benchmark_keeps_its_table_when_only_times_differ(tmp_path):
    solver_bench.run(2, [0.0], out=tmp_path)
    path = tmp_path / "solvers.md"
    earlier = re.sub(r"\| [0-9.]+ \|$", "| 999.9 |", path.read_text(), flags=re.M)  # an earlier run's times
    assert earlier.count("999.9") == len(solver_bench.MINIMAL_SOLVERS)
    path.write_text(earlier)
    solver_bench.run(2, [0.0], out=tmp_path)
    assert path.read_text() == earlier
    solver_bench.run(3, [0.0], out=tmp_path)          # other problems: other rates, rewritten
    assert "999.9" not in path.read_text()


def test_each_data_set_prints_its_lines_under_its_heading(monkeypatch, tmp_path, capsys):
    def fake_run_set(name, folder, out, n_subsets, n_jobs):
        print(f"{name}: line 1")
        print(f"{name}: line 2")
        return [f"## {name}"], {}

    monkeypatch.setattr(real_data, "run_set", fake_run_set)
    name, section, summary, log = real_data._timed_set("rig-a", tmp_path, tmp_path, 0)
    assert capsys.readouterr().out == ""                 # held back in the worker
    real_data.print_set(name, summary["seconds"], log)
    assert capsys.readouterr().out.splitlines() == ["== rig-a", "rig-a: line 1", "rig-a: line 2", "== rig-a: 0 s"]


def test_the_bench_table_stays_aligned_for_long_method_names():
    from experiments.bench.bench import method_lines

    rows = [{"method": m, "median_ms": 1.5, "p90_ms": 2.25, "runs": 20, "valid": "10/10"}
            for m in ("peng2022", "zhang_pless_linear+joint", "a_very_long_plugin_method_name+ml+refine")]
    lines = method_lines(rows)
    ends = {ln.index("  valid") if i == 0 else ln.rindex("  10/10") for i, ln in enumerate(lines)}
    assert len(ends) == 1, "\n".join(lines)
    assert all(ln.split()[0] == r["method"] for ln, r in zip(lines[1:], rows, strict=True))


def test_a_held_out_residual_that_no_fold_gives_is_no_nan_on_the_console(capsys):
    from experiments.real.real_eval import leaderboard
    from simulate import SimOptions, generate

    obs = generate(SimOptions(n_boards=4), seed=3)
    rows = leaderboard(obs, ["zhang_pless", "lidarcam"], sigma_m=0.02)
    out = capsys.readouterr().out
    assert "nan" not in out.lower(), out
    assert "zhang_pless: ok=False" in out and "held-out none (0 of 4 folds solved)" in out, out
    assert rows[1]["ok"] and f"held-out {rows[1]['cv']['rms_mm']:.1f} mm" in out
