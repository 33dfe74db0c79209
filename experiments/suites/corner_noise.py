"""Camera noise in the benchmark: the corner-noise sweep and the valid rate under camera noise, with the figure and the
REPORT section "Camera noise and the joint model".

    python -m experiments corner-noise [--trials 100] [--boards-trials 100] [--results results] [--n-jobs -1]
                                       [OVERRIDE ...]

Runs, through the ordinary runner in one process pool, the Hydra experiments ``conf/experiment/corner_noise.yaml``
(0, 0.25, 0.5, 1 px corner noise at 4, 6, 8 boards, 20 and 30 mm) and ``corner_boards.yaml`` (3-8 boards at 0.5 px,
20 mm). The observations carry the image corners (``pose_mode=pixel``), so the runner's CRLB columns are those of
the joint model (range and corner noise, board poses unknown) and its NEES column uses each method's reported
covariance. Writes into ``<results>/corner_noise/``: ``summary_*.csv`` / ``trials_*.csv``,
``figures/corner_noise.png|pdf``, ``figures/corner_boards.png|pdf`` and ``REPORT.md``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from lidarcam.rig.markdown import md_table, num  # noqa: E402

from ..config.overrides import refuse_flag_overrides
from ..config.sweeps import experiment_cells  # noqa: E402
from ..engine.catalog import PAPER_METHODS, method_colour, method_label, method_order  # noqa: E402
from ..engine.cli import n_jobs, positive_int, study_parser
from ..engine.fingerprint import write_stamped
from ..engine.runner import run_cells  # noqa: E402
from ..engine.store import load_cell  # noqa: E402
from ..summary.aggregate import summarise, write_tables  # noqa: E402
from ..summary.figures import save_figure  # noqa: E402

EXPERIMENTS = ("corner_noise", "corner_boards")
PX = "pixel_noise_px"


def camera_share(trials: pd.DataFrame) -> pd.DataFrame:
    """Per (boards, range noise, corner noise > 0, method): the share of the mean squared rotation and translation
    error that the camera adds, ``1 - MSE(0 px) / MSE(px)`` over valid trials (0 px: the same method, same settings,
    exact corners)."""
    v = trials[trials["valid"].astype(bool)]
    g = v.groupby(["n_boards", "noise_mm", PX, "method"])
    mse = pd.DataFrame({"mse_R": g["e_R_deg"].apply(lambda s: float(np.mean(s**2))),
                        "mse_t": g["e_t_m"].apply(lambda s: float(np.mean(s**2)))}).reset_index()
    base = mse[mse[PX] == 0].drop(columns=PX).rename(columns={"mse_R": "mse_R0", "mse_t": "mse_t0"})
    out = mse[mse[PX] > 0].merge(base, on=["n_boards", "noise_mm", "method"], how="left")
    out["camera_share_R"] = 1 - out["mse_R0"] / out["mse_R"]
    out["camera_share_t"] = 1 - out["mse_t0"] / out["mse_t"]
    return out


def draw_corner_noise(summary: pd.DataFrame, out: Path) -> Path:
    """RMS e_R / joint CRLB and mean NEES against corner noise, one column per board count (20 mm)."""
    s = summary[summary["noise_mm"] == summary["noise_mm"].min()]
    boards = sorted(s["n_boards"].unique())
    fig, ax = plt.subplots(3, len(boards), figsize=(4 * len(boards), 9), squeeze=False, sharex=True)
    for j, nb in enumerate(boards):
        for m in method_order(s["method"].unique()):
            g = s[(s["n_boards"] == nb) & (s["method"] == m)].sort_values(PX)
            kw = {"color": method_colour(m), "label": method_label(m), "marker": "o"}
            ax[0, j].plot(g[PX], 100 * g["valid_rate"], **kw)
            ax[1, j].plot(g[PX], g["rms_over_crlb_rot"], **kw)
            ax[2, j].plot(g[PX], g["mean_nees"], **kw)
        ax[0, j].set_title(f"{nb} boards, {s['noise_mm'].min():g} mm")
        ax[1, j].axhline(1.0, color="k", lw=0.8, ls=":")
        ax[2, j].axhline(6.0, color="k", lw=0.8, ls=":")
        ax[1, j].set_yscale("log")
        ax[2, j].set_yscale("log")
        ax[2, j].set_xlabel("corner noise std (px)")
    ax[0, 0].set_ylabel("valid solutions (%)")
    ax[1, 0].set_ylabel("RMS e_R / joint CRLB")
    ax[2, 0].set_ylabel("mean NEES (6 = honest)")
    ax[0, -1].legend(fontsize=7)
    return _save(fig, out, "corner_noise")


def draw_corner_boards(summary: pd.DataFrame, out: Path) -> Path:
    fig, ax = plt.subplots(figsize=(6, 4))
    for m in method_order(summary["method"].unique()):
        g = summary[summary["method"] == m].sort_values("n_boards")
        err = 100 * np.clip([g["valid_rate"] - g["valid_lo95"], g["valid_hi95"] - g["valid_rate"]], 0, None)
        ax.errorbar(g["n_boards"], 100 * g["valid_rate"], yerr=err, color=method_colour(m), label=method_label(m),
                    marker="o", capsize=2)
    ax.set_xlabel("number of boards")
    ax.set_ylabel("valid solutions (%)")
    ax.set_title("0.5 px corner noise, 20 mm range noise")
    ax.legend(fontsize=7)
    return _save(fig, out, "corner_boards")


def _save(fig, out: Path, name: str) -> Path:
    """The figure saved under ``out`` (``figures.save_figure``); its path relative to the report."""
    fig.tight_layout()
    save_figure(fig, out, name, dpi=120)
    return Path("figures") / f"{name}.png"


def noise_section(summary: pd.DataFrame, share: pd.DataFrame, fig: Path) -> list[str]:
    lines = ["## Camera noise and the joint model", "",
             "Board poses from noisy image corners (solvePnP), the corners in the observations. RMS / CRLB: RMS "
             "error over valid trials against the RMS of the per-trial Cramer-Rao bound of the joint model (range "
             "and corner noise, board poses unknown); 1 is efficient. NEES: mean of `e^T P^-1 e` with the "
             "method's reported covariance `P` (6 when honest; n/a: no covariance). Camera share: the part of the "
             "mean squared error that the corner noise adds, `1 - MSE(0 px) / MSE(px)` (sampling noise can make it "
             "negative). The RMS is over valid trials only, i.e. truncated at the validity thresholds, so at few "
             "boards a ratio below 1 reflects the truncation, not an estimator beating the bound.", "",
             f"![corner noise]({fig})", ""]
    key = ["n_boards", "noise_mm", PX, "method"]
    merged = summary.merge(share[key + ["camera_share_R", "camera_share_t"]], on=key, how="left")

    def f(v, spec=".2f"):
        return num(v, spec, missing="n/a")

    rows = [[r.n_boards, f"{r.noise_mm:g}", f"{r[PX]:g}", r.method, f"{100 * r.valid_rate:.0f}", f(r.rms_e_R_deg),
             f(r.rms_over_crlb_rot), f(r.rms_over_crlb_trans), f(r.mean_nees, ".1f"), f(r.camera_share_R, ".0%"),
             f(r.camera_share_t, ".0%")] for _, r in merged.iterrows()]
    head = ["boards", "mm", "px", "method", "valid %", "RMS e_R (deg)", "RMS/CRLB rot", "RMS/CRLB trans",
            "mean NEES", "camera share R", "camera share t"]
    return lines + md_table(head, rows) + [""]


def boards_section(summary: pd.DataFrame, fig: Path) -> list[str]:
    methods = method_order(summary["method"].unique())
    rows = []
    for nb, g in summary.groupby("n_boards"):
        rate = dict(zip(g["method"], 100 * g["valid_rate"], strict=True))
        seeds = [rate[m] for m in PAPER_METHODS if m in rate]
        ok = "yes" if "lidarcam" in rate and all(rate["lidarcam"] >= s for s in seeds) else "no"
        rows.append([nb, *(f"{rate.get(m, np.nan):.0f}" for m in methods), ok])
    return (["## Valid rate under camera noise (0.5 px, 20 mm)", "", f"![valid rate]({fig})", ""]
            + md_table(["boards", *methods, "lidarcam >= every seed method"], rows) + [""])


def corner_noise(trials: int = 100, boards_trials: int = 100, results_dir: str = "results", n_jobs: int = -1,
                 overrides: Sequence[str] = (), progress: bool = True) -> dict:
    t0 = time.perf_counter()
    base = [f"results_dir={results_dir}", *overrides]
    n = {"corner_noise": trials, "corner_boards": boards_trials}
    cells = {e: experiment_cells(e, [f"n_trials={n[e]}", *base]) for e in EXPERIMENTS}
    run_cells([c for cs in cells.values() for c in cs], n_jobs=n_jobs, progress=progress, label="corner-noise")
    out = Path(results_dir) / "corner_noise"
    frames = {}
    for exp, cs in cells.items():
        frames[exp] = pd.concat([load_cell(c) for c in cs], ignore_index=True)
        write_tables(frames[exp], exp, out)
    s_noise, s_boards = summarise(frames["corner_noise"]), summarise(frames["corner_boards"])
    share = camera_share(frames["corner_noise"])
    share.to_csv(out / "camera_share.csv", index=False, float_format="%.6g")
    lines = ["# Camera noise: joint estimation over image corners and lidar ranges", "",
             f"Generated by `python -m experiments corner-noise --trials {trials} --boards-trials {boards_trials}`.",
             ""]
    lines += noise_section(s_noise, share, draw_corner_noise(s_noise, out / "figures"))
    lines += boards_section(s_boards, draw_corner_boards(s_boards, out / "figures"))
    report = out / "REPORT.md"
    write_stamped(report, "\n".join(lines))
    return {"report": report, "total_s": time.perf_counter() - t0}


def main(argv: Sequence[str] | None = None) -> None:
    ap = study_parser(__doc__)
    ap.add_argument("overrides", nargs="*", help="Hydra overrides applied to both experiments")
    ap.add_argument("--trials", type=positive_int, default=100, help="trials per corner-noise point")
    ap.add_argument("--boards-trials", type=positive_int, default=100, help="trials per board count at 0.5 px")
    ap.add_argument("--results", default="results")
    ap.add_argument("--n-jobs", type=n_jobs, default=-1)
    a = ap.parse_args(argv)
    refuse_flag_overrides(a.overrides, {"results_dir": "--results", "n_trials": "--trials and --boards-trials"})
    r = corner_noise(a.trials, a.boards_trials, a.results, a.n_jobs, a.overrides)
    print(f"done in {r['total_s']:.1f} s. Report: {r['report']}")
