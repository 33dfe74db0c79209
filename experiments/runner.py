"""The Monte-Carlo runner: one simulated problem per trial, every configured method run on that same data,
one long-format row per trial x method, written per chunk of trials as the chunks finish.

Results of one setting ("cell") live in ``<results_dir>/<sweep>/trials/<setting-key>/``: ``settings.json``
and ``chunk-<first>-<last>-<methods>.csv`` files, each written whole (temporary file, then rename). The
setting key hashes everything that changes a row except the trial count and the method list, so re-running
an interrupted sweep with the same settings computes only the (trial, method) pairs no file holds yet, more
trials extend a cell, and an added method runs on the old trials. Data are seeded by ``(seed, trial,
settings)`` inside the simulator, so the table does not depend on chunking, worker count or order.

A bad draw never kills a cell: an exception from the simulator or a method becomes rows with ``ok=False``
and the reason (a ``CalibrationError`` -- unknown method or option -- is a configuration error and raised).
"""

from __future__ import annotations

import hashlib
import importlib
import json
import math
import os
import re
import socket
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from calib_core import CalibrationError, calibrate, get_method
from calib_core.entry import is_seed_method
from calib_core.geometry.metrics import (
    TRUTH_MAX_ROT_DEG,
    TRUTH_MAX_TRANS_M,
    VALID_MAX_ROT_DEG,
    VALID_MAX_TRANS_M,
    is_valid,
    nees,
    pose_errors,
)
from calib_core.plugins import load_plugins
from calib_core.refine.joint import corner_residuals, joint_crlb
from calib_core.refine.uncertainty import conditioning, crlb
from simulate.options import hashed_settings

THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")

# Columns of a trial row after the settings columns (sweep, setting_key, seed, every SimOptions field).
RESULT_COLUMNS = (
    "trial", "method", "ok", "reason", "e_R_deg", "e_t_m", "valid", "n_candidates", "true_among_candidates",
    "some_candidate_valid", "best_candidate_e_R_deg", "best_candidate_e_t_m", "seconds",
    "crlb_rot_deg", "crlb_trans_mm", "conditioning", "nees", "sigma_rot_deg", "sigma_trans_mm",
    "n_wrong", "n_rejected", "wrong_caught", "good_lost",
)
# Columns that legitimately differ between two runs of the same settings (wall time).
TIMING_COLUMNS = ("seconds",)


class RunnerError(RuntimeError):
    """A sweep cannot run (bad settings, unreadable results folder)."""


def _default_metrics() -> dict[str, Any]:
    return {"max_rot_deg": VALID_MAX_ROT_DEG, "max_trans_m": VALID_MAX_TRANS_M, "truth_rot_deg": TRUTH_MAX_ROT_DEG,
            "truth_trans_m": TRUTH_MAX_TRANS_M,
            "uncertainty": True, "crlb_sigma_mm": None}


@dataclass(frozen=True)
class Cell:
    """One setting of a sweep: simulator options, seed, trial count, methods and metric thresholds.

    ``sim`` holds ``simulate.SimOptions`` fields as plain values; ``method_options`` maps a method name to
    its ``calibrate`` keyword options; ``plugins`` are modules every worker imports before running (their
    methods join the registry; ``calib_core.plugins``). Neither the plugins nor the method list change the key.
    ``crn_stream``: common random numbers -- trial ``t`` draws the same random numbers in every cell with the
    same stream (``simulate.trial_rngs``); None: seeded by the settings.
    """

    sweep: str
    sim: dict[str, Any]
    seed: int = 0
    n_trials: int = 100
    methods: tuple[str, ...] = ()
    method_options: dict[str, dict[str, Any]] = field(default_factory=dict)
    metrics: dict[str, Any] = field(default_factory=_default_metrics)
    results_dir: str = "results"
    plugins: tuple[str, ...] = ()
    crn_stream: int | None = None

    @property
    def key(self) -> str:
        """Readable, stable folder name: board count, noise, and a hash of every setting that shapes a row."""
        payload = json.dumps({"sim": hashed_settings(self.sim), "seed": self.seed, "metrics": self.metrics,
                              "method_options": {m: self.method_options[m] for m in sorted(self.method_options)},
                              **({} if self.crn_stream is None else {"crn_stream": self.crn_stream})},
                             sort_keys=True, default=str)
        digest = hashlib.sha1(payload.encode()).hexdigest()[:10]
        parts = [f"nb{self.sim['n_boards']}" if "n_boards" in self.sim else "",
                 f"noise{self.sim['noise_mm']:g}mm" if "noise_mm" in self.sim else ""]
        return "-".join([p for p in parts if p] + [digest])

    @property
    def dir(self) -> Path:
        return Path(self.results_dir) / self.sweep / "trials" / self.key

    def columns(self) -> dict[str, Any]:
        """The settings columns every row of this cell carries."""
        return {"sweep": self.sweep, "setting_key": self.key, "seed": self.seed, **self.sim}

    def options_for(self, method: str) -> dict[str, Any]:
        return dict(self.method_options.get(method, {}))


def resolve_methods(names: Iterable[str]) -> tuple[str, ...]:
    """``names``, each registered or derivable (``X+ml``): CalibrationError otherwise."""
    out = [get_method(n).name for n in names]
    if not out:
        raise RunnerError("no method to run")
    return tuple(out)


# ----------------------------------------------------------------------------------------------- trials

def _failure_row(base: dict, method: str, reason: str) -> dict:
    return {**base, "method": method, "ok": False, "reason": reason, "e_R_deg": np.nan, "e_t_m": np.nan,
            "valid": False, "n_candidates": 0, "true_among_candidates": False, "some_candidate_valid": False,
            "best_candidate_e_R_deg": np.nan, "best_candidate_e_t_m": np.nan, "seconds": np.nan,
            "nees": np.nan, "sigma_rot_deg": np.nan, "sigma_trans_mm": np.nan}


def evaluate(result, T_true: np.ndarray, metrics: dict[str, Any]) -> dict[str, Any]:
    """The metric columns of one ``CalibrationResult`` against the true ``T_lidar_cam``."""
    row: dict[str, Any] = {"ok": bool(result.ok), "reason": result.reason or "", "seconds": float(result.seconds),
                           "n_candidates": result.n_candidates, "e_R_deg": np.nan, "e_t_m": np.nan,
                           "valid": False, "true_among_candidates": False, "some_candidate_valid": False,
                           "best_candidate_e_R_deg": np.nan, "best_candidate_e_t_m": np.nan,
                           "nees": np.nan, "sigma_rot_deg": np.nan, "sigma_trans_mm": np.nan}
    if result.ok:
        e_R, e_t = pose_errors(result.T_lidar_cam, T_true)
        row.update(e_R_deg=float(e_R), e_t_m=float(e_t),
                   valid=bool(is_valid(e_R, e_t, metrics["max_rot_deg"], metrics["max_trans_m"])))
        if result.covariance is not None:
            row.update(nees=nees(result.T_lidar_cam, T_true, result.covariance),
                       sigma_rot_deg=result.sigma_rot_deg, sigma_trans_mm=result.sigma_trans_mm)
    if result.n_candidates:
        cR, ct = pose_errors(result.candidates, T_true)
        best = int(np.nanargmin(cR)) if np.isfinite(cR).any() else 0
        row.update(best_candidate_e_R_deg=float(cR[best]), best_candidate_e_t_m=float(ct[best]),
                   true_among_candidates=bool(np.any((cR < metrics["truth_rot_deg"])
                                                     & (ct < metrics["truth_trans_m"]))),
                   some_candidate_valid=bool(np.any(is_valid(cR, ct, metrics["max_rot_deg"],
                                                             metrics["max_trans_m"]))))
    return row


def rejection_columns(result, wrong_boards: Sequence[int]) -> dict[str, Any]:
    """Boards the method left out: how many (NaN for methods that do not report it, or when it failed), how many
    of the simulated wrong boards it caught, how many good boards it lost."""
    out: dict[str, Any] = {"n_wrong": len(wrong_boards), "n_rejected": np.nan, "wrong_caught": np.nan,
                           "good_lost": np.nan}
    if result.ok and result.boards_used is not None:
        rej = {int(r["index"]) for r in result.boards_rejected}
        wrong = {int(i) for i in wrong_boards}
        out.update(n_rejected=len(rej), wrong_caught=len(rej & wrong), good_lost=len(rej - wrong))
    return out


def corner_sigma_px(obs, sim: dict) -> float | None:
    """The corner noise std (px) of a simulated trial with image corners: ``pixel_noise_px`` in ``pixel`` mode, the
    RMS detection error against the true poses in ``image`` mode; None without corners or true poses."""
    if not obs.has_corners or "T_cam_board_true" not in obs.meta:
        return None
    from simulate import SimOptions

    o = SimOptions(**sim)
    if o.pose_mode == "pixel":
        return o.pixel_noise_px
    e = corner_residuals(obs, np.asarray(obs.meta["T_cam_board_true"], float))
    return float(np.sqrt(np.mean(e**2)))


def uncertainty_columns(obs, cell: Cell) -> dict[str, float]:
    """CRLB of the rotation (deg) and translation (mm) at the trial's noise, and the conditioning number.

    With image corners the bound is that of the joint model (range and corner noise, board poses unknown, at the
    true poses; ``corner_sigma_px``), else that of the range model (board poses exact)."""
    out = {"crlb_rot_deg": np.nan, "crlb_trans_mm": np.nan, "conditioning": np.nan}
    if not cell.metrics.get("uncertainty", True):
        return out

    sigma_mm = cell.metrics.get("crlb_sigma_mm")
    sigma_mm = cell.sim.get("noise_mm", 0.0) if sigma_mm is None else sigma_mm
    try:
        px = corner_sigma_px(obs, cell.sim)
        if px is None:
            bound = crlb(obs, range_sigma_m=float(sigma_mm) / 1000.0)
        else:
            bound = joint_crlb(obs, float(sigma_mm) / 1000.0, px, T_cam_board=np.asarray(obs.meta["T_cam_board_true"]))
        out.update(crlb_rot_deg=float(bound.rot_rms_deg), crlb_trans_mm=1000.0 * float(bound.trans_rms_m))
    except Exception:  # noqa: BLE001 -- a degenerate board set has no bound: NaN, not a dead cell
        pass
    try:
        out["conditioning"] = float(conditioning(obs))
    except Exception:  # noqa: BLE001
        pass
    return out


def simulate_trial(cell: Cell, trial: int, methods: Sequence[str]) -> list[dict[str, Any]]:
    """Simulate trial ``trial`` of ``cell`` once and run every method in ``methods`` on it: one row each."""
    from simulate import SimOptions, generate

    base = {**cell.columns(), "trial": int(trial), "crlb_rot_deg": np.nan, "crlb_trans_mm": np.nan,
            "conditioning": np.nan, "n_wrong": 0, "n_rejected": np.nan, "wrong_caught": np.nan, "good_lost": np.nan}
    try:
        obs = generate(SimOptions(**cell.sim), seed=cell.seed, trial=int(trial), stream=cell.crn_stream)
    except Exception as exc:  # noqa: BLE001 -- a bad draw is a status, not a crash
        return [_failure_row(base, m, f"simulate: {type(exc).__name__}: {exc}") for m in methods]
    base.update(uncertainty_columns(obs, cell))
    rows = []
    for m in methods:
        try:
            # the verdict decides ok for our methods; for the paper's it is a warning no column reads
            res = calibrate(obs, m, verdict=not is_seed_method(m), **cell.options_for(m))
        except CalibrationError:
            raise  # unknown method or option: the configuration is wrong, every trial would fail
        except Exception as exc:  # noqa: BLE001
            rows.append(_failure_row(base, m, f"error: {type(exc).__name__}: {exc}"))
            continue
        rows.append({**base, "method": m, **evaluate(res, obs.T_lidar_cam_true, cell.metrics),
                     **rejection_columns(res, obs.meta.get("wrong_boards", []))})
    return rows


TrialFn = Callable[[Cell, int, Sequence[str]], list[dict[str, Any]]]


def _run_chunk(trial_fn: TrialFn, cell: Cell, trials: Sequence[int], methods: Sequence[str],
               search_path: Sequence[str] = ()):
    """One chunk of trials. ``search_path`` is the parent's ``sys.path``: a reused worker may have started
    before a plugin's folder joined it, so the worker takes the parent's path before loading the plugins."""
    missing = [p for p in search_path if p not in sys.path]
    if missing:
        sys.path[:0] = missing
        importlib.invalidate_caches()
    load_plugins(cell.plugins)  # a worker process starts with the package's methods only (idempotent)
    rows = []
    for t in trials:
        rows.extend(trial_fn(cell, t, methods))
    return cell, tuple(trials), tuple(methods), rows


# ------------------------------------------------------------------------------------------------ files

def read_table(path: Path, text_columns: Sequence[str] = ("reason",)) -> pd.DataFrame:
    """A CSV table whose ``text_columns`` read back as strings ("" where empty, even when all are empty)."""
    df = pd.read_csv(path)
    for col in text_columns:
        if col in df:
            df[col] = df[col].astype(object).where(df[col].notna(), "").astype(str)
    return df


class DamagedChunk(RunnerError):
    """A chunk file that does not parse in full (empty, cut mid-row, junk): never read in part."""


_CHUNK_NAME = re.compile(r"^chunk-(\d{5,})-(\d{5,})-([0-9a-f]{6})\.csv$")


def _read_chunk(path: Path) -> pd.DataFrame:
    """The rows of one chunk file, checked in full: the header has the result columns; every (trial, method) of
    the name's trial range and of the methods whose hash the name carries appears exactly once; trial, method,
    ok and valid are well-formed in every row. DamagedChunk otherwise."""
    def damaged(why: str) -> DamagedChunk:
        return DamagedChunk(f"{path}: damaged chunk file ({why})")

    m = _CHUNK_NAME.match(path.name)
    if not m:
        raise damaged("name is not chunk-<first>-<last>-<methods hash>.csv")
    try:
        df = read_table(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, ValueError) as exc:
        raise damaged(f"does not parse: {str(exc).splitlines()[0][:120]}") from None
    missing = [c for c in RESULT_COLUMNS if c not in df.columns]
    if missing:
        raise damaged(f"missing columns {missing[:4]}")
    first, last = int(m.group(1)), int(m.group(2))
    trial = pd.to_numeric(df["trial"], errors="coerce")
    if trial.isna().any() or not (trial == trial.round()).all():
        raise damaged("a trial number that is not an integer")
    if df["method"].isna().any() or not df["method"].map(lambda v: isinstance(v, str) and v != "").all():
        raise damaged("a row without a method")
    methods = list(dict.fromkeys(df["method"]))
    tag = hashlib.sha1(",".join(methods).encode()).hexdigest()[:6]
    for col in ("ok", "valid"):
        if not df[col].map(lambda v: str(v) in ("True", "False")).all():
            raise damaged(f"a row whose {col!r} is not True/False")
    want = {(t, mm) for t in range(first, last + 1) for mm in methods}
    got = list(zip(trial.astype(int), df["method"], strict=True))
    if tag != m.group(3) or len(got) != len(set(got)) or set(got) != want:
        raise damaged(f"{len(got)} rows, expected {(last - first + 1)} trials x the methods of hash {m.group(3)}")
    df["trial"] = trial.astype(int)
    for col in ("ok", "valid"):
        df[col] = df[col].map(lambda v: str(v) == "True").astype(bool)
    return df


def verify_cell_dir(path: Path) -> list[str]:
    """Problems of the store of one cell (empty when sound): damaged chunk files, stray temporary files."""
    out = []
    for f in sorted(Path(path).glob("chunk-*.csv")):
        try:
            _read_chunk(f)
        except DamagedChunk as err:
            out.append(str(err))
    out += [f"{f}: temporary file left by an interrupted write" for f in sorted(Path(path).glob(".chunk-*.tmp"))]
    return out


def verify_store(results_dir: str | Path, sweep: str | None = None) -> list[str]:
    """Problems of every cell under ``results_dir`` (one sweep, or all): see ``verify_cell_dir``."""
    root = Path(results_dir)
    sweeps = [root / sweep] if sweep else sorted(p for p in root.iterdir() if (p / "trials").is_dir())
    return [msg for sw in sweeps for cell in sorted((sw / "trials").glob("*/")) for msg in verify_cell_dir(cell)]


def load_cell_dir(path: Path, heal: bool = False) -> pd.DataFrame:
    """Every row stored under one cell folder (duplicates of a (trial, method) pair dropped).

    A damaged chunk file raises DamagedChunk; with ``heal`` it is renamed ``<name>.damaged`` (so its trials are
    recomputed), reported on stderr, and left out whole.
    """
    frames = []
    for f in sorted(Path(path).glob("chunk-*.csv")):
        try:
            frames.append(_read_chunk(f))
        except DamagedChunk as err:
            if not heal:
                raise DamagedChunk(f"{err}; rerun the sweep to recompute it") from None
            os.replace(f, f.with_name(f.name + ".damaged"))
            sys.stderr.write(f"{err}: moved aside to {f.name}.damaged; its trials are recomputed\n")
    if not frames:
        return pd.DataFrame()
    df = pd.concat(frames, ignore_index=True)
    return df.drop_duplicates(["trial", "method"], keep="first")


def load_cell(cell: Cell) -> pd.DataFrame:
    """The rows of ``cell``: its trials ``0..n_trials-1`` and its methods, sorted by trial then method order."""
    df = load_cell_dir(cell.dir)
    if df.empty:
        return df
    df = df[(df["trial"] < cell.n_trials) & df["method"].isin(cell.methods)].copy()
    order = {m: i for i, m in enumerate(cell.methods)}
    df["_m"] = df["method"].map(order)
    return df.sort_values(["trial", "_m"]).drop(columns="_m").reset_index(drop=True)


def load_sweep(results_dir: str | Path, sweep: str) -> pd.DataFrame:
    """Every row stored for ``sweep`` under ``results_dir`` (all its cells)."""
    cells = sorted((Path(results_dir) / sweep / "trials").glob("*/"))
    frames = [load_cell_dir(c) for c in cells]
    frames = [f for f in frames if not f.empty]
    if not frames:
        raise RunnerError(f"no trials stored under {Path(results_dir) / sweep / 'trials'}")
    return pd.concat(frames, ignore_index=True)


def _tmp_name(path: Path) -> Path:
    """A hidden temporary name next to ``path``, unique per host and process (workers of a cluster share the store
    on one file system, where two hosts may run the same pid)."""
    return path.with_name(f".{path.name}.{socket.gethostname()}.{os.getpid()}.tmp")


def _write_atomic(df: pd.DataFrame, path: Path) -> None:
    """Write whole or not at all: a temporary file in the same folder, flushed to disk, then renamed."""
    tmp = _tmp_name(path)
    with open(tmp, "w", newline="") as fh:
        df.to_csv(fh, index=False, float_format="%.10g")
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _write_chunk(cell: Cell, trials: Sequence[int], methods: Sequence[str], rows: list[dict]) -> None:
    cols = list(cell.columns()) + list(RESULT_COLUMNS)
    df = pd.DataFrame(rows)
    df = df.reindex(columns=cols + [c for c in df.columns if c not in cols])  # a trial_fn may omit metric columns
    tag = hashlib.sha1(",".join(methods).encode()).hexdigest()[:6]
    _write_atomic(df, cell.dir / f"chunk-{min(trials):05d}-{max(trials):05d}-{tag}.csv")


def _prepare(cell: Cell) -> None:
    cell.dir.mkdir(parents=True, exist_ok=True)
    settings = cell.dir / "settings.json"
    if not settings.exists():
        d = asdict(cell)
        d.pop("n_trials"), d.pop("methods"), d.pop("results_dir"), d.pop("plugins")
        tmp = _tmp_name(settings)  # whole or absent: a worker killed mid-write must not leave half a file
        tmp.write_text(json.dumps({"key": cell.key, **d}, indent=1, sort_keys=True, default=str) + "\n")
        os.replace(tmp, settings)


def pending(cell: Cell, chunk_size: int) -> list[tuple[int, ...] | tuple]:
    """(trials, methods) tasks still to run for ``cell``: consecutive trials missing the same methods."""
    df = load_cell_dir(cell.dir, heal=True)
    done = set(zip(df["trial"], df["method"], strict=True)) if not df.empty else set()
    tasks: list[tuple[list[int], tuple[str, ...]]] = []
    for t in range(cell.n_trials):
        missing = tuple(m for m in cell.methods if (t, m) not in done)
        if not missing:
            continue
        if tasks and tasks[-1][1] == missing and len(tasks[-1][0]) < chunk_size and tasks[-1][0][-1] == t - 1:
            tasks[-1][0].append(t)
        else:
            tasks.append(([t], missing))
    return [(tuple(ts), ms) for ts, ms in tasks]


def auto_chunk_size(n_trials: int, n_workers: int) -> int:
    """Trials per task: about 8 tasks per worker, 5..25 trials (a trial takes milliseconds)."""
    return max(5, min(25, math.ceil(n_trials / max(1, 8 * n_workers))))


# ------------------------------------------------------------------------------------------------ runner

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
    for cell in cells:
        _prepare(cell)
    total_trials = sum(c.n_trials for c in cells)
    size = chunk_size if chunk_size > 0 else auto_chunk_size(total_trials, workers)
    tasks = [(cell, ts, ms) for cell in cells for ts, ms in pending(cell, size)]
    bar = _Progress(sum(len(ts) for _, ts, _ in tasks), label or ", ".join(sorted({c.sweep for c in cells})),
                    progress)
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
    finally:
        bar.close()
    frames = [load_cell(c) for c in cells]
    frames = [f for f in frames if not f.empty]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def _consume(results: Iterable, bar: _Progress) -> None:
    for cell, trials, methods, rows in results:
        _write_chunk(cell, trials, methods, rows)
        bar.update(len(trials))
