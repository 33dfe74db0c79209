"""The paper's figures 3-7, re-drawn from the summary and trial tables of ``experiments.summary.aggregate``.

    python -m experiments figures [--tables results/paper] [boards noise ...]

Per sweep: valid-solution probability with 95% Wilson intervals (Fig. 3a / 3b), mean e_R and e_t
(Fig. 4 / 6) and box plots of e_R and e_t (Fig. 5 / 7), PNG and PDF, one fixed colour per method.
Errors are over the trials where a method returned a result; failures count only in Fig. 3.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from calib_core.geometry.metrics import VALID_MAX_ROT_DEG, VALID_MAX_TRANS_M  # noqa: E402

from ..engine.catalog import method_colour, method_label, method_order  # noqa: E402
from ..engine.cli import study_parser
from .aggregate import load_summary, load_trials  # noqa: E402


@dataclass(frozen=True)
class SweepFigures:
    """How one sweep is drawn: its x column and axis label, and the paper's figure names."""

    x: str
    xlabel: str
    valid: str
    mean: str
    box: str


PAPER_SWEEPS = {
    "boards": SweepFigures("n_boards", "Number of boards", "fig3a_valid_vs_boards", "fig4_mean_error_vs_boards",
                           "fig5_error_distribution_vs_boards"),
    "noise": SweepFigures("noise_mm", "Range noise std (mm)", "fig3b_valid_vs_noise", "fig6_mean_error_vs_noise",
                          "fig7_error_distribution_vs_noise"),
}
VALID_MAX_TRANS_MM = 1000 * VALID_MAX_TRANS_M


def sweep_figures(sweep: str, summary: pd.DataFrame) -> SweepFigures:
    """The paper's layout for ``boards``/``noise``; for another sweep, its first varying setting on x."""
    if sweep in PAPER_SWEEPS:
        return PAPER_SWEEPS[sweep]
    settings = [c for c in summary.columns[: list(summary.columns).index("method")] if c != "setting_key"]
    x = next((c for c in settings if summary[c].nunique() > 1), settings[0])
    return SweepFigures(x, x, f"{sweep}_valid", f"{sweep}_mean_error", f"{sweep}_error_distribution")


def save_figure(fig, out: Path, name: str, dpi: int = 150) -> list[Path]:
    """``<out>/<name>.png`` (at ``dpi``) and ``<out>/<name>.pdf``, trimmed to the drawing, the folder made if
    needed; the figure is closed. The one figure saver of the experiments."""
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{name}.png", out / f"{name}.pdf"]
    for p in paths:  # no creation date in the PDF: the same figure is the same file on a rerun
        fig.savefig(p, dpi=dpi if p.suffix == ".png" else None, bbox_inches="tight",
                    metadata={"CreationDate": None} if p.suffix == ".pdf" else None)
    plt.close(fig)
    return paths


def plot_valid(summary: pd.DataFrame, spec: SweepFigures, title: str):
    """Fig. 3: valid-solution probability (%) against the swept setting, Wilson 95% bars."""
    fig, ax = plt.subplots(figsize=(6, 4))
    methods = method_order(summary["method"].unique())
    width = 0.06 * (summary[spec.x].max() - summary[spec.x].min() or 1) / max(1, len(methods) - 1)
    for i, m in enumerate(methods):
        s = summary[summary["method"] == m].sort_values(spec.x)
        x = s[spec.x].to_numpy(float) + (i - (len(methods) - 1) / 2) * width  # dodge the bars
        y = 100 * s["valid_rate"].to_numpy(float)
        err = 100 * np.vstack([s["valid_rate"] - s["valid_lo95"], s["valid_hi95"] - s["valid_rate"]])
        ax.errorbar(x, y, yerr=np.clip(err, 0, None), marker="o", ms=4, capsize=2, color=method_colour(m),
                    label=method_label(m))
    ax.set(xlabel=spec.xlabel, ylabel="Valid-solution probability (%)", ylim=(-3, 103), title=title)
    ax.set_xticks(sorted(summary[spec.x].unique()))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    return fig


def plot_mean(summary: pd.DataFrame, spec: SweepFigures, title: str):
    """Fig. 4 / 6: mean e_R (deg) and mean e_t (mm) against the swept setting."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for m in method_order(summary["method"].unique()):
        s = summary[summary["method"] == m].sort_values(spec.x)
        kw = {"marker": "o", "ms": 4, "color": method_colour(m), "label": method_label(m)}
        axes[0].plot(s[spec.x], s["mean_e_R_deg"], **kw)
        axes[1].plot(s[spec.x], 1000 * s["mean_e_t_m"], **kw)
    axes[0].set(xlabel=spec.xlabel, ylabel="Mean rotation error $e_R$ (deg)")
    axes[1].set(xlabel=spec.xlabel, ylabel="Mean translation error $e_t$ (mm)")
    for ax in axes:
        ax.set_xticks(sorted(summary[spec.x].unique()))
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, loc="best")
    fig.suptitle(title)
    return fig


def plot_box(trials: pd.DataFrame, spec: SweepFigures, title: str):
    """Fig. 5 / 7: box plots of e_R (deg) and e_t (mm) per setting and method (log axis, validity line)."""
    ok = trials[trials["ok"].astype(bool)]
    xs = sorted(trials[spec.x].unique())
    methods = method_order(trials["method"].unique())
    fig, axes = plt.subplots(2, 1, figsize=(max(8, 1.4 * len(xs) * max(1, len(methods)) / 3), 7), sharex=True)
    step = 0.8 / len(methods)
    for ax, col, scale, limit, ylabel in ((axes[0], "e_R_deg", 1.0, VALID_MAX_ROT_DEG, "$e_R$ (deg)"),
                                          (axes[1], "e_t_m", 1000.0, VALID_MAX_TRANS_MM, "$e_t$ (mm)")):
        for j, m in enumerate(methods):
            data = [scale * ok[(ok["method"] == m) & (ok[spec.x] == x)][col].dropna().to_numpy() for x in xs]
            pos = np.arange(len(xs)) + (j - (len(methods) - 1) / 2) * step
            keep = [i for i, d in enumerate(data) if len(d)]
            if not keep:
                continue
            bp = ax.boxplot([data[i] for i in keep], positions=pos[keep], widths=0.9 * step, patch_artist=True,
                            showfliers=True, flierprops={"markersize": 2, "alpha": 0.5,
                                                         "markeredgecolor": method_colour(m)},
                            medianprops={"color": "black"})
            for patch in bp["boxes"]:
                patch.set(facecolor=method_colour(m), alpha=0.7)
            ax.plot([], [], "s", color=method_colour(m), label=method_label(m))
        ax.axhline(limit, color="grey", ls="--", lw=1, label="validity threshold")
        ax.set_yscale("log")
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3, axis="y")
    axes[1].set_xticks(np.arange(len(xs)), [f"{x:g}" for x in xs])
    axes[1].set_xlim(-0.5, len(xs) - 0.5)
    axes[1].set_xlabel(spec.xlabel)
    axes[0].legend(fontsize=7, ncol=min(4, len(methods) + 1), loc="upper right")
    fig.suptitle(title)
    return fig


def draw_sweep(tables_dir: str | Path, sweep: str, out_dir: str | Path | None = None) -> list[Path]:
    """Draw the three figures of ``sweep`` from ``<tables_dir>/{summary,trials}_<sweep>.csv``."""
    out = Path(out_dir or Path(tables_dir) / "figures")
    out.mkdir(parents=True, exist_ok=True)
    summary, trials = load_summary(tables_dir, sweep), load_trials(tables_dir, sweep)
    spec = sweep_figures(sweep, summary)
    n = int(summary["n_trials"].max())
    paths = save_figure(plot_valid(summary, spec, f"Valid-solution probability ({n} trials per point)"), out,
                        spec.valid)
    paths += save_figure(plot_mean(summary, spec, f"Mean errors of the returned solutions ({n} trials per point)"),
                         out, spec.mean)
    paths += save_figure(plot_box(trials, spec, "Error distributions of the returned solutions"), out, spec.box)
    return paths


def main(argv: Sequence[str] | None = None) -> None:
    ap = study_parser(__doc__)
    ap.add_argument("sweeps", nargs="*", default=["boards", "noise"])
    ap.add_argument("--tables", default="results/paper", help="folder of the summary/trial tables")
    ap.add_argument("--out", default=None, help="figure folder (default: <tables>/figures)")
    args = ap.parse_args(argv)
    for sweep in args.sweeps:
        for p in draw_sweep(args.tables, sweep, args.out):
            print(p)
