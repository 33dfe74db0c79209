"""``results/plan/REPORT.md`` and ``plan_check.png`` from the plan check's summary (``suites.plan_check``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lidarcam.rig.markdown import md_table

from ..engine.fingerprint import write_stamped

TOLERANCE = 0.2
"""The prediction holds when the empirical RMS is within this fraction of the predicted sigma."""


def _ci(v) -> str:
    return f"{v[0]:.3g} [{v[1]:.3g}, {v[2]:.3g}]"


def _within_tolerance(ratio: float) -> str:
    return "within 20%" if abs(ratio - 1) <= TOLERANCE else "**outside 20%**"


def write_figure(path: Path, summary: dict) -> None:
    """Left: empirical / predicted RMS per board count and mode; right: planned vs random RMS errors."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.2))
    for mode, mk in (("exact", "o"), ("pixel", "s")):
        rows = [r for r in summary["prediction"] if r["mode"] == mode]
        n = np.array([r["boards"] for r in rows])
        for key, emp, colour in (("rot", "emp_rot_deg", "tab:blue"), ("trans", "emp_trans_mm", "tab:orange")):
            pred = np.array([r[f"pred_{key}_deg" if key == "rot" else "pred_trans_mm"] for r in rows])
            e = np.array([r[emp] for r in rows])
            ax.errorbar(n + (0.15 if key == "trans" else -0.15), e[:, 0] / pred,
                        yerr=[(e[:, 0] - e[:, 1]) / pred, (e[:, 2] - e[:, 0]) / pred], fmt=mk, color=colour,
                        label=f"{key}, {'no corner noise' if mode == 'exact' else 'corner noise'}", capsize=3,
                        mfc="none" if mode == "exact" else colour)
    ax.axhspan(1 - TOLERANCE, 1 + TOLERANCE, color="0.9")
    ax.axhline(1.0, color="0.4", lw=0.8)
    ax.set_xscale("log", base=2)
    ax.set_xticks([4, 8, 16], ["4", "8", "16"])
    ax.set_xlabel("boards (planned)")
    ax.set_ylabel("empirical RMS / predicted sigma (95% interval)")
    ax.set_title("prediction vs spread of the calibration")
    ax.legend(fontsize=8)
    for i, r in enumerate(summary["versus"]):
        k = r["boards"]
        for j, (name, colour) in enumerate((("rot_deg", "tab:blue"), ("trans_mm", "tab:orange"))):
            x = k + (j - 0.5) * 0.5
            rr = np.array(r[f"random_{name}"]) / r[f"planned_{name}"]
            bx.plot(np.full(len(rr), x), rr, ".", color=colour, alpha=0.5,
                    label=f"random / planned, {name.split('_')[0]}" if i == 0 else None)
            bx.plot([x - 0.2, x + 0.2], [r[f"ratio_{name}"][0]] * 2, color=colour, lw=2)
    bx.axhline(1.0, color="0.4", lw=0.8)
    bx.set_yscale("log")
    bx.set_xlabel("boards K")
    bx.set_ylabel("random set's RMS error / planned set's (bar: median)")
    bx.set_title("planned vs random feasible poses")
    bx.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_plan_report(out: Path, summary: dict) -> Path:
    """Write REPORT.md and plan_check.png into ``out``."""
    out = Path(out)
    write_figure(out / "plan_check.png", summary)
    n_pred, n_vs = summary["redraws"]["prediction"], summary["redraws"]["versus"]
    md = ["# The capture planner against the simulator", "",
          "`make plan-check` (`python -m experiments plan-check`, sizes in `conf/plan/check.yaml`); "
          f"method `{summary['method']}`; {summary['seconds']} s wall. Intervals: 95% percentile bootstrap.", "",
          "![plan check](plan_check.png)", "",
          "## Predicted sigma against the spread of the calibration", "",
          f"The planner's D-optimal sets of 4, 8 and 16 boards; each set measured afresh {n_pred} times (range noise "
          "20 mm; corner noise 0.5 px or none, i.e. exact board poses) and calibrated. Empirical: the RMS over the "
          "redraws of the rotation error angle and of |t - t_true|; predicted: `rot_sigma_deg` and "
          "`trans_sigma_mm` of `lidarcam plan` (roots of the traces of the joint Cramer-Rao bound).", "",
          ]
    md += md_table(["corner noise", "boards", "ok / failed", "rotation: predicted deg", "empirical RMS deg", "ratio",
                    "translation: predicted mm", "empirical RMS mm", "ratio"],
                   [["none" if r["mode"] == "exact" else "0.5 px", r["boards"], f"{r['n']} / {r['failed']}",
                     f"{r['pred_rot_deg']:.3f}", _ci(r["emp_rot_deg"]),
                     f"{r['ratio_rot']:.2f} ({_within_tolerance(r['ratio_rot'])})",
                     f"{r['pred_trans_mm']:.1f}", _ci(r["emp_trans_mm"]),
                     f"{r['ratio_trans']:.2f} ({_within_tolerance(r['ratio_trans'])})"] for r in summary["prediction"]],
                   "lrrrrrrrr")
    md += ["", "## Planned against random feasible poses", "",
           f"Corner noise 0.5 px. At each K: the planner's K poses and {summary['random_sets']} sets of K random "
           "feasible poses (uniform over the workspace: 3-6 m, bearings +-30 deg, turn and lean +-40 deg; each in "
           f"the image with its margin and cut by the scan plane), each set measured afresh {n_vs} times and "
           "calibrated. Margin: the random sets' median RMS error over the planned set's, with its interval "
           "(bootstrap over the random sets and the planned redraws); 'beaten': random sets whose RMS is above "
           "the planned set's.", "",
           ]
    m = summary["random_sets"]
    md += md_table(["K", "planned RMS rot deg (predicted)", "random median deg", "margin rot", "beaten",
                    "planned RMS trans mm (predicted)", "random median mm", "margin trans", "beaten"],
                   [[r["boards"], f"{r['planned_rot_deg']:.3f} ({r['pred']['rot_sigma_deg']:.3f})",
                     f"{r['random_median_rot_deg']:.3f}", f"x{_ci(r['ratio_rot_deg'])}", f"{r['beaten_rot_deg']}/{m}",
                     f"{r['planned_trans_mm']:.1f} ({r['pred']['trans_sigma_mm']:.1f})",
                     f"{r['random_median_trans_mm']:.1f}", f"x{_ci(r['ratio_trans_mm'])}",
                     f"{r['beaten_trans_mm']}/{m}"]
                    for r in summary["versus"]], "r" * 9)
    v = summary["vertical"]
    md += ["", "## Vertical boards, before any data", "",
           f"The same rig with a workspace of vertical boards (lean 0, turn +-40 deg), {v['boards']} planned "
           f"boards: the planner names **{', '.join(v['undetermined']) or 'nothing'}** as not determined or weak:",
           "", f"> {v['message']}", ""]
    write_stamped(out / "REPORT.md", "\n".join(md) + "\n")
    return out / "REPORT.md"
