"""The leaderboard's table and figure from the runner's trial rows (``experiments.suites.leaderboard`` runs them).

One row per method, pooled over the simulated suites: valid rate with its 95% Wilson interval
(``intervals.wilson_interval``) and per suite, median errors (solutions returned), RMS errors (valid solutions),
RMS / CRLB and mean NEES where the method reports a covariance, median time per call.

RMS / CRLB and NEES come from the per-setting summaries of ``aggregate.summarise`` (the one home of those
formulas: within a setting, RMS error over RMS bound on the valid trials). Pooled here over the settings of the
suites where the range-noise bound applies, as the root of the mean squared ratio weighted by valid trials, so a
setting of near-degenerate scenes (3 boards: bounds of degrees) does not drown the others as it would in one
ratio of pooled RMS values. NEES: the mean over the valid trials that have one (as in the summaries).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from lidarcam.rig.markdown import md_table, num, pct  # noqa: E402

from ..engine.catalog import method_colour  # noqa: E402
from ..summary.aggregate import rms, summarise  # noqa: E402
from ..summary.figures import save_figure  # noqa: E402
from ..summary.intervals import wilson_interval  # noqa: E402


def _median(x: pd.Series) -> float:
    x = x.dropna()
    return float(x.median()) if len(x) else np.nan


def _weightedrms(ratio: pd.Series, weight: pd.Series) -> float:
    ok = ratio.notna() & (weight > 0)
    return float(np.sqrt(np.average(ratio[ok] ** 2, weights=weight[ok]))) if ok.any() else np.nan


def method_row(g: pd.DataFrame, summary: pd.DataFrame, crlb_suites: set[str]) -> dict:
    """The leaderboard figures of one method from its trial rows ``g`` and its per-setting summary rows
    ``summary`` (``aggregate.summarise``), both with a ``suite`` column. A setting that two suites share (6 boards
    at 20 mm is in both paper sweeps) counts once in the pooled figures, in each of its suites' columns."""
    per_suite = {f"valid_{suite}": float(s["valid"].astype(bool).mean()) for suite, s in g.groupby("suite", sort=False)}
    g = g.drop_duplicates(["setting_key", "trial"])
    summary = summary.drop_duplicates("setting_key")
    ok, valid = g["ok"].astype(bool), g["valid"].astype(bool)
    lo, hi = wilson_interval(int(valid.sum()), len(g))
    v = g[valid]
    row = {"n_trials": len(g), "n_valid": int(valid.sum()), "valid_rate": float(valid.mean()),
           "valid_lo95": float(lo), "valid_hi95": float(hi),
           "median_e_R_deg": _median(g.loc[ok, "e_R_deg"]), "median_e_t_mm": 1000 * _median(g.loc[ok, "e_t_m"]),
           "rms_e_R_deg": rms(v["e_R_deg"]), "rms_e_t_mm": 1000 * rms(v["e_t_m"])}
    b = summary[summary["suite"].isin(crlb_suites)]
    row["rms_over_crlb_rot"] = _weightedrms(b["rms_over_crlb_rot"], b["n_valid"])
    row["rms_over_crlb_trans"] = _weightedrms(b["rms_over_crlb_trans"], b["n_valid"])
    nees = v["nees"].dropna() if "nees" in v else pd.Series(dtype=float)
    row["mean_nees"], row["n_nees"] = (float(nees.mean()) if len(nees) else np.nan), len(nees)
    row["median_ms"] = 1000 * _median(g["seconds"])
    return {**row, **per_suite}


def leaderboard_table(rows: dict[str, pd.DataFrame], crlb_suites: set[str], origins: dict[str, str]) -> pd.DataFrame:
    """One row per method over the suites ``rows`` (suite -> trial rows), ranked by valid rate then median e_R."""
    frames = [df.assign(suite=name) for name, df in rows.items() if not df.empty]
    if not frames:
        return pd.DataFrame(columns=["rank", "method", "origin"])
    df = pd.concat(frames, ignore_index=True)
    summ = pd.concat([summarise(f).assign(suite=f["suite"].iloc[0]) for f in frames], ignore_index=True)
    out = pd.DataFrame([{"method": m, "origin": origins.get(m, ""),
                         **method_row(g, summ[summ["method"] == m], crlb_suites)}
                        for m, g in df.groupby("method", sort=False)])
    out = out.sort_values(["valid_rate", "median_e_R_deg"], ascending=[False, True], kind="stable")
    out.insert(0, "rank", np.arange(1, len(out) + 1))
    return out.reset_index(drop=True)


def real_table(rows: dict[str, pd.DataFrame]) -> pd.DataFrame | None:
    """Per method on the real files: results returned, median time, errors against a reference when given."""
    frames = [df for df in rows.values() if not df.empty]
    if not frames:
        return None
    df = pd.concat(frames, ignore_index=True)
    out = []
    for m, g in df.groupby("method", sort=False):
        ok = g["ok"].astype(bool)
        ref = g[g["has_reference"].astype(bool) & ok] if "e_R_deg" in g else g.iloc[0:0]
        out.append({"method": m, "files": len(g), "returned": int(ok.sum()), "median_ms": 1000 * _median(g["seconds"]),
                    "n_reference": len(ref), "median_e_R_deg": _median(ref["e_R_deg"]) if len(ref) else np.nan,
                    "median_e_t_mm": 1000 * _median(ref["e_t_m"]) if len(ref) else np.nan})
    return pd.DataFrame(out)


def markdown_table(t: pd.DataFrame) -> list[str]:
    """The table as Markdown lines (leaderboard or real-data table)."""
    if "valid_rate" not in t:  # real data
        head = ["method", "returned / files", "ms per call", "vs reference: median e_R (deg) / e_t (mm)"]
        body = [[f"`{r.method}`", f"{r.returned}/{r.files}", num(r.median_ms, ".1f"),
                 f"{num(r.median_e_R_deg, '.3f')} / {num(r.median_e_t_mm, '.1f')}" if r.n_reference else "no reference"]
                for r in t.itertuples()]
    else:
        suites = [c[len("valid_"):] for c in t.columns if c.startswith("valid_") and c not in (
            "valid_rate", "valid_lo95", "valid_hi95")]
        head = ["#", "method", "origin", "valid % [95%]", *(f"{s} %" for s in suites),
                "median e_R deg / e_t mm", "RMS e_R deg / e_t mm", "RMS / CRLB rot / trans", "NEES", "ms"]
        body = []

        def share(v):
            return pct(v, sign="")

        for r in t.to_dict("records"):
            body.append([str(r["rank"]), f"`{r['method']}`", r["origin"],
                         f"{share(r['valid_rate'])} [{share(r['valid_lo95'])}, {share(r['valid_hi95'])}]",
                         *(share(r.get(f"valid_{s}", np.nan)) for s in suites),
                         f"{num(r['median_e_R_deg'], '.3f')} / {num(r['median_e_t_mm'], '.1f')}",
                         f"{num(r['rms_e_R_deg'], '.3f')} / {num(r['rms_e_t_mm'], '.1f')}",
                         f"{num(r['rms_over_crlb_rot'], '.2f')} / {num(r['rms_over_crlb_trans'], '.2f')}",
                         num(r["mean_nees"], ".1f"), num(r["median_ms"], ".1f")])
    return md_table(head, body)


def figure(t: pd.DataFrame, suites: Sequence[str], out: Path) -> list[Path]:
    """``leaderboard.png|pdf``: valid rate per method (pooled with its interval, and per suite), and RMS / CRLB."""
    n = max(1, len(t))
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 1.2 + 0.32 * n), sharey=True,
                               gridspec_kw={"width_ratios": [3, 2]})
    y = np.arange(n)[::-1]
    markers = "osD^v<>p*h"
    for i, s in enumerate(suites):
        if f"valid_{s}" in t:
            a.plot(100 * t[f"valid_{s}"], y, markers[i % len(markers)], mfc="none", color="grey", ms=5, label=s)
    for yi, r in zip(y, t.to_dict("records"), strict=True):
        c = method_colour(r["method"])
        a.errorbar(100 * r["valid_rate"], yi, xerr=[[100 * (r["valid_rate"] - r["valid_lo95"])],
                                                   [100 * (r["valid_hi95"] - r["valid_rate"])]],
                   fmt="o", color=c, capsize=3)
        for val, dy, hatch in ((r["rms_over_crlb_rot"], 0.18, None), (r["rms_over_crlb_trans"], -0.18, "//")):
            if np.isfinite(val):
                b.barh(yi + dy, val, height=0.34, color=c, alpha=0.8, hatch=hatch, edgecolor="white")
    a.set_yticks(y, t["method"] if len(t) else [])
    a.set(xlabel="valid-solution rate (%), pooled [95% Wilson] and per suite", xlim=(-3, 103))
    a.grid(alpha=0.3)
    if suites:
        a.legend(fontsize=7, loc="lower left", title="suites", title_fontsize=7)
    b.axvline(1.0, color="black", lw=1, ls="--")
    b.set(xlabel="RMS / CRLB (solid: rotation, hatched: translation)", xscale="log")
    b.grid(alpha=0.3, axis="x")
    fig.tight_layout()
    return save_figure(fig, out, "leaderboard", dpi=130)
