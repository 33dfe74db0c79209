"""The search's objective: how far our results are from the paper's numbers (``conf/search/paper.yaml``).

The paper's numbers are ``experiments.paper.claims.paper_claims()``; the config gives each term's weight and the
scale that reads one unit of miss. ``score(trials)`` returns the objective under each Zhang & Pless variant
playing the paper's "Zhang", with the per-term misses, so a report can show where the distance comes from.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from omegaconf import DictConfig, OmegaConf

from lidarcam.rig.markdown import md_table

from ..summary.figures import PAPER_SWEEPS
from .claim_stats import claim_values, sweep_arrays, term_name
from .claims import Claim, paper_claims

SEARCH_CONF = Path(__file__).resolve().parents[2] / "conf" / "search" / "paper.yaml"


def load_search_conf(path: str | Path = SEARCH_CONF) -> DictConfig:
    return OmegaConf.load(path)


def miss(claim: Claim, values: np.ndarray, obj: DictConfig) -> np.ndarray:
    """Per setting: the distance of our value outside the claimed band in units of the kind's scale, capped
    at ``obj.cap``; ``obj.missing`` where our value does not exist."""
    v = np.asarray(values, float)
    scale = float(obj.scales[claim.kind])
    with np.errstate(divide="ignore", invalid="ignore"):
        if claim.kind == "relative":
            r = np.maximum(1 + v / 100, 1e-9)
            d = np.maximum.reduce([np.zeros_like(v), np.log2((1 + claim.lo / 100) / r),
                                   np.log2(r / (1 + claim.hi / 100))])
        elif claim.kind == "at_least":
            d = np.maximum(claim.lo - v, 0.0)
        else:
            d = np.maximum.reduce([np.zeros_like(v), claim.lo - v, v - claim.hi])
    d = np.minimum(d / scale, float(obj.cap))
    return np.where(np.isnan(v), float(obj.missing), d)


def score(trials: dict[str, pd.DataFrame], obj: DictConfig) -> pd.DataFrame:
    """One row per Zhang variant: ``objective`` and one column per term (its mean miss).

    ``trials``: the runner's rows of the ``boards`` and ``noise`` sweeps (point values, no resampling).
    """
    weights = dict(obj.weights)
    arrays = {s: sweep_arrays(t, PAPER_SWEEPS[s].x) for s, t in trials.items()}
    rows = []
    for zhang in obj.zhang:
        terms = {}
        for claim in paper_claims():
            name = term_name(claim)
            if claim.other is not None and claim.other != zhang and name.split(":")[2] == "zhang":
                continue
            if name not in weights:
                raise KeyError(f"conf/search: no weight for the term {name!r}")
            vals = claim_values(None, claim, PAPER_SWEEPS[claim.sweep].x, smooth=float(obj.smooth_trials),
                                arrays=arrays[claim.sweep])
            terms[name] = float(np.mean(miss(claim, vals["value"].to_numpy(), obj)))
        total = sum(weights[k] * v for k, v in terms.items()) / sum(weights[k] for k in terms)
        rows.append({"zhang": zhang, "objective": total, **terms})
    return pd.DataFrame(rows)


def objective_lines(obj: DictConfig) -> list[str]:
    """The objective as a markdown table (term, claim, weight, scale) for the reports."""
    claims = {term_name(c): c for c in paper_claims()}
    rows = []
    units = {"points": "pt", "at_least": "pt", "relative": "x2 (log2 ratio)", "err_deg": "deg", "err_mm": "mm"}
    for name, w in obj.weights.items():
        c = claims[name]
        band = f"{c.lo:g}" if c.lo == c.hi else f"{c.lo:g}..{c.hi:g}"
        scale = obj.scales[c.kind]
        rows.append([f"`{name}`", f"{c.text} ({c.source})", band, f"{w:g}",
                     f"{'' if c.kind == 'relative' else f'{scale:g} '}{units[c.kind]}"])
    lines = md_table(["term", "the paper's claim", "band", "weight", "one unit of miss"], rows)
    return lines + ["", f"A miss is capped at {obj.cap:g} units per setting; a value that does not exist (no "
                    f"mean error where Zhang & Pless returns nothing) misses by {obj.missing:g}. Relative valid-rate "
                    f"gains count {obj.smooth_trials:g} extra valid trials on each side. Objective = weighted mean "
                    "of the terms' mean misses; each Zhang & Pless variant is scored as the paper's Zhang and the "
                    "better one counts."]
