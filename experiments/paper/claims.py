"""The paper's claims as data, and the one rule that judges a claim on our values.

A claim "ours beats X by a..b over the settings" is judged on our value per setting, with or without a 95%
interval (``lo``, ``hi``; without one the interval is the value itself): a setting counts as better (worse) only
when its whole interval is above (below) zero, else as a tie. **holds**: better at some setting, worse at
none, and some interval overlaps the claimed band [a, b] (a single claimed number a = b: a factor of two either
way); **direction only**: so, but no interval reaches the band; **mixed**: worse at some setting, or a setting
where our value does not exist; **does not hold**: better nowhere. "At least p" holds unless some setting's
interval lies wholly below p. Which method plays "Zhang" is reported for both of our Zhang & Pless variants.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

PAPER = "peng2022"  # the method whose claims this report checks
FRANCISCO = "vasconcelos"
FRANCISCO_CODE = "vasconcelos_msac"
"""The other reading of "Francisco": the authors' MATLAB (MSAC selection over the same minimal solutions), as
against the paper's description (``FRANCISCO``, point-to-plane selection). Every claim against Francisco is judged
under both (``francisco_twins``)."""
READINGS = {FRANCISCO: "the paper's description", FRANCISCO_CODE: "the authors' code"}
ZHANGS = ("zhang_pless_linear", "zhang_pless")


@dataclass(frozen=True)
class Claim:
    """One claim of the paper, as a comparison the summary tables can check.

    ``kind``: ``points`` (valid rate, ours - other, percentage points), ``relative`` (valid rate,
    ours/other - 1, percent), ``err_deg`` / ``err_mm`` (mean e_R / e_t, other - ours), ``at_least``
    (ours' valid rate >= lo percent). ``at``: restrict to one value of the swept setting.
    """

    sweep: str
    text: str
    source: str
    kind: str
    other: str | None
    lo: float
    hi: float
    at: float | None = None


def paper_claims() -> list[Claim]:
    """docs/METHOD.md "The paper's claims" and the error claims of the paper's Section 3.1 text (Fig. 4, 6)."""
    claims = [Claim("boards", "valid-solution probability +2 to +20 points vs Francisco (3-8 boards)",
                    "abstract, Fig. 3a", "points", FRANCISCO, 2, 20)]
    claims += [Claim("boards", "valid-solution probability +30% to +260% vs Zhang (relative, 3-8 boards)",
                     "abstract, Fig. 3a", "relative", z, 30, 260) for z in ZHANGS]
    claims += [Claim("noise", "valid-solution probability at least 90% at every noise level (6 boards)",
                     "Fig. 3b", "at_least", None, 90, 100),
               Claim("noise", "at 30 mm: +19 vs Francisco (read as points)", "Fig. 3b", "points", FRANCISCO,
                     19, 19, at=30.0),
               Claim("noise", "at 30 mm: +19% vs Francisco (read as relative)", "Fig. 3b", "relative", FRANCISCO,
                     19, 19, at=30.0)]
    claims += [Claim("noise", "at 30 mm: +150% vs Zhang (relative)", "Fig. 3b", "relative", z, 150, 150, at=30.0)
               for z in ZHANGS]
    claims += [Claim("noise", "mean e_R 1-5 deg lower than Francisco over noise levels", "abstract, Fig. 6",
                     "err_deg", FRANCISCO, 1, 5)]
    claims += [Claim("noise", "mean e_R 3-14 deg lower than Zhang over noise levels", "abstract, Fig. 6",
                     "err_deg", z, 3, 14) for z in ZHANGS]
    claims += [Claim("noise", "mean e_t 100-400 mm lower than Francisco over noise levels", "Fig. 6 text",
                     "err_mm", FRANCISCO, 100, 400)]
    claims += [Claim("noise", "mean e_t 300-1400 mm lower than Zhang over noise levels", "Fig. 6 text",
                     "err_mm", z, 300, 1400) for z in ZHANGS]
    claims += [Claim("boards", "mean e_R 2-42 deg lower than Francisco (3-8 boards)", "Fig. 4 text", "err_deg",
                     FRANCISCO, 2, 42),
               Claim("boards", "mean e_t 200-4000 mm lower than Francisco (3-8 boards)", "Fig. 4 text", "err_mm",
                     FRANCISCO, 200, 4000)]
    claims += [Claim("boards", "mean e_R 10-38 deg lower than Zhang (3-8 boards)", "Fig. 4 text", "err_deg", z,
                     10, 38) for z in ZHANGS]
    claims += [Claim("boards", "mean e_t 300-4200 mm lower than Zhang (3-8 boards)", "Fig. 4 text", "err_mm", z,
                     300, 4200) for z in ZHANGS]
    return claims


def francisco_twins() -> list[tuple[int, Claim, Claim]]:
    """Each claim against Francisco: its number in ``paper_claims``, the claim, and its twin against the authors'
    code's reading (``FRANCISCO_CODE``)."""
    return [(i, c, replace(c, other=FRANCISCO_CODE)) for i, c in enumerate(paper_claims(), 1) if c.other == FRANCISCO]


def reading_fit(verdict_description: str, verdict_code: str) -> str:
    """Which reading of Francisco the paper's numbers fit, from the claim's verdict under each: the one(s) under
    which it holds, else "neither" ("not run" where a reading was not run)."""
    if "not run" in (verdict_description, verdict_code):
        return "not run"
    fits = [r for r, v in zip(READINGS.values(), (verdict_description, verdict_code), strict=True) if v == "holds"]
    return "both" if len(fits) == 2 else fits[0] if fits else "neither"


def claim_holds(claim: Claim, value, lo=None, hi=None) -> str:
    """The verdict of ``claim`` on our per-setting ``value`` (its unit: see ``Claim``) and, where known, its 95%
    interval ``lo``..``hi`` (None: point values, every interval of zero width). Rules: the module docstring."""
    value = np.asarray(value, float)
    lo = value if lo is None else np.asarray(lo, float)
    hi = value if hi is None else np.asarray(hi, float)
    if len(value) == 0:
        return "not run"
    if claim.kind == "at_least":
        return "does not hold" if np.any(hi < claim.lo) else "holds"
    known = ~np.isnan(value)
    if not known.any():
        return "not computable"
    better, worse = lo[known] > 0, hi[known] < 0
    if not better.any():
        return "does not hold"
    if worse.any() or not known.all():
        return "mixed"
    band = (claim.lo / 2, claim.hi * 2) if claim.lo == claim.hi else (claim.lo, claim.hi)
    return "holds" if lo[known].min() <= band[1] and hi[known].max() >= band[0] else "direction only"


def claim_value_text(v: float, kind: str) -> str:
    """A value of a claim of ``kind`` in its unit, signed (``n/a`` where it does not exist)."""
    if math.isnan(v):
        return "n/a"
    if math.isinf(v):
        return "+inf"
    unit = {"points": " pt", "relative": "%", "err_deg": " deg", "err_mm": " mm", "at_least": "%"}[kind]
    if kind == "at_least":
        return f"{v:.0f}{unit}"
    return f"{v:+.1f}{unit}" if kind == "err_deg" else f"{v:+.0f}{unit}"
