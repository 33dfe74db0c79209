"""A sweep through a real SLURM scheduler: ``hydra/launcher=slurm`` (hydra-submitit-launcher) submits one job per
setting with ``sbatch``; the jobs write into one resumable store. Checked: every row equals the rows of the same
sweep run locally (same seeds, same answers); the jobs were SLURM jobs (``sacct`` states and node, submitit's
log files named by SLURM job id, the job's own SLURM environment); a job cancelled mid-way with ``scancel``
resumes on the rerun with no row lost or written twice, and the rows it had stored are kept, not recomputed.

Needs a reachable cluster whose nodes see this machine's temporary folder (``dev/slurm/cluster.sh start``, then
``export SLURM_CONF=...``, or ``make test-slurm``; elsewhere ``--basetemp`` on a shared file system). Skips with
one line when there is none; ``LIDARCAM_REQUIRE_SLURM=1`` (CI) turns that skip into a failure."""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from experiments.engine.store import CHECK_COLUMN

pytestmark = pytest.mark.slurm

ROOT = Path(__file__).resolve().parents[2]
METHODS = ("zhang_pless_linear", "lidarcam")
SWEEP = {"n_trials": 10, "chunk_size": 2, "boards": (4, 6), "noises": (10, 30)}  # 4 jobs of ~1 s of trials
# One job with 200 trials (10-40 s): scancel'd at <= 30 trials stored; its task ignores the SIGTERM (submitit's
# default) and is killed about 5 s later on dev/slurm's cluster (measured), with most of its trials still to do.
CANCEL = {"n_trials": 200, "chunk_size": 10, "boards": (6,), "noises": (20,)}
CANCEL_AT_MOST = 3  # chunks stored when the job is cancelled
# The columns that differ between two runs of the same settings: the wall time, and the row checksum over it.
TIMING = ("seconds", CHECK_COLUMN)
SLURM = ("hydra/launcher=slurm", "n_jobs=1", "hydra.launcher.cpus_per_task=1", "hydra.launcher.mem_gb=1",
         "hydra.launcher.timeout_min=10")


def _no_cluster() -> str | None:
    """Why no SLURM sweep can run here, or None."""
    if importlib.util.find_spec("hydra_plugins.hydra_submitit_launcher") is None:
        return "hydra-submitit-launcher is not installed (pip install -e '.[cluster]')"
    missing = [c for c in ("sbatch", "sinfo", "sacct", "squeue", "scancel") if shutil.which(c) is None]
    if missing:
        return f"no SLURM client here ({', '.join(missing)} not on PATH; dev/slurm/cluster.sh start installs one)"
    try:
        out = subprocess.run(["sinfo", "-h", "-o", "%T"], capture_output=True, text=True, timeout=30)
    except subprocess.TimeoutExpired:
        return "no SLURM controller answers (sinfo timed out after 30 s)"
    lines = [ln for ln in (out.stderr + out.stdout).splitlines() if ln.strip()]
    if out.returncode != 0:
        return (f"no SLURM controller answers ({lines[-1] if lines else 'sinfo failed'}; start one: "
                "dev/slurm/cluster.sh start, then export SLURM_CONF as it prints)")
    if not any(s.rstrip("*~#") in ("idle", "mixed", "allocated", "completing") for s in out.stdout.split()):
        return f"no SLURM node is up (sinfo: {' '.join(out.stdout.split()) or 'no nodes'})"
    return None


WHY_NOT = _no_cluster()
if WHY_NOT and os.environ.get("LIDARCAM_REQUIRE_SLURM") == "1":
    raise RuntimeError(f"SLURM required (LIDARCAM_REQUIRE_SLURM=1): {WHY_NOT}")
if WHY_NOT:
    pytest.skip(WHY_NOT, allow_module_level=True)


def _command(results: Path, sweep: dict, *launcher: str) -> list[str]:
    return [sys.executable, "-m", "experiments.run", "-m", *launcher, f"chunk_size={sweep['chunk_size']}",
            f"n_trials={sweep['n_trials']}", f"scene.n_boards={','.join(map(str, sweep['boards']))}",
            f"noise.noise_mm={','.join(map(str, sweep['noises']))}", "sweep=slurm",
            f"methods.names=[{','.join(METHODS)}]", "progress=false", f"results_dir={results}"]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT), "HYDRA_FULL_ERROR": "1"}


def _rows(results: Path) -> pd.DataFrame:
    files = sorted((results / "slurm" / "trials").glob("*/chunk-*.csv"))
    assert files, f"no rows under {results}"
    df = pd.concat([pd.read_csv(f) for f in files], ignore_index=True)
    return df.sort_values(["setting_key", "trial", "method"]).reset_index(drop=True)


def _cells(results: Path) -> dict[tuple[int, float], Path]:
    """Each stored cell's folder by its (boards, noise mm), read from its settings.json."""
    out = {}
    for s in (results / "slurm" / "trials").glob("*/settings.json"):
        sim = json.loads(s.read_text())["sim"]
        out[(int(sim["n_boards"]), float(sim["noise_mm"]))] = s.parent
    return out


def _sweep_dirs(results: Path) -> list[Path]:
    return sorted((results / "slurm" / "hydra").glob("multirun-*/"))


def _jobs(sweep_dir: Path) -> dict[int, str]:
    """SLURM job id of each job of the sweep by Hydra's job number: submitit's folder of a job is named by its id,
    ``<array>_<index>`` in an array, ``<id>`` for a sweep of one job."""
    jobs = {}
    for p in (sweep_dir / ".submitit").glob("*/"):
        if (p / f"{p.name}_submitted.pkl").exists():
            jobs[int(p.name.split("_")[1]) if "_" in p.name else 0] = p.name
    return jobs


def _array_id(sweep_dir: Path) -> str | None:
    ids = {j.split("_")[0] for j in _jobs(sweep_dir).values()}
    assert len(ids) <= 1, ids
    return ids.pop() if ids else None


def _setting_of(sweep_dir: Path, task: int) -> tuple[int, float] | None:
    """(boards, noise mm) of the sweep's job ``task`` (Hydra's job number = the SLURM array index)."""
    f = sweep_dir / str(task) / ".hydra" / "overrides.yaml"
    if not f.exists():
        return None
    kv = dict(line[2:].split("=", 1) for line in f.read_text().splitlines() if line.startswith("- "))
    return int(kv["scene.n_boards"]), float(kv["noise.noise_mm"])


def _squeue(array: str) -> list[tuple[str, str]]:
    out = subprocess.run(["squeue", "-h", "-r", "-j", array, "-o", "%i %T"], capture_output=True, text=True)
    return [tuple(ln.split()) for ln in out.stdout.splitlines() if ln.strip()]


def _sacct(array: str) -> dict[str, tuple[str, str]]:
    out = subprocess.run(["sacct", "-n", "-X", "-P", "-j", array, "-o", "JobID,State,NodeList"],
                         capture_output=True, text=True, check=True)
    return {j: (s.split()[0], n) for j, s, n in (ln.split("|") for ln in out.stdout.splitlines() if ln)}


def _cancel_midway(proc: subprocess.Popen, results: Path, timeout_s: float = 180.0) -> tuple[str, str, Path]:
    """Wait until the running job's cell holds 1..CANCEL_AT_MOST chunks, scancel the job."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        assert proc.poll() is None, "the sweep finished before its job could be cancelled"
        dirs = _sweep_dirs(results)
        array = _array_id(dirs[-1]) if dirs else None
        cells = _cells(results) if array else {}
        for job, state in _squeue(array) if array else []:
            setting = _setting_of(dirs[-1], int(job.split("_")[1]) if "_" in job else 0)
            if state == "RUNNING" and setting in cells:
                if 0 < len(list(cells[setting].glob("chunk-*.csv"))) <= CANCEL_AT_MOST:
                    subprocess.run(["scancel", job], check=True)
                    return array, job, cells[setting]
        time.sleep(0.05)
    raise AssertionError(f"no job caught mid-way in {timeout_s:.0f} s")


def _final_states(array: str, expected: set[str] | None = None,
                  timeout_s: float = 120.0) -> dict[str, tuple[str, str]]:
    """sacct's (state, node) of each job of ``array`` once every one has left squeue and ended in sacct (a job
    whose task has returned its result may still be running or completing for a moment), and once every job of
    ``expected`` is listed there (slurmdbd records a job a moment after it ends)."""
    t0 = time.monotonic()
    while True:
        states = {} if _squeue(array) else _sacct(array)
        ended = states and not {s for s, _ in states.values()} & {"PENDING", "RUNNING", "COMPLETING", "REQUEUED"}
        if ended and (expected is None or expected <= set(states)):
            return states
        assert time.monotonic() - t0 < timeout_s, f"jobs of {array} not ended after {timeout_s:.0f} s: {states}"
        time.sleep(0.5)


def _check_slurm_jobs(sweep_dir: Path, n_jobs: int, states: dict[str, tuple[str, str]]) -> None:
    """Every job of the sweep is a SLURM job: in sacct, run on a node of sinfo, with submitit's logs named by its
    SLURM job id and its task started under that job id."""
    nodes = subprocess.run(["sinfo", "-h", "-o", "%N"], capture_output=True, text=True).stdout.split()
    jobs = _jobs(sweep_dir)
    assert sorted(jobs) == list(range(n_jobs)), f"submitit job folders under {sweep_dir}: {jobs}"
    for job in jobs.values():
        assert job in states, f"{job} not in sacct: {states}"
        assert states[job][1] in nodes, f"{job} ran on {states[job][1]!r}, not a node of sinfo {nodes}"
        log = sweep_dir / ".submitit" / job / f"{job}_0_log.out"
        assert log.exists(), f"no submitit log named by the SLURM job id: {log}"
        assert f"JobEnvironment(job_id={job}," in log.read_text(), f"{log}: not run as SLURM job {job}"


def _run(cmd: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=300)


def _unique_rows(results: Path, sweep: dict) -> pd.DataFrame:
    rows = _rows(results)
    keys = list(zip(rows["setting_key"], rows["trial"], rows["method"], strict=True))
    assert len(keys) == len(set(keys)), "a (setting, trial, method) row written twice"
    n = len(sweep["boards"]) * len(sweep["noises"]) * sweep["n_trials"] * len(METHODS)
    assert len(rows) == n, f"{len(rows)} rows stored, {n} expected: rows lost"
    return rows


def test_slurm_sweep_rows_equal_the_local_sweep(tmp_path):
    local, remote = tmp_path / "local", tmp_path / "slurm"
    ran = _run(_command(local, SWEEP, "n_jobs=1"))
    assert ran.returncode == 0, ran.stderr[-2000:]
    ran = _run(_command(remote, SWEEP, *SLURM))
    assert ran.returncode == 0, ran.stderr[-2000:]
    [sweep_dir] = _sweep_dirs(remote)
    states = _final_states(_array_id(sweep_dir), expected=set(_jobs(sweep_dir).values()))
    n_jobs = len(SWEEP["boards"]) * len(SWEEP["noises"])
    assert sorted(states) == sorted(_jobs(sweep_dir).values()), states
    assert {s for s, _ in states.values()} == {"COMPLETED"}, states
    _check_slurm_jobs(sweep_dir, n_jobs, states)
    got, want = _unique_rows(remote, SWEEP), _unique_rows(local, SWEEP)
    pd.testing.assert_frame_equal(got.drop(columns=list(TIMING)), want.drop(columns=list(TIMING)), check_exact=True)


def test_slurm_job_cancelled_midway_resumes_without_loss_or_duplicates(tmp_path):
    log = (tmp_path / "first.log").open("w")
    first = subprocess.Popen(_command(tmp_path, CANCEL, *SLURM), cwd=ROOT, env=_env(), stdout=log,
                             stderr=subprocess.STDOUT)
    try:
        array, cancelled, cell = _cancel_midway(first, tmp_path)
        first.wait(timeout=300)
    finally:
        if first.poll() is None:
            first.kill()
    states = _final_states(array, expected={cancelled})
    assert states[cancelled][0] == "CANCELLED", states
    _check_slurm_jobs(_sweep_dirs(tmp_path)[0], 1, states)
    kept = {f.name: f.stat().st_mtime_ns for f in cell.glob("chunk-*.csv")}
    n_chunks = CANCEL["n_trials"] // CANCEL["chunk_size"]
    assert 0 < len(kept) < n_chunks, f"{cell.name}: {len(kept)} of {n_chunks} chunks when killed, nothing to resume"
    assert first.returncode != 0, "the launcher should report the cancelled job"
    assert f"Job {cancelled}" in (tmp_path / "first.log").read_text(), "the launcher does not name the cancelled job"

    again = _run(_command(tmp_path, CANCEL, *SLURM))
    assert again.returncode == 0, again.stderr[-2000:]
    second = _sweep_dirs(tmp_path)[-1]
    rerun = _final_states(_array_id(second), expected=set(_jobs(second).values()))
    assert {s for s, _ in rerun.values()} == {"COMPLETED"}, rerun
    _check_slurm_jobs(second, 1, rerun)
    assert {f.name: f.stat().st_mtime_ns for f in cell.glob("chunk-*.csv") if f.name in kept} == kept, \
        "the rerun rewrote rows the cancelled job had stored"
    _unique_rows(tmp_path, CANCEL)
