"""``make leaderboard``: every registered method (plugins included) on one fixed, versioned suite, one table.

    python -m experiments leaderboard [--suite conf/leaderboard/v3.yaml] [--full] [--trials N]
                                      [--methods a,b,...] [--results results] [--out results/leaderboard]
                                      [--n-jobs -1] [OVERRIDE ...]

The suite file names the suites and their trial counts (see ``conf/leaderboard/v3.yaml``): Hydra experiments
(``conf/experiment/<name>.yaml``, run with their own sweeps) and real observation files; a suite whose
config or files are absent is skipped with a line in the report. Every setting runs through the ordinary
runner in one process pool, into the same resumable store as the other experiments (``<results>/<sweep>/
trials/``), so trials already there are read back, not recomputed. Hydra overrides apply to every suite:
``methods.plugins=[my_lab.my_method]`` adds a plugin's methods, ``methods.names=[a,b]`` (or ``--methods``)
chooses the methods (default: every registered one). Writes ``<out>/REPORT.md``, ``leaderboard.csv`` (the
table), ``summary_<suite>.csv`` (per setting x method, ``experiments.summary.aggregate``) and ``leaderboard.png|pdf``.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
import yaml
from hydra import compose, initialize_config_dir
from hydra.errors import HydraException
from omegaconf import OmegaConf
from omegaconf.errors import OmegaConfBaseException

from calib_core import CalibrationError, calibrate, load_observations
from calib_core.data.io import OBS_SCHEMA
from calib_core.plugins import load_plugins
from calib_core.registry import METHODS, get_method

from ..config.overrides import check_overrides, composition_error, refuse_flag_overrides
from ..config.schema import register_configs
from ..config.sweeps import CONF_DIR, experiment_cells
from ..config.validate import ConfigError
from ..engine.cell import Cell, resolve_methods
from ..engine.cli import n_jobs, positive_int, study_parser
from ..engine.fingerprint import write_stamped
from ..engine.paths import repo_relative
from ..engine.runner import run_cells
from ..engine.store import load_cell
from ..engine.trial import evaluate
from ..summary.aggregate import summarise, write_summary
from .leaderboard_table import figure, leaderboard_table, markdown_table, real_table

DEFAULT_SUITE = CONF_DIR / "leaderboard" / "v3.yaml"
REAL_SWEEP = "leaderboard-real"


@dataclass(frozen=True)
class Suite:
    """One suite of the leaderboard: a Hydra ``experiment`` (``overrides`` fix some of its swept settings: a
    swept key given a single value leaves the sweep) or real observation files under ``path``."""

    name: str
    experiment: str | None = None
    trials: int = 20
    full_trials: int = 100
    crlb: bool = False
    overrides: tuple[str, ...] = ()
    path: str | None = None
    glob: str = "**/*.json"


def load_suites(path: str | Path) -> tuple[str, list[Suite]]:
    """The version and the suites of a leaderboard suite file; ConfigError naming the file and what is wrong
    (absent, not YAML text, not a mapping of suites, an unknown field)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: no such suite file (--suite)")
    try:
        d = OmegaConf.to_container(OmegaConf.load(path), resolve=True)
    except (UnicodeDecodeError, yaml.YAMLError, OmegaConfBaseException) as exc:
        raise ConfigError(f"{path}: not a YAML suite file ({' '.join(str(exc).split())[:120]})") from None
    if not isinstance(d, dict) or not isinstance(d.get("suites") or {}, dict):
        raise ConfigError(f"{path}: a suite file is a mapping with a 'suites' mapping (see {DEFAULT_SUITE.name})")
    suites = []
    fields = set(Suite.__dataclass_fields__) - {"name"}
    for k, v in (d.get("suites") or {}).items():
        if not isinstance(v, dict) or set(v) - fields:
            extra = sorted(set(v) - fields) if isinstance(v, dict) else v
            raise ConfigError(f"{path}: suite {k!r}: unknown field(s) {extra} (fields: {', '.join(sorted(fields))})")
        suites.append(Suite(name=str(k), **{**v, "overrides": tuple(v.get("overrides") or ())}))
    return str(d.get("version", "?")), suites


def chosen_methods(overrides: Sequence[str]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(methods, plugins): the plugins named by ``methods.plugins`` loaded (and the installed ones), then the
    methods a ``methods.names`` / ``methods=`` override chooses, or every registered method."""
    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        check_overrides(overrides, lambda choices: compose(config_name="config", overrides=choices), CONF_DIR)
        try:
            cfg = compose(config_name="config", overrides=list(overrides))
        except (HydraException, OmegaConfBaseException) as err:
            raise ConfigError(composition_error(err)) from None
    plugins = tuple(str(p) for p in cfg.methods.get("plugins", None) or ())
    load_plugins(plugins)
    keys = {o.split("=", 1)[0].lstrip("+~") for o in overrides}
    if keys & {"methods", "methods.names"}:
        return resolve_methods(cfg.methods.names), plugins
    return tuple(METHODS), plugins


def _names_override(methods: Sequence[str]) -> str:
    return "methods.names=[" + ",".join(f"'{m}'" for m in methods) + "]"


def real_files(suite: Suite) -> list[Path]:
    """The ``lidarcam.observations/1`` files of a real suite (other JSON files ignored), sorted."""
    out = []
    for f in sorted(Path(suite.path).glob(suite.glob)) if suite.path and Path(suite.path).is_dir() else []:
        try:
            if json.loads(f.read_text()).get("schema") == OBS_SCHEMA:
                out.append(f)
        except (OSError, ValueError, AttributeError):
            continue
    return out


def real_cell(path: Path, methods, plugins, results_dir: str) -> Cell:
    """One real observation file as a one-trial cell (its content hash in the key: an edited file reruns)."""
    sha = hashlib.sha1(path.read_bytes()).hexdigest()[:12]
    return Cell(sweep=REAL_SWEEP, sim={"data_file": str(path), "data_sha1": sha}, n_trials=1,
                methods=tuple(methods), results_dir=results_dir, plugins=tuple(plugins))


def real_trial(cell: Cell, trial: int, methods: Sequence[str]) -> list[dict]:
    """Every method on one real observation file; errors against its ``ground_truth`` (a reference) if any."""
    obs = load_observations(cell.sim["data_file"])
    rows = []
    for m in methods:
        row = {**cell.columns(), "trial": int(trial), "method": m, "has_reference": obs.T_lidar_cam_true is not None}
        try:
            res = calibrate(obs, m, **cell.options_for(m))
        except CalibrationError:
            raise
        except Exception as exc:  # noqa: BLE001 -- a method crashing on real data is a row, not a dead run
            rows.append({**row, "ok": False, "reason": f"error: {type(exc).__name__}: {exc}", "seconds": float("nan")})
            continue
        row.update(ok=bool(res.ok), reason=res.reason or "", seconds=float(res.seconds))
        if obs.T_lidar_cam_true is not None:
            row.update(evaluate(res, obs.T_lidar_cam_true, cell.metrics))
        rows.append(row)
    return rows


def plan(suites: Sequence[Suite], methods, plugins, overrides, results_dir: str, full: bool,
         trials: int | None) -> tuple[dict[str, list[Cell]], list[str]]:
    """The cells of every present suite, and a line for each suite skipped."""
    cells: dict[str, list[Cell]] = {}
    skipped = []
    for s in suites:
        if s.experiment is not None:
            if not (CONF_DIR / "experiment" / f"{s.experiment}.yaml").exists():
                skipped.append(f"{s.name}: skipped, conf/experiment/{s.experiment}.yaml is absent")
                continue
            n = trials or (s.full_trials if full else s.trials)
            cells[s.name] = experiment_cells(s.experiment, [f"n_trials={n}", f"results_dir={results_dir}",
                                                            _names_override(methods), *s.overrides, *overrides])
        else:
            files = real_files(s)
            if not files:
                skipped.append(f"{s.name}: skipped, no {OBS_SCHEMA} file under {s.path}/{s.glob}")
                continue
            cells[s.name] = [real_cell(f, methods, plugins, results_dir) for f in files]
    return cells, skipped


def _rows(cells: list[Cell]) -> pd.DataFrame:
    frames = [f for f in (load_cell(c) for c in cells) if not f.empty]
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def run_leaderboard(suite_file: str | Path = DEFAULT_SUITE, *, full: bool = False, trials: int | None = None,
                    overrides: Sequence[str] = (), results_dir: str = "results", out_dir: str | Path | None = None,
                    n_jobs: int = -1, progress: bool = True) -> dict:
    """Run the suites, write the table, figure and report; return paths, counts and timings."""
    t0 = time.perf_counter()
    version, suites = load_suites(suite_file)
    methods, plugins = chosen_methods(overrides)
    cells, skipped = plan(suites, methods, plugins, overrides, results_dir, full, trials)
    sim = [c for name, cs in cells.items() for c in cs if any(s.name == name and s.experiment for s in suites)]
    real = [c for c in (c for cs in cells.values() for c in cs) if c.sweep == REAL_SWEEP]
    unique = list({c.dir: c for cs in cells.values() for c in cs}.values())  # a setting two suites share: once
    before = sum(len(load_cell(c)) for c in unique)
    run_cells(sim, n_jobs=n_jobs, progress=progress, label="leaderboard")
    if real:
        run_cells(real, n_jobs=n_jobs, progress=progress, label="leaderboard real", trial_fn=real_trial)
    t_run = time.perf_counter() - t0
    rows = {name: _rows(cs) for name, cs in cells.items()}
    after = sum(len(load_cell(c)) for c in unique)
    out = Path(out_dir or Path(results_dir) / "leaderboard")
    out.mkdir(parents=True, exist_ok=True)
    crlb = {s.name for s in suites if s.crlb}
    sim_rows = {k: v for k, v in rows.items() if k not in {s.name for s in suites if not s.experiment}}
    origins = {m: get_method(m).origin for m in methods}
    table = leaderboard_table(sim_rows, crlb, origins)
    real_rows = {k: v for k, v in rows.items() if k not in sim_rows}
    for name, df in sim_rows.items():
        write_summary(summarise(df), out / f"summary_{name}.csv")
    table.to_csv(out / "leaderboard.csv", index=False, float_format="%.6g")
    if len(table):
        figure(table, list(sim_rows), out)
    info = {"version": version, "suite_file": repo_relative(suite_file), "methods": methods, "plugins": plugins,
            "skipped": skipped, "cells": {k: len(v) for k, v in cells.items()},
            "trials": {k: sorted({c.n_trials for c in v}) for k, v in cells.items()},
            "rows_computed": after - before, "rows": after, "run_s": t_run, "cores": os.cpu_count(),
            "load": os.getloadavg()[1],
            "full": full, "overrides": list(overrides), "real": sorted(real_rows),
            "suite_overrides": {s.name: list(s.overrides) for s in suites}}
    report = out / "REPORT.md"
    write_stamped(report, build_leaderboard_report(table, real_table(real_rows), info, crlb))
    return {"out": out, "report": report, **info, "total_s": time.perf_counter() - t0}


def _suite_text(name: str, info: dict) -> str:
    n = info["cells"][name]
    what = f"{n} files" if name in info["real"] else f"{n} settings x {'/'.join(map(str, info['trials'][name]))} trials"
    fixed = info["suite_overrides"].get(name)
    return f"`{name}` ({what}{', ' + ' '.join(fixed) if fixed else ''})"


def build_leaderboard_report(table: pd.DataFrame, real: pd.DataFrame | None, info: dict, crlb: set[str]) -> str:
    """The text of REPORT.md."""
    suites = ", ".join(_suite_text(k, info) for k in info["cells"]) or "none"
    lines = ["# Leaderboard (generated)", "",
             f"Generated by `python -m experiments leaderboard` from suite file `{info['suite_file']}` "
             f"(version {info['version']}{', full trial counts' if info['full'] else ', reduced trial counts'}); "
             "do not edit by hand.", "",
             f"- Suites run: {suites}.",
             *(f"- Suite {line}." for line in info["skipped"]),
             f"- Methods: {len(info['methods'])}"
             + (f"; plugins: {', '.join(f'`{p}`' for p in info['plugins'])}" if info["plugins"] else "") + ".",
             *([f"- Overrides: `{' '.join(info['overrides'])}`."] if info["overrides"] else []),
             f"- Timing of this run (differs between runs): {info['rows']} (trial, method) rows, "
             f"{info['rows_computed']} computed now and the rest read back from the store; {info['run_s']:.0f} s wall "
             f"on {info['cores']} cores (5-minute load average at the end {info['load']:.1f}: times grow when other "
             "processes share the cores).", "",
             "## One table over every simulated suite", "",
             "Ranked by valid rate, then median rotation error. *Valid*: e_R < 8 deg and e_t < 0.8 m; a method that "
             "returned nothing counts as invalid; [95% Wilson interval]. Medians are over the solutions returned, "
             "RMS over the valid ones. *RMS / CRLB* (rotation, translation): per setting, the RMS error of the valid "
             "trials over the RMS of the Cramer-Rao bound on the same trials (range noise; with image corners, the "
             "joint model's bound over ranges and corners) "
             "(`summary_<suite>.csv`), pooled over the settings of the suites where that bound applies "
             f"({', '.join(sorted(crlb)) or 'none'}) as a root mean square weighted by valid trials; 1 = efficient, "
             "below 1 only by chance or because invalid trials are left out. *NEES*: mean of e^T P^-1 e over valid "
             "trials, for methods that report a covariance P (6 when P is honest). *ms*: median wall time per call "
             "on this run's machine (`make bench` times methods alone).", ""]
    lines += [*markdown_table(table), "", "![leaderboard](leaderboard.png)", ""] if len(table) else [
        "No simulated suite ran.", ""]
    if real is not None and not real.empty:
        lines += ["## Real data", "",
                  "Every method on each real observation file. Without ground truth a real rig has no valid rate; "
                  "errors are against the file's reference extrinsic where it carries one.", ""]
        lines += markdown_table(real)
    return "\n".join(lines).rstrip() + "\n"


def main(argv: Sequence[str] | None = None) -> None:
    ap = study_parser(__doc__)
    ap.add_argument("overrides", nargs="*", help="Hydra overrides applied to every suite")
    ap.add_argument("--suite", default=str(DEFAULT_SUITE), help="suite file (default: %(default)s)")
    ap.add_argument("--full", action="store_true", help="full trial counts (the suite file's full_trials)")
    ap.add_argument("--trials", type=positive_int, help="trials per setting in every suite (overrides the suite file)")
    ap.add_argument("--methods", help="comma-separated methods (default: every registered one)")
    ap.add_argument("--results", default="results", help="results store (default: results)")
    ap.add_argument("--out", help="where the leaderboard goes (default: <results>/leaderboard)")
    ap.add_argument("--n-jobs", type=n_jobs, default=-1, help="worker processes (-1: all cores)")
    a = ap.parse_args(argv)
    refuse_flag_overrides(a.overrides, {"results_dir": "--results", "n_trials": "--trials"})
    overrides = list(a.overrides) + ([_names_override(a.methods.split(","))] if a.methods else [])
    r = run_leaderboard(a.suite, full=a.full, trials=a.trials, overrides=overrides, results_dir=a.results,
                        out_dir=a.out, n_jobs=a.n_jobs)  # a plugin that does not load: one line, exit 2 (run_main)
    for line in r["skipped"]:
        print(f"suite {line}")
    print(f"{len(r['methods'])} methods on {', '.join(r['cells']) or 'no suite'}: {r['rows_computed']} rows computed "
          f"in {r['run_s']:.1f} s ({r['total_s']:.1f} s with the report). Report: {r['report']}")
