"""The paper's claims measured on trial rows, with paired bootstrap intervals (judged by ``claims.claim_holds``).

    values = claim_values(trials, claim, x, n_boot=2000)   # one row per setting: value, lo95, hi95

``trials`` holds the runner's rows of one paper sweep (``boards`` or ``noise``): ``trial``, ``method``,
``ok``, ``valid``, ``e_R_deg``, ``e_t_m`` and the swept column ``x``. Every method ran on the same simulated
trials, so a resample draws trials, not rows: the interval of a difference is paired. Units follow
``experiments.paper.claims.Claim``: points and percent for valid rates, degrees and millimetres for mean errors.
"""

from __future__ import annotations

from functools import partial

import numpy as np
import pandas as pd

from ..summary.aggregate import nanmean
from ..summary.intervals import paired_bootstrap
from .claims import FRANCISCO, Claim
from .claims import PAPER as OURS

BOOT_SEED = 20220101


def sweep_arrays(trials: pd.DataFrame, x: str) -> dict:
    """Per setting of ``x`` and method: ``valid`` (0/1), ``e_R`` (deg, NaN where it returned nothing), ``e_t``
    (m), aligned by trial. Computed once per sweep and shared by every claim on it."""
    out = {}
    for xv, g in trials.groupby(x, sort=True):
        w = g.pivot(index="trial", columns="method", values=["valid", "e_R_deg", "e_t_m", "ok"])
        per = {}
        for m in w["valid"].columns:
            ok = w["ok"][m].astype(float).fillna(0.0).to_numpy() > 0
            per[m] = {"valid": w["valid"][m].astype(float).fillna(0.0).to_numpy(),
                      "e_R": np.where(ok, w["e_R_deg"][m].astype(float).to_numpy(), np.nan),
                      "e_t": np.where(ok, w["e_t_m"][m].astype(float).to_numpy(), np.nan)}
        out[xv] = per
    return out


def claim_statistic(kind: str, ours: dict, other: dict | None, idx: np.ndarray, smooth: float = 0.0) -> np.ndarray:
    """The claim's statistic on the trials ``idx`` (shape (B, n): B resamples); shape (B,).

    ``smooth`` > 0 adds that many valid trials to each side of a relative gain (a finite ratio at 0 valid).
    """
    if kind == "at_least":
        return 100 * ours["valid"][idx].mean(axis=-1)
    if kind in ("points", "relative"):
        po, px = ours["valid"][idx].mean(axis=-1), other["valid"][idx].mean(axis=-1)
        if kind == "points":
            return 100 * (po - px)
        n = idx.shape[-1]
        with np.errstate(divide="ignore", invalid="ignore"):
            return 100 * ((po * n + smooth) / (px * n + smooth) - 1)
    key, scale = ("e_R", 1.0) if kind == "err_deg" else ("e_t", 1000.0)
    return scale * (nanmean(other[key][idx]) - nanmean(ours[key][idx]))


def claim_values(trials: pd.DataFrame | None, claim: Claim, x: str, n_boot: int = 0, smooth: float = 0.0,
                 seed: int = BOOT_SEED, arrays: dict | None = None) -> pd.DataFrame:
    """Our value of ``claim`` per setting of ``x``: ``value`` and, with ``n_boot`` resamples, the 95% paired
    percentile interval ``lo95``, ``hi95`` (NaN without resamples); ``n_trials`` per setting. ``arrays``:
    ``sweep_arrays(trials, x)`` when already computed."""
    arrays = sweep_arrays(trials, x) if arrays is None else arrays
    rows = []
    for xv, arr in arrays.items():
        if claim.at is not None and not np.isclose(float(xv), claim.at):
            continue
        n = len(arr[OURS]["valid"])
        other = arr.get(claim.other) if claim.other else None
        value = float(claim_statistic(claim.kind, arr[OURS], other, np.arange(n)[None], smooth)[0])
        lo = hi = np.nan
        if n_boot:
            lo, hi = paired_bootstrap(partial(claim_statistic, claim.kind, arr[OURS], other, smooth=smooth),
                                      n, n_boot, seed)
        rows.append({x: xv, "n_trials": n, "value": value, "lo95": float(lo), "hi95": float(hi)})
    return pd.DataFrame(rows, columns=[x, "n_trials", "value", "lo95", "hi95"])


def term_name(claim: Claim) -> str:
    """The objective's name of ``claim``: ``<sweep>:<kind>:<vs>[@<setting>]`` (vs: francisco, zhang, self)."""
    vs = "self" if claim.other is None else "francisco" if claim.other == FRANCISCO else "zhang"
    return f"{claim.sweep}:{claim.kind}:{vs}" + (f"@{claim.at:g}" if claim.at is not None else "")
