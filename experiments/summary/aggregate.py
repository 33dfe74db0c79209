"""Summary tables of the Monte-Carlo trials: per setting x method, the valid rate with its 95% Wilson
interval, mean/median errors, the share of trials with the truth among the candidates, timings.

    python -m experiments aggregate [--results results] [--out results/paper] [boards noise ...]

Writes ``<out>/summary_<sweep>.csv`` (one row per setting x method) and ``<out>/trials_<sweep>.csv`` (the
trial rows with the columns the figures and the notebook read; their wall times apart in ``timings_*.csv``, not
committed). A method that returned nothing counts as
invalid (it stays in ``n_trials``); error means and medians are over the trials where it returned a result.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..engine.catalog import method_order
from ..engine.cell import RESULT_COLUMNS, TIMING_COLUMNS, RunnerError
from ..engine.cli import study_parser
from ..engine.store import load_sweep, read_table
from .intervals import wilson_interval

# Settings that always label a row (the two the paper sweeps), and those never used to group.
LABEL_COLUMNS = ("n_boards", "noise_mm")
NON_SETTING = set(RESULT_COLUMNS) | {"sweep", "setting_key"}
TRIAL_TABLE_COLUMNS = ("sweep", "setting_key", "n_boards", "noise_mm", "trial", "method", "ok", "reason", "valid",
                       "e_R_deg", "e_t_m", "n_candidates", "true_among_candidates", "some_candidate_valid",
                       "best_candidate_e_R_deg", "best_candidate_e_t_m", "seconds", "crlb_rot_deg",
                       "crlb_trans_mm", "conditioning", "nees", "sigma_rot_deg", "sigma_trans_mm")


def setting_columns(df: pd.DataFrame) -> list[str]:
    """The settings that vary within ``df`` (plus the paper's two labels), in table order."""
    cols = [c for c in df.columns if c not in NON_SETTING]
    varying = [c for c in cols if df[c].nunique(dropna=False) > 1]
    return [c for c in cols if c in LABEL_COLUMNS or c in varying]


def nanmean(a, axis: int = -1):
    """Mean over ``axis`` of the non-NaN values; NaN where there is none (no warning). A 1-D input gives a float."""
    a = np.asarray(a, float)
    with np.errstate(invalid="ignore"):
        n = np.sum(~np.isnan(a), axis=axis)
        s = np.nansum(a, axis=axis)
        out = np.where(n > 0, s / np.maximum(n, 1), np.nan)
    return float(out) if out.ndim == 0 else out


def rms(x) -> float:
    """Root mean square of the finite values of ``x``; NaN when there is none."""
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2))) if len(x) else np.nan


def _top_reason(reasons: pd.Series) -> str:
    """The commonest failure reason, board and triple counts folded ("board 3:" -> "board k:")."""
    if reasons.empty:
        return ""
    folded = reasons.astype(str).str.replace(r"\bboard \d+", "board k", regex=True)
    folded = folded.str.replace(r"^\d+ triples", "k triples", regex=True).str.replace(r"\d+x ", "kx ", regex=True)
    return str(folded.value_counts().index[0])


def _efficiency(v: pd.DataFrame) -> dict[str, float]:
    """Over the valid trials ``v``: RMS errors, their ratio to the RMS of the CRLB (1 = efficient), and the mean and
    median NEES (6 = honest covariance)."""
    def col_rms(col):
        return rms(v[col]) if col in v else np.nan

    rms_R, rms_t = col_rms("e_R_deg"), 1000 * col_rms("e_t_m")
    nees = v["nees"].to_numpy(float) if "nees" in v else np.array([])
    nees = nees[np.isfinite(nees)]
    return {"rms_e_R_deg": rms_R, "rms_e_t_mm": rms_t,
            "rms_over_crlb_rot": rms_R / col_rms("crlb_rot_deg"),
            "rms_over_crlb_trans": rms_t / col_rms("crlb_trans_mm"),
            "mean_nees": float(nees.mean()) if len(nees) else np.nan,
            "median_nees": float(np.median(nees)) if len(nees) else np.nan}


def summarise(df: pd.DataFrame) -> pd.DataFrame:
    """One row per setting x method of the trial rows ``df`` (see the module docstring for the columns)."""
    if df.empty:
        raise ValueError("no trial rows to summarise")
    settings = setting_columns(df)
    keys = ["setting_key", *settings, "method"]
    rows = []
    for key, g in df.groupby(keys, sort=False, dropna=False):
        n = len(g)
        ok = g["ok"].astype(bool)
        valid = g["valid"].astype(bool)
        lo, hi = wilson_interval(int(valid.sum()), n)
        e_R, e_t = g.loc[ok, "e_R_deg"], g.loc[ok, "e_t_m"]
        rows.append({**dict(zip(keys, key, strict=True)),
                     "n_trials": n, "n_ok": int(ok.sum()), "n_failed": int((~ok).sum()), "n_valid": int(valid.sum()),
                     "valid_rate": valid.mean(), "valid_lo95": float(lo), "valid_hi95": float(hi),
                     "mean_e_R_deg": nanmean(e_R), "median_e_R_deg": float(e_R.median()) if len(e_R) else np.nan,
                     "mean_e_t_m": nanmean(e_t), "median_e_t_m": float(e_t.median()) if len(e_t) else np.nan,
                     "mean_e_R_valid_deg": nanmean(g.loc[valid, "e_R_deg"]),
                     "mean_e_t_valid_m": nanmean(g.loc[valid, "e_t_m"]),
                     "truth_among_rate": g["true_among_candidates"].astype(bool).mean(),
                     "some_candidate_valid_rate": g["some_candidate_valid"].astype(bool).mean(),
                     "mean_n_candidates": float(g["n_candidates"].mean()),
                     "median_seconds": float(g["seconds"].median()) if g["seconds"].notna().any() else np.nan,
                     "mean_crlb_rot_deg": nanmean(g["crlb_rot_deg"]),
                     "mean_crlb_trans_mm": nanmean(g["crlb_trans_mm"]),
                     **_efficiency(g.loc[valid]),
                     "median_conditioning": float(g["conditioning"].median()) if g["conditioning"].notna().any()
                     else np.nan,
                     "top_failure": _top_reason(g.loc[~ok, "reason"])})
    out = pd.DataFrame(rows)
    order = {m: i for i, m in enumerate(method_order(out["method"].unique()))}
    out = out.assign(_m=out["method"].map(order)).sort_values([*settings, "_m"]).drop(columns="_m")
    return out.reset_index(drop=True)


def trial_table(df: pd.DataFrame) -> pd.DataFrame:
    """The trial rows reduced to the columns the figures and the notebook read."""
    extra = [c for c in setting_columns(df) if c not in TRIAL_TABLE_COLUMNS]
    cols = [c for c in TRIAL_TABLE_COLUMNS if c in df.columns]
    return df[cols[:4] + extra + cols[4:]].reset_index(drop=True)


def constant_settings(df: pd.DataFrame) -> dict:
    """The settings that are the same in every row of ``df`` (the sweep's fixed assumptions); a missing value (an
    empty text setting read back from the store is NaN) is None, so ``settings_<sweep>.json`` is strict JSON."""
    cols = [c for c in df.columns if c not in NON_SETTING and df[c].nunique(dropna=False) == 1]
    return {c: None if pd.isna(v) else (v.item() if hasattr(v, "item") else v) for c, v in df[cols].iloc[0].items()}


SUMMARY_TIMING_COLUMNS = ("median_seconds",)
"""Summary columns of wall time: like ``TIMING_COLUMNS`` of the rows, they differ between two runs of the same code."""
TIMING_KEYS = ("sweep", "setting_key", "trial", "method")
"""The columns that name a row in ``timings_<sweep>.csv``."""


def write_summary(summary: pd.DataFrame, path: Path) -> Path:
    """Write a ``summarise`` table to ``path`` without its wall-time columns (``SUMMARY_TIMING_COLUMNS``), which go
    to ``timings_<name>`` beside it (not committed: a rerun of the same code rewrites ``path`` byte for byte)."""
    path = Path(path)
    timing = [c for c in SUMMARY_TIMING_COLUMNS if c in summary.columns]
    summary.drop(columns=timing).to_csv(path, index=False, float_format="%.6g")
    keys = [c for c in ("setting_key", "method") if c in summary.columns]
    summary[keys + timing].to_csv(path.with_name(f"timings_{path.name}"), index=False, float_format="%.6g")
    return path


def write_tables(df: pd.DataFrame, sweep: str, out_dir: str | Path) -> tuple[Path, Path]:
    """Write ``summary_<sweep>.csv``, ``trials_<sweep>.csv`` and ``settings_<sweep>.json`` (the fixed
    settings) of the trial rows ``df`` into ``out_dir``; returns the two tables' paths. The wall times
    (``TIMING_COLUMNS``, ``SUMMARY_TIMING_COLUMNS``) go to ``timings_trials_<sweep>.csv`` and
    ``timings_summary_<sweep>.csv`` instead (not committed: a rerun of the same code rewrites the others byte for
    byte)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    summary_path, trials_path = out / f"summary_{sweep}.csv", out / f"trials_{sweep}.csv"
    write_summary(summarise(df), summary_path)
    trials = trial_table(df)
    t_time = [c for c in TIMING_COLUMNS if c in trials.columns]
    trials.drop(columns=t_time).to_csv(trials_path, index=False, float_format="%.6g")
    keys = [c for c in TIMING_KEYS if c in trials.columns]
    trials[keys + t_time].to_csv(out / f"timings_{trials_path.name}", index=False, float_format="%.6g")
    (out / f"settings_{sweep}.json").write_text(json.dumps(constant_settings(df), indent=1, sort_keys=True) + "\n")
    return summary_path, trials_path


def load_settings(out_dir: str | Path, sweep: str) -> dict:
    path = Path(out_dir) / f"settings_{sweep}.json"
    return json.loads(path.read_text()) if path.exists() else {}


def _table(path: Path, text_columns: Sequence[str] = ("reason",)) -> pd.DataFrame:
    """A table this module wrote; RunnerError naming it when it is absent or does not parse."""
    if not path.is_file():
        raise RunnerError(f"{path}: no such table (the sweep's study writes it; "
                          f"{'is --tables the folder of its tables?' if not path.parent.is_dir() else 'run it first'})")
    try:
        return read_table(path, text_columns)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, ValueError) as exc:
        raise RunnerError(f"{path}: not a readable table ({str(exc).splitlines()[0][:120]})") from None


def load_summary(out_dir: str | Path, sweep: str) -> pd.DataFrame:
    return _table(Path(out_dir) / f"summary_{sweep}.csv", ("top_failure",))


def load_trials(out_dir: str | Path, sweep: str) -> pd.DataFrame:
    return _table(Path(out_dir) / f"trials_{sweep}.csv")


def main(argv: Sequence[str] | None = None) -> None:
    ap = study_parser(__doc__)
    ap.add_argument("sweeps", nargs="*", default=["boards", "noise"])
    ap.add_argument("--results", default="results", help="results folder of the runner (default: results)")
    ap.add_argument("--out", default=None, help="where the tables go (default: <results>/paper)")
    args = ap.parse_args(argv)
    out = args.out or str(Path(args.results) / "paper")
    for sweep in args.sweeps:
        paths = write_tables(load_sweep(args.results, sweep), sweep, out)
        print(" ".join(map(str, paths)))
