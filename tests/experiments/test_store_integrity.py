"""The results store heals: a damaged chunk file of any kind is found, moved aside, recomputed on rerun, and the
final table equals that of an undamaged run; experiment configs fail at composition with one line."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from experiments.engine.cell import Cell
from experiments.engine.runner import run_cells
from experiments.engine.store import DamagedChunk, load_cell_dir, verify_store

ROOT = Path(__file__).resolve().parents[2]


def fake_trial(cell: Cell, trial: int, methods) -> list[dict]:
    rows = []
    for k, m in enumerate(methods):
        rng = np.random.default_rng([cell.seed, trial, sum(map(ord, m))])
        e_R, e_t = float(rng.exponential(4.0)), float(rng.exponential(0.3))
        rows.append({**cell.columns(), "trial": trial, "method": m, "ok": True, "reason": "",
                     "e_R_deg": e_R, "e_t_m": e_t, "valid": e_R < 8 and e_t < 0.8, "n_candidates": k + 1,
                     "true_among_candidates": e_R < 1, "some_candidate_valid": True,
                     "best_candidate_e_R_deg": e_R, "best_candidate_e_t_m": e_t, "seconds": 0.0,
                     "crlb_rot_deg": np.nan, "crlb_trans_mm": np.nan, "conditioning": np.nan})
    return rows


def _cell(root, n_trials=9) -> Cell:
    return Cell("fake", {"n_boards": 6, "noise_mm": 20.0}, seed=3, n_trials=n_trials, methods=("m1", "m2"),
                results_dir=str(root))


def _damage(path: Path, kind: str) -> None:
    raw = path.read_bytes()
    lines = raw.splitlines(keepends=True)
    damaged = {
        "empty": b"",
        "header_only": lines[0],
        "cut_mid_row": raw[: len(raw) - len(lines[-1]) // 2 - 1],
        "cut_at_row": b"".join(lines[:-1]),
        "junk_row": raw + b"garbage,1,2,3\n",
        "junk_bytes": raw[:40] + b"\x00\xff\xfe junk \x00" + raw[60:],
        "duplicate_row": raw + lines[-1],
        "bad_bool": raw.replace(b",True,", b",Maybe,", 1),
        "not_csv": b"\x89PNG\r\n\x1a\n" + bytes(range(256)),
    }[kind]
    path.write_bytes(damaged)


KINDS = ["empty", "header_only", "cut_mid_row", "cut_at_row", "junk_row", "junk_bytes", "duplicate_row", "bad_bool",
         "not_csv"]


@pytest.mark.parametrize("kind", KINDS)
def test_damaged_chunk_is_recomputed_to_the_same_table(tmp_path, kind):
    full = run_cells([_cell(tmp_path / "full")], n_jobs=1, chunk_size=3, trial_fn=fake_trial, progress=False)
    cell = _cell(tmp_path / "hurt")
    run_cells([cell], n_jobs=1, chunk_size=3, trial_fn=fake_trial, progress=False)
    chunk = sorted(cell.dir.glob("chunk-*.csv"))[1]
    _damage(chunk, kind)
    problems = verify_store(tmp_path / "hurt")
    assert len(problems) == 1 and chunk.name in problems[0]
    with pytest.raises(DamagedChunk, match="damaged chunk"):
        load_cell_dir(cell.dir)                    # a reader never takes it in part
    calls: list[int] = []
    healed = run_cells([cell], n_jobs=1, chunk_size=3, progress=False,
                       trial_fn=lambda *a: (calls.append(a[1]), fake_trial(*a))[1])
    assert calls == [3, 4, 5]                      # exactly the damaged chunk's trials
    pd.testing.assert_frame_equal(full, healed)
    assert verify_store(tmp_path / "hurt") == []
    assert (chunk.parent / (chunk.name + ".damaged")).exists()


def test_verify_command(tmp_path):
    cell = _cell(tmp_path)
    run_cells([cell], n_jobs=1, chunk_size=3, trial_fn=fake_trial, progress=False)
    cmd = [sys.executable, "-m", "experiments", "verify", str(tmp_path)]
    assert subprocess.run(cmd, cwd=ROOT, capture_output=True).returncode == 0
    sorted(cell.dir.glob("chunk-*.csv"))[0].write_bytes(b"")
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 1 and "damaged chunk file" in out.stdout


@pytest.mark.parametrize("override, key", [
    ("scene.n_boards=0", "scene.n_boards"), ("noise.noise_mm=-5", "noise.noise_mm"),
    ("scene.dist_min_m=7", "scene.dist_min_m"), ("scene.max_tilt_deg=90", "scene.max_tilt_deg"),
    ("methods.names=[nope]", "methods.names"), ("n_trials=-5", "n_trials"), ("n_trials=0", "n_trials"),
    ("+methods.options.nope.x=1", "methods.options.nope"), ("+methods.options.lidarcam.bogus=1",
                                                            "methods.options.lidarcam"),
    ("seed=-1", "seed"), ("metrics.max_rot_deg=0", "metrics.max_rot_deg"), ("chunk_size=-1", "chunk_size"),
])
def test_bad_config_is_one_line_naming_the_key(tmp_path, override, key):
    from hydra import compose, initialize_config_dir

    from experiments.config.schema import cell_from_cfg
    from experiments.config.validate import ConfigError

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="config", overrides=[override, f"results_dir={tmp_path}"])
    with pytest.raises(ConfigError) as err:
        cell_from_cfg(cfg)
    assert f"'{key}'" in str(err.value) and "\n" not in str(err.value)


def test_bad_config_exits_2_without_traceback(tmp_path):
    out = subprocess.run([sys.executable, "-m", "experiments.run", "scene.n_boards=0", f"results_dir={tmp_path}"],
                         cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 2
    assert out.stderr.strip().splitlines() == ["error: config key 'scene.n_boards': n_boards must be >= 1, got 0"]
    assert not list(Path(tmp_path).rglob("chunk-*.csv"))
