"""The benchmark on many cores: the automatic chunking of the paper's 1,200 trials keeps every worker busy to the
end (list scheduling of the tasks, longest first, ends within 10% of a perfect split of the work at 2-16 workers,
and 16 workers finish at least 1.6x sooner than 8), and the steps after the sweeps are skipped when nothing
changed (the same rows and code), redrawn when an output is missing."""

from __future__ import annotations

import heapq

import pytest

from experiments.config.sweeps import experiment_cells
from experiments.engine.runner import MAX_CHUNK, TASKS_PER_WORKER, auto_chunk_size, even_split, schedule, task_cost


@pytest.fixture(scope="module")
def paper_runs():
    cells = [c for e in ("boards", "noise") for c in experiment_cells(e, ["n_trials=100", "results_dir=unused"])]
    assert sum(c.n_trials for c in cells) == 1200
    return [(c, tuple(range(c.n_trials)), c.methods, None) for c in cells]


def makespan(tasks, workers: int) -> float:
    """Finish time of the tasks, in order, each to the first free worker (what a joblib pool with batch size 1
    does), the cost of a task being ``task_cost``."""
    free = [0.0] * workers
    for cell, ts, ms, _ in tasks:
        heapq.heappush(free, heapq.heappop(free) + task_cost(cell, ts, ms))
    return max(free)


@pytest.mark.parametrize("workers", [2, 4, 8, 16])
def test_the_paper_sweeps_keep_every_worker_busy(paper_runs, workers):
    tasks = schedule(paper_runs, 0, workers)
    assert sorted(t for _, ts, _, _ in tasks for t in ts) == sorted(t for _, ts, _, _ in paper_runs for t in ts)
    assert len(tasks) >= TASKS_PER_WORKER * workers or max(len(ts) for _, ts, _, _ in tasks) == MAX_CHUNK
    ideal = sum(task_cost(*t[:3]) for t in tasks) / workers
    assert makespan(tasks, workers) <= 1.10 * ideal


def test_sixteen_workers_finish_at_least_1_6x_sooner_than_eight(paper_runs):
    t8, t16 = (makespan(schedule(paper_runs, 0, w), w) for w in (8, 16))
    assert t8 / t16 >= 1.6, (t8, t16)


def test_a_cell_is_split_evenly_not_into_chunks_and_a_stub():
    parts = even_split(tuple(range(100)), auto_chunk_size(1200, 16))
    assert sorted({len(p) for p in parts}) in ([16, 17], [17]) and sum(map(len, parts)) == 100
    assert [t for p in parts for t in p] == list(range(100))
    assert even_split((5, 6, 7), 25) == [(5, 6, 7)]


def test_a_given_chunk_size_is_kept(paper_runs):
    from experiments.engine.store import pending

    cell = paper_runs[0][0]
    runs = [(cell, ts, ms, None) for ts, ms in pending(cell, 7)]
    assert schedule(runs, 7, 16) == runs


def test_the_steps_after_the_sweeps_are_skipped_when_nothing_changed(tmp_path):
    from experiments.paper.reproduce import reproduce

    kw = dict(trials=1, results_dir=str(tmp_path), n_jobs=1, experiments=("boards",), progress=False,
              overrides=["scene.n_boards=4", "methods.names=[zhang_pless_linear,peng2022]"])
    first = reproduce(**kw)
    out = first["out"]
    written = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()}
    assert first["redrawn"] and (out / "REPORT.md") in written and list((out / "figures").glob("*.png"))
    again = reproduce(**kw)
    assert not again["redrawn"]
    assert {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file()} == written
    png = sorted((out / "figures").glob("*.png"))[0]
    png.unlink()                                       # an output gone: everything is drawn again
    assert reproduce(**kw)["redrawn"] and png.exists()
    more = reproduce(**{**kw, "trials": 2})            # other rows: redrawn
    assert more["redrawn"]
