"""The robustness benchmark: wrong scan segments, gross outlier points and mixed pixels (``experiment=outliers``),
and the clean-data check of the default method (valid rate, RMS error over the CRLB, NEES at 3-8 boards).

    python -m experiments outliers [--trials 100] [--results results] [--n-jobs -1]
    python -m experiments outliers --clean [--trials 100]          # clean-data check only, printed

Writes ``<results>/outliers/``: the standard tables of ``experiments.summary.aggregate`` (``summary_outliers.csv``,
``trials_outliers.csv``), ``robustness_outliers.csv`` (per contamination x method, the columns below), the figure
``figures/outliers.png`` (and PDF) and ``REPORT.md``. "Accurate" is the robustness target's bound (1.5 deg and
80 mm); "valid" the paper's (8 deg, 0.8 m). For methods that reject boards: the share of the simulated wrong
boards caught, the share of trials naming every wrong board, and the share of trials losing a good board.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from lidarcam.rig.markdown import md_table, pct

from ..config.sweeps import experiment_cells
from ..engine.catalog import method_colour, method_label, method_order
from ..engine.cli import n_jobs, nonnegative_int, positive_int, study_parser
from ..engine.fingerprint import write_stamped
from ..engine.runner import run_cells
from ..engine.store import load_cell
from ..summary.aggregate import write_tables
from ..summary.figures import save_figure

ACCURATE_ROT_DEG = 1.5
ACCURATE_TRANS_M = 0.080


def case_label(row) -> str:
    """A readable name of a contamination setting."""
    parts = [f"{int(row['n_boards'])} boards"]
    if row.get("wrong_segments", 0):
        parts.append(f"{int(row['wrong_segments'])} wrong")
    if row.get("gross_outlier_frac", 0):
        parts.append(f"{100 * row['gross_outlier_frac']:g}% gross")
    if row.get("mixed_pixel_frac", 0):
        parts.append(f"{100 * row['mixed_pixel_frac']:g}% mixed")
    return ", ".join(parts) if len(parts) > 1 else parts[0] + ", clean"


def summarise_outliers(df: pd.DataFrame) -> pd.DataFrame:
    """One row per contamination setting x method."""
    rows = []
    keys = ["n_boards", "wrong_segments", "gross_outlier_frac", "mixed_pixel_frac", "method"]
    for key, g in df.groupby(keys, sort=False):
        d = dict(zip(keys, key, strict=True))
        ok = g["ok"].astype(bool)
        acc = ok & (g["e_R_deg"] < ACCURATE_ROT_DEG) & (g["e_t_m"] < ACCURATE_TRANS_M)
        rep = g[g["n_rejected"].notna()]
        wrong = rep["n_wrong"].sum()
        rows.append({"case": case_label(d), **d, "n_trials": len(g), "valid_rate": g["valid"].astype(bool).mean(),
                     "accurate_rate": acc.mean(), "median_e_R_deg": g.loc[ok, "e_R_deg"].median(),
                     "median_e_t_mm": 1000 * g.loc[ok, "e_t_m"].median(),
                     "wrong_caught_share": rep["wrong_caught"].sum() / wrong if len(rep) and wrong else np.nan,
                     "all_wrong_named_rate": (rep["wrong_caught"] == rep["n_wrong"]).mean()
                     if len(rep) and wrong else np.nan,
                     "good_lost_rate": (rep["good_lost"] > 0).mean() if len(rep) else np.nan})
    return pd.DataFrame(rows)


def draw(summary: pd.DataFrame, out: Path) -> list[Path]:
    """Grouped bars per contamination case: share of trials within 1.5 deg / 80 mm, and valid (8 deg / 0.8 m)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = list(dict.fromkeys(summary["case"]))
    methods = method_order(summary["method"].unique())
    fig, axes = plt.subplots(2, 1, figsize=(11, 6.5), sharex=True)
    w = 0.8 / len(methods)
    for ax, col, title in ((axes[0], "accurate_rate", f"within {ACCURATE_ROT_DEG} deg and "
                            f"{1000 * ACCURATE_TRANS_M:g} mm"), (axes[1], "valid_rate", "valid (8 deg, 0.8 m)")):
        for k, m in enumerate(methods):
            s = summary[summary["method"] == m].set_index("case").reindex(cases)[col]
            ax.bar(np.arange(len(cases)) + (k - (len(methods) - 1) / 2) * w, s.values, w, label=method_label(m),
                   color=method_colour(m))
        ax.set_ylabel("share of trials")
        ax.set_title(title, fontsize=10)
        ax.set_ylim(0, 1.05)
        ax.axhline(0.95, color="0.5", lw=0.8, ls="--")
    axes[1].set_xticks(np.arange(len(cases)), cases, rotation=25, ha="right", fontsize=8)
    axes[0].legend(fontsize=8, ncol=len(methods))
    fig.tight_layout()
    return save_figure(fig, out / "figures", "outliers", dpi=120)


def report(summary: pd.DataFrame, trials: int, command: str) -> str:
    """The REPORT section of the robustness benchmark (markdown)."""
    md = ["# Robustness: wrong boards, outlier points, mixed pixels", "",
          f"`{command}` (at least {trials} trials per setting, 20 mm range noise, exact camera poses). Wrong segment: "
          "another object's straight segment at a similar range in place of a board's scan; gross outliers: "
          "returns at 1-30 m within the board's bearing span; mixed pixels: beams just beyond the board ends, "
          "between the board and a background 0.2-3 m behind (`simulate/outliers.py`). Clean settings share their "
          "trials' geometry and noise with the contaminated ones.", "",
          "![robustness](figures/outliers.png)", ""]
    head = ["setting", "method", "trials", f"within {ACCURATE_ROT_DEG} deg / {1000 * ACCURATE_TRANS_M:g} mm", "valid",
            "median e_R (deg)", "median e_t (mm)", "wrong boards caught", "all wrong named",
            "trials losing a good board"]
    rows = [[r["case"], method_label(r["method"]), r["n_trials"], pct(r["accurate_rate"]), pct(r["valid_rate"]),
             f"{r['median_e_R_deg']:.2f}", f"{r['median_e_t_mm']:.0f}", pct(r["wrong_caught_share"]),
             pct(r["all_wrong_named_rate"]), pct(r["good_lost_rate"])] for _, r in summary.iterrows()]
    md += md_table(head, rows, "llrrrrrrrr")
    return "\n".join(md) + "\n"


def run(trials: int, results_dir: str, n_jobs: int, chunk_size: int = 0, compute: bool = True) -> Path:
    """Run the cells (``compute``; else only read what is stored), write the tables, figure and report."""
    cells = experiment_cells("outliers", [f"n_trials={trials}", f"results_dir={results_dir}"])
    if compute:
        run_cells(cells, n_jobs=n_jobs, chunk_size=chunk_size, label="outliers")
    df = pd.concat([load_cell(c) for c in cells], ignore_index=True)
    out = Path(results_dir) / "outliers"
    out.mkdir(parents=True, exist_ok=True)
    write_tables(df, "outliers", out)                     # the standard per-setting tables
    summary = summarise_outliers(df)
    summary.to_csv(out / "robustness_outliers.csv", index=False, float_format="%.6g")
    draw(summary, out)
    n = int(summary["n_trials"].min()) if len(summary) else 0
    write_stamped(out / "REPORT.md", report(summary, n, f"python -m experiments outliers --trials {trials}"))
    return out


def main(argv: Sequence[str] | None = None) -> None:
    ap = study_parser(__doc__)
    ap.add_argument("--trials", type=positive_int, default=100)
    ap.add_argument("--results", default="results")
    ap.add_argument("--n-jobs", type=n_jobs, default=-1)
    ap.add_argument("--clean", action="store_true", help="only the clean-data check (printed)")
    ap.add_argument("--chunk-size", type=nonnegative_int, default=0, help="trials per stored chunk (0: automatic)")
    ap.add_argument("--stored", action="store_true", help="only tabulate the trials already stored (no runs)")
    args = ap.parse_args(argv)
    if args.clean:
        from .clean_check import clean_check

        print(clean_check(args.trials).to_string(index=False, float_format=lambda x: f"{x:.3f}"))
        return
    out = run(args.trials, args.results, args.n_jobs, args.chunk_size, compute=not args.stored)
    print(f"wrote {out}/robustness_outliers.csv, {out}/figures/outliers.png, {out}/REPORT.md")
