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


REFUSAL_WORDS = ("not determined", "undetermined")
"""How a refusal names what the boards leave free (``calib_core.checks.degeneracy.Degeneracy.message``)."""


def refused_axes(reason) -> tuple[str, ...]:
    """The lidar axes (``checks.degeneracy.AXES``) that a method's reason names as not determined: those whose
    words (``AXIS_WORDS``, e.g. "roll (rotation about the lidar x axis)") stand before its first "not determined"
    or "undetermined"; () for an answer (empty or missing reason), another failure, or a reason naming no axis."""
    from calib_core.checks.degeneracy import AXES, AXIS_WORDS

    text = reason if isinstance(reason, str) else ""
    cuts = [i for w in REFUSAL_WORDS if (i := text.find(w)) >= 0]
    head = text[:min(cuts)] if cuts else ""
    return tuple(a for a in AXES if AXIS_WORDS[a] in head)


def refusals(df: pd.DataFrame, method: str = "lidarcam") -> pd.DataFrame:
    """Per board count, ``method``'s rows of ``df`` (columns ``n_boards``, ``method``, ``ok`` and either
    ``refused_axes``, the axes space-separated, or ``reason``; optional ``nees``): ``n``, ``answered`` (ok),
    ``axis_refused`` (rows whose refusal names an axis as not determined, ``refused_axes``), ``axes`` (how often
    each axis is named, e.g. "roll 3, pitch 3"), ``median_nees`` over the answers with a NEES and ``n_nees``."""
    from calib_core.checks.degeneracy import AXES

    d = df[df["method"] == method]
    named = (d["refused_axes"].fillna("").astype(str).str.split() if "refused_axes" in d
             else d["reason"].map(refused_axes))
    rows = []
    for k in sorted(d["n_boards"].unique()):
        at = (d["n_boards"] == k).to_numpy()
        dk, ax = d[at], [set(a) for a in named[at]]
        ok = dk["ok"].astype(bool)
        nees = dk.loc[ok, "nees"].astype(float).dropna() if "nees" in dk else pd.Series(dtype=float)
        counts = [(a, sum(a in s for s in ax)) for a in AXES]
        rows.append({"n_boards": int(k), "n": len(dk), "answered": int(ok.sum()),
                     "axis_refused": sum(bool(s) for s in ax),
                     "axes": ", ".join(f"{a} {c}" for a, c in counts if c) or "-",
                     "median_nees": float(nees.median()) if len(nees) else float("nan"), "n_nees": len(nees)})
    return pd.DataFrame(rows)


def refusal_table(r: pd.DataFrame, extra: dict[str, list[str]] | None = None) -> list[str]:
    """Markdown of ``refusals``: per board count the rows, answered, refusals naming an axis (count and share),
    the axes named and the NEES median (with how many answers it is over); ``extra``: more columns, header ->
    one right-aligned cell per row of ``r``."""
    extra = extra or {}
    body = [[int(x.n_boards), x.n, f"{x.answered} ({100 * x.answered / x.n:.0f}%)",
             f"{x.axis_refused} ({100 * x.axis_refused / x.n:.0f}%)", x.axes,
             f"{x.median_nees:.1f} ({x.n_nees})" if x.n_nees else "-", *(c[i] for c in extra.values())]
            for i, x in enumerate(r.itertuples())]
    return md_table(["boards", "runs", "answered", "refused an axis", "axes named", "NEES median (answers)",
                     *extra], body, "rrrrlr" + "r" * len(extra))
