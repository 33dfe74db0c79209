"""A sweep through a distributed engine: Hydra's submitit launcher with submitit's local executor (the code path
of the SLURM preset), two settings in concurrent worker processes writing into one resumable store. The workers
are killed mid-way; the same command run again completes the sweep with no trial lost or written twice."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
N_TRIALS = 12
METHODS = ("zhang_pless_linear", "vasconcelos")


def _command(results: Path) -> list[str]:
    return [sys.executable, "-m", "experiments.run", "-m", "hydra/launcher=local_submitit", "n_jobs=1",
            "chunk_size=1", f"n_trials={N_TRIALS}", "scene.n_boards=4,6", "sweep=dist",
            f"methods.names=[{','.join(METHODS)}]",
            "progress=false", f"results_dir={results}"]


def _chunks(results: Path) -> dict[str, list[Path]]:
    cells = sorted((results / "dist" / "trials").glob("*/"))
    return {c.name: sorted(c.glob("chunk-*.csv")) for c in cells}


def _workers(results: Path) -> list[int]:
    """PIDs of the running submitit task processes (children of each local job's controller, whose pid is the
    job id and the name of its folder)."""
    pids = []
    for job in (results / "dist" / "hydra").glob("multirun-*/.submitit/*/"):
        if not job.name.isdigit():
            continue
        children = Path(f"/proc/{job.name}/task/{job.name}/children")
        if children.exists():
            pids += [int(p) for p in children.read_text().split()]
    return pids


def _kill_midway(proc: subprocess.Popen, results: Path, timeout_s: float = 60.0) -> dict[str, int]:
    """Wait until a cell holds some but not all of its chunks, SIGKILL every worker, wait for the launcher."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        counts = {k: len(v) for k, v in _chunks(results).items()}
        if any(0 < n <= N_TRIALS // 2 for n in counts.values()) and len(_workers(results)) >= 2:
            break
        assert proc.poll() is None, "the sweep finished before a worker could be killed"
        time.sleep(0.02)
    for pid in _workers(results):
        os.kill(pid, signal.SIGKILL)
    proc.wait(timeout=60)
    return {k: len(v) for k, v in _chunks(results).items()}


def test_submitit_sweep_killed_midway_resumes_without_loss_or_duplicates(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "HYDRA_FULL_ERROR": "1"}
    first = subprocess.Popen(_command(tmp_path), cwd=ROOT, env=env, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
    try:
        at_kill = _kill_midway(first, tmp_path)
    finally:
        if first.poll() is None:
            first.kill()
    assert first.returncode != 0, "the launcher should report the killed workers"
    assert len(at_kill) < 2 or min(at_kill.values()) < N_TRIALS, f"nothing left to resume: {at_kill}"

    again = subprocess.run(_command(tmp_path), cwd=ROOT, env=env, capture_output=True, text=True, timeout=120)
    assert again.returncode == 0, again.stderr[-2000:]
    chunks = _chunks(tmp_path)
    assert len(chunks) == 2
    for cell, files in chunks.items():
        rows = pd.concat([pd.read_csv(f) for f in files], ignore_index=True)
        pairs = list(zip(rows["trial"], rows["method"], strict=True))
        assert len(pairs) == len(set(pairs)), f"{cell}: a (trial, method) row written twice"
        assert set(pairs) == {(t, m) for t in range(N_TRIALS) for m in METHODS}, f"{cell}: rows lost"
    leftovers = [p.name for p in (tmp_path / "dist" / "trials").rglob("*") if p.is_file()
                 and not (p.name.startswith("chunk-") or p.name == "settings.json")]
    assert all(n.endswith(".tmp") for n in leftovers), leftovers  # a killed write leaves only a hidden temp file
