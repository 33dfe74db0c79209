"""The Monte-Carlo runner: one simulated problem per trial, every configured method run on that same data,
one long-format row per trial x method, written per chunk of trials as the chunks finish.

Results of one setting ("cell", ``experiments.engine.cell``) live in ``<results_dir>/<sweep>/trials/<setting-key>/``
(``experiments.engine.store``). Re-running an interrupted sweep with the same settings computes only the (trial, method)
pairs no file holds yet, more trials extend a cell, and an added method runs on the old trials. Data are seeded by
``(seed, trial, settings)`` inside the simulator, so the table does not depend on chunking, worker count or order.
A trial (``experiments.engine.trial``) turns a bad draw into rows with ``ok=False`` and the reason.
"""

from __future__ import annotations

import importlib
import math
import os
import sys
import time
from collections.abc import Iterable, Sequence

import pandas as pd

from calib_core.plugins import load_plugins

from .cell import CODE_COLUMN, Cell, RunnerError
from .entry import SweepInterrupted
from .fingerprint import method_codes, refresh_plugins, rerun_message
from .store import load_cell, pending, prepare_cell, prune_stale, write_chunk
from .trial import TrialFn, simulate_trial

THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def _run_chunk(trial_fn: TrialFn, cell: Cell, trials: Sequence[int], methods: Sequence[str],
               codes: dict[str, str] | None = None, search_path: Sequence[str] = ()):
    """One chunk of trials, every row stamped with the fingerprint of the code that computed it. ``codes``: the
    parent's fingerprints; a worker running other code (started before an edit) refuses rather than mislabel
    rows. ``search_path`` is the parent's ``sys.path``: a reused worker may have started before a plugin's
    folder joined it, so the worker takes the parent's path before loading the plugins."""
    missing = [p for p in search_path if p not in sys.path]
    if missing:
        sys.path[:0] = missing
        importlib.invalidate_caches()
    load_plugins(cell.plugins)  # a worker process starts with the package's methods only (idempotent)
    refresh_plugins(cell.plugins)
    mine = method_codes(methods)
    if codes is not None and any(mine[m] != codes[m] for m in methods):
        diff = [f"{m}: {mine[m]} here, {codes[m]} in the parent" for m in methods if mine[m] != codes[m]]
        raise RunnerError(f"a worker process runs other code than the sweep ({'; '.join(diff)}): the code changed "
                          "while this process was running; start a new process")
    rows = []
    for t in trials:
        rows.extend({**r, CODE_COLUMN: mine[r["method"]]} for r in trial_fn(cell, t, methods))
    write_chunk(cell, trials, methods, rows)  # in the worker: the parent does not serialise the writes
    return cell, tuple(trials), tuple(methods)


TASKS_PER_WORKER = 4
"""The automatic chunking aims at this many tasks per worker at least (see ``auto_chunk_size``)."""
MAX_CHUNK = 25


def auto_chunk_size(n_trials: int, n_workers: int) -> int:
    """Trials per task: the pending trials spread over ``TASKS_PER_WORKER`` tasks per worker, 1..``MAX_CHUNK``
    (a trial takes tens of milliseconds; a task costs a few milliseconds more, and one file). With the largest
    tasks started first (``schedule``), the last wave is of the smallest tasks, so every worker stays busy to the
    end: the paper's 1,200 trials are 64 tasks of <= 19 trials on 16 workers, 48 tasks of <= 25 on 8."""
    return max(1, min(MAX_CHUNK, math.ceil(n_trials / max(1, TASKS_PER_WORKER * n_workers))))


def even_split(trials: Sequence[int], size: int) -> list[tuple[int, ...]]:
    """``trials`` (consecutive) cut into ceil(n / size) runs of equal length (+-1), not ``size``-runs and a stub."""
    n = len(trials)
    k = max(1, math.ceil(n / max(1, size)))
    bounds = [round(i * n / k) for i in range(k + 1)]
    return [tuple(trials[a:b]) for a, b in zip(bounds, bounds[1:], strict=False) if b > a]


def task_cost(cell: Cell, trials: Sequence[int], methods: Sequence[str]) -> float:
    """A task's expected cost, for ordering only: trials x methods x boards (the methods' work grows with the board
    count; the simulation is a small share)."""
    return len(trials) * len(methods) * float(cell.sim.get("n_boards", 6) or 6)


class _Progress:
    def __init__(self, total: int, label: str, enabled: bool) -> None:
        self.total, self.label, self.enabled = total, label, enabled and total > 0
        self.done, self.t0, self.shown = 0, time.perf_counter(), -1.0

    def update(self, n: int) -> None:
        self.done += n
        el = time.perf_counter() - self.t0
        if not self.enabled or (el - self.shown < 0.5 and self.done < self.total):
            return
        self.shown = el
        eta = el / self.done * (self.total - self.done) if self.done else float("nan")
        sys.stderr.write(f"\r{self.label}: {self.done}/{self.total} trials ({100 * self.done / self.total:3.0f}%)"
                         f"  {el:6.1f} s elapsed, ~{eta:5.1f} s left ")
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")


def n_workers(n_jobs: int) -> int:
    cpus = os.cpu_count() or 1
    return max(1, cpus + 1 + n_jobs if n_jobs < 0 else n_jobs)


def run_cells(cells: Sequence[Cell], *, n_jobs: int = -1, chunk_size: int = 0, progress: bool = True,
              trial_fn: TrialFn = simulate_trial, label: str | None = None) -> pd.DataFrame:
    """Run every missing (trial, method) pair of ``cells`` in one pool; return their rows, cells in order.

    Workers are joblib (loky) processes with one BLAS/OpenMP thread each; chunks of ``chunk_size`` trials
    (0: automatic) are the unit of work and of writing. ``n_jobs=1`` runs in this process.
    """
    workers = n_workers(n_jobs)
    label = label or ", ".join(sorted({c.sweep for c in cells}))
    codes, stale, why = _prune(cells)
    runs = [(cell, ts, ms, code) for cell, code in zip(cells, codes, strict=True)
            for ts, ms in pending(cell, chunk_size if chunk_size > 0 else MAX_CHUNK * 10**6)]
    tasks = schedule(runs, chunk_size, workers)
    todo = sum(len(ts) * len(ms) for _, ts, ms, _ in tasks)
    reused = sum(c.n_trials * len(c.methods) for c in cells) - todo
    if progress or reused or stale:
        print(f"{label}: {rerun_message(reused, stale, why, todo - sum(stale.values()))}", file=sys.stderr)
    bar = _Progress(sum(len(ts) for _, ts, _, _ in tasks), label, progress)
    try:
        if workers == 1 or len(tasks) <= 1:
            results: Iterable = (_run_chunk(trial_fn, *task) for task in tasks)
            _consume(results, bar)
        else:
            from joblib import Parallel, delayed, parallel_config

            for var in THREAD_VARS:  # the loky workers inherit these at start
                os.environ.setdefault(var, "1")
            with parallel_config(backend="loky", inner_max_num_threads=1):
                par = Parallel(n_jobs=workers, return_as="generator_unordered", batch_size=1)
                search_path = tuple(sys.path)
                _consume(par(delayed(_run_chunk)(trial_fn, *task, search_path) for task in tasks), bar)
    except KeyboardInterrupt:
        raise SweepInterrupted(f"interrupted after {bar.done} of {bar.total} trials; the same command resumes") \
            from None
    finally:
        bar.close()
    frames = [load_cell(c) for c in cells]
    frames = [f for f in frames if not f.empty]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def schedule(runs, chunk_size: int, workers: int) -> list[tuple]:
    """The tasks of the pending ``runs`` ((cell, consecutive trials missing the same methods, methods, codes)):
    with ``chunk_size`` > 0 the runs as ``pending`` cut them; automatic (0): each run split evenly by
    ``auto_chunk_size`` of the pending trials, then every task in decreasing ``task_cost`` (longest first)."""
    if chunk_size > 0:
        return list(runs)
    size = auto_chunk_size(sum(len(ts) for _, ts, _, _ in runs), workers)
    tasks = [(cell, part, ms, code) for cell, ts, ms, code in runs for part in even_split(ts, size)]
    return sorted(tasks, key=lambda t: -task_cost(t[0], t[1], t[2]))  # stable: equal costs keep their order


def _prune(cells: Sequence[Cell]):
    """Prepare every cell, take the current code fingerprints of its methods (plugins whose file changed are
    reloaded first) and remove the rows another code computed. Returns the fingerprints of each cell and the
    removed rows and their reasons per method."""
    stale: dict[str, int] = {}
    why: dict[str, set] = {}
    codes = []
    for cell in cells:
        prepare_cell(cell)
        load_plugins(cell.plugins)
        refresh_plugins(cell.plugins)
        codes.append(method_codes(cell.methods))
        removed, reasons = prune_stale(cell, codes[-1])
        for m, n in removed.items():
            stale[m] = stale.get(m, 0) + n
            why.setdefault(m, set()).update(reasons[m])
    return codes, {m: n for m, n in stale.items() if n}, why


def _consume(results: Iterable, bar: _Progress) -> None:
    for _cell, trials, _methods in results:
        bar.update(len(trials))
