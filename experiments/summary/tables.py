"""Markdown tables of summary rows (one row per swept value, one column per method), shared by the reports."""

from __future__ import annotations

import pandas as pd

from lidarcam.rig.markdown import md_table

from ..engine.catalog import method_label, method_order


def method_table(summary: pd.DataFrame, x: str, cell) -> list[str]:
    """A markdown table: one row per value of ``x``, one column per method, ``cell(summary row)`` in each (``-``
    where the method has no row, or ``cell`` returns None)."""
    methods = method_order(summary["method"].unique())
    rows = []
    for xv, g in summary.groupby(x, sort=True):
        per = [g[g["method"] == m] for m in methods]
        rows.append([f"{xv:g}", *((cell(r.iloc[0]) if not r.empty else None) or "-" for r in per)])
    return md_table([x, *(method_label(m) for m in methods)], rows)


def valid_cell(r) -> str:
    """A summary row's valid rate and its 95% Wilson interval, in percent."""
    return f"{100 * r.valid_rate:.0f}% [{100 * r.valid_lo95:.0f}, {100 * r.valid_hi95:.0f}]"


def error_cell(r) -> str | None:
    """A summary row's mean (median) e_R in degrees / e_t in millimetres; None when the method never returned."""
    if r.n_ok == 0:
        return None
    return (f"{r.mean_e_R_deg:.2f} / {1000 * r.mean_e_t_m:.0f} (med {r.median_e_R_deg:.2f} / "
            f"{1000 * r.median_e_t_m:.0f})")
