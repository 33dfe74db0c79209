"""``<results>/<preset>/REPORT.md``: every claim of the paper under the default and the matched preset, with
paired 95% bootstrap intervals, the search that found the preset, and how sensitive each verdict is.

    python -m experiments matched-report [--tables results/paper-matched] [--preset paper-matched]

Reads ``summary_*.csv`` / ``trials_*.csv`` of the preset (``<tables>``) and of the default (``<tables>/default``),
and the search's ``points_*.csv`` / ``verdicts_*.csv``; writes ``claims.csv`` (per claim, preset and setting:
value and interval) and ``REPORT.md``.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from lidarcam.rig.markdown import md_table

from ..engine.catalog import method_label
from ..engine.cell import RunnerError
from ..engine.cli import study_parser
from ..engine.fingerprint import write_stamped
from ..summary.aggregate import load_summary, load_trials
from ..summary.figures import PAPER_SWEEPS
from ..summary.tables import method_table, valid_cell
from .claim_stats import claim_values, sweep_arrays, term_name
from .claims import (
    FRANCISCO,
    FRANCISCO_CODE,
    READINGS,
    Claim,
    claim_holds,
    claim_value_text,
    francisco_twins,
    paper_claims,
    reading_fit,
)
from .objective import load_search_conf, objective_lines, score
from .settings_search import SPACE_KEYS, sensitivity_ranges

N_BOOT = 2000
LABELS = {"max_tilt_deg": "tilt (deg)", "board_size_m": "board (m)", "bearing_spread_deg": "spread (deg)",
          "corner_noise_px": "corner noise (px; < 0.3: exact poses)"}


def claims_table(tables: dict[str, Path], numbered: list[tuple[int, Claim]] | None = None) -> pd.DataFrame:
    """Per preset, claim and setting: our value with its paired 95% interval, and the claim's verdict; ``numbered``:
    the claims with their numbers (default: ``paper_claims``). A claim whose other method was not run is left out."""
    rows = []
    numbered = list(enumerate(paper_claims(), 1)) if numbered is None else numbered
    for preset, folder in tables.items():
        trials = {s: sweep_arrays(load_trials(folder, s), PAPER_SWEEPS[s].x) for s in PAPER_SWEEPS
                  if (folder / f"trials_{s}.csv").exists()}
        for i, claim in numbered:
            if claim.sweep not in trials or (claim.other and any(claim.other not in a
                                                                 for a in trials[claim.sweep].values())):
                continue
            x = PAPER_SWEEPS[claim.sweep].x
            v = claim_values(None, claim, x, n_boot=N_BOOT, arrays=trials[claim.sweep])
            verdict = claim_holds(claim, v["value"], v["lo95"], v["hi95"])
            rows += [{"preset": preset, "claim": i, "term": term_name(claim), "x": r[x], "n_trials": r["n_trials"],
                      "value": r["value"], "lo95": r["lo95"], "hi95": r["hi95"], "verdict": verdict}
                     for _, r in v.iterrows()]
    return pd.DataFrame(rows)


def _cell(g: pd.DataFrame, kind: str) -> str:
    def text(v):
        return claim_value_text(v, kind)

    per = "; ".join(f"{r.x:g}: {text(r.value)} [{text(r.lo95)}, {text(r.hi95)}]" for r in g.itertuples())
    return f"{per} -> **{g['verdict'].iloc[0]}**"


def _sensitivity(verdicts: pd.DataFrame, claim: int) -> str:
    v = verdicts[verdicts["claim"] == claim]
    ok = v[v["verdict"] == "holds"]
    if ok.empty:
        return f"at none of {len(v)}"
    short = {"max_tilt_deg": "tilt", "board_size_m": "board", "bearing_spread_deg": "spread",
             "corner_noise_px": "px"}
    spans = ", ".join(f"{short[k]} {ok[k].min():g}-{ok[k].max():g}" for k in SPACE_KEYS)
    return f"at {len(ok)} of {len(v)}: {spans}"


def claims_section(ct: pd.DataFrame, presets: list[str], verdicts: pd.DataFrame | None) -> list[str]:
    rows = []
    for i, claim in enumerate(paper_claims(), 1):
        cells = []
        for p in presets:
            g = ct[(ct["preset"] == p) & (ct["claim"] == i)]
            cells.append(_cell(g, claim.kind) if len(g) else "not run")
        sens = _sensitivity(verdicts, i) if verdicts is not None else "search not run"
        vs = method_label(claim.other) if claim.other else "-"
        rows.append([i, claim.text, vs, *cells, sens])
    return md_table(["#", "Paper's claim", "vs", *(f"{p}: ours per setting [95% CI]" for p in presets),
                     "holds at coarse search points"], rows)


def readings_section(tables: dict[str, Path], ct: pd.DataFrame, presets: list[str]) -> list[str]:
    """Every claim against Francisco under both readings, per preset, and which one the paper's numbers fit."""
    twins = francisco_twins()
    code = claims_table(tables, [(i, twin) for i, _, twin in twins])
    rows = []
    for i, claim, _ in twins:
        cells = []
        for p in presets:
            d = ct[(ct["preset"] == p) & (ct["claim"] == i)]
            c = code[(code["preset"] == p) & (code["claim"] == i)] if len(code) else code
            vd = d["verdict"].iloc[0] if len(d) else "not run"
            vc = c["verdict"].iloc[0] if len(c) else "not run"
            cells.append(f"{_cell(d, claim.kind) if len(d) else 'not run'} / "
                         f"{_cell(c, claim.kind) if len(c) else 'not run'} -> {reading_fit(vd, vc)}")
        rows.append([i, claim.text, *cells])
    return md_table(["#", "Paper's claim", *(f"{p}: {READINGS[FRANCISCO]} / {READINGS[FRANCISCO_CODE]} -> fit"
                                             for p in presets)], rows)


def _values(vals: list, key: str) -> str:
    return ", ".join(f"{v:g}" for v in vals) + (" px" if key == "corner_noise_px" else "")


def sensitivity_verdicts_section(sens: pd.DataFrame | None, conf) -> list[str]:
    """Per claim and setting: the values (the others at the winner's) at which the claim holds."""
    if sens is None:
        return ["The sensitivity stage has not run (`python -m experiments search --stage sensitivity`)."]
    ranges = sensitivity_ranges(sens)
    n = int(conf.sensitivity.trials)
    lines = [f"One setting at a time through the matched preset (the others at its values), {conf.sensitivity.levels} "
             f"values over each setting's searched range, {n} trials per setting of the sweeps, common random numbers; "
             "each claim judged as above (paired 95% intervals). A cell lists the values at which the claim holds: "
             "*all* = over the whole range searched (the verdict does not hinge on that setting), *none* = at none.",
             ""]
    rows = []
    for i, claim in enumerate(paper_claims(), 1):
        cells = []
        for k in SPACE_KEYS:
            r = ranges[(ranges["claim"] == i) & (ranges["setting"] == k)]
            if r.empty:
                cells.append("-")
                continue
            held, tried = r["holds_at"].iloc[0], r["tried"].iloc[0]
            cells.append("all" if len(held) == len(tried) else "none" if not held else _values(held, k))
        vs = method_label(claim.other) if claim.other else "-"
        rows.append([i, claim.text, vs, *cells])
    return lines + md_table(["#", "Paper's claim", "vs", *(LABELS[k] for k in SPACE_KEYS)], rows)


def meaning(ct: pd.DataFrame, presets: list[str], verdicts: pd.DataFrame | None) -> list[str]:
    """The generated reading: which claims hold where, and which under none of the settings searched."""
    v = {(r.preset, r.claim): r.verdict for r in ct.drop_duplicates(["preset", "claim"]).itertuples()}
    claims = paper_claims()
    default, matched = presets[-1], presets[0]
    groups: dict[str, list[int]] = {"both": [], "matched": [], "default": [], "searched": [], "none": []}
    for i in range(1, len(claims) + 1):
        hm, hd = v.get((matched, i)) == "holds", v.get((default, i)) == "holds"
        anywhere = verdicts is not None and (verdicts[verdicts["claim"] == i]["verdict"] == "holds").any()
        key = ("both" if hm and hd else "matched" if hm else "default" if hd else "searched" if anywhere else "none")
        groups[key].append(i)

    def names(ids: list[int]) -> str:
        return ", ".join(f"{i} ({claims[i - 1].text.split(' (')[0]}"
                         f"{' vs ' + method_label(claims[i - 1].other) if claims[i - 1].other else ''})"
                         for i in ids) or "none"

    return [f"- **Hold under both presets** (so under settings the paper could have used, and not only there): "
            f"{names(groups['both'])}.",
            f"- **Hold under the matched preset only**: {names(groups['matched'])}.",
            f"- **Hold under our default only**: {names(groups['default'])}.",
            "- **Hold under neither preset but at some search point** (a coarse point, judged on point estimates "
            "at few trials, or a point of the sensitivity lines: a lead, not a finding): "
            f"{names(groups['searched'])}.",
            f"- **Hold under none of the settings searched**: {names(groups['none'])}.",
            "", "How sensitive a verdict is: the sensitivity table above (one setting at a time through the matched "
            "preset, over each setting's whole range), and the last column of the claims table (at how many of the "
            "coarse search's points the claim holds, point estimates, and the range of each setting over those "
            "points). A claim that holds over the whole range of a setting does not hinge on it; one that holds "
            "only at part of it does."]


def _search_lines(search_dir: Path) -> list[str]:
    lines = []
    for stage in ("coarse", "fine"):
        path = search_dir / f"points_{stage}.csv"
        if not path.exists():
            lines += [f"Stage {stage}: not run.", ""]
            continue
        t = pd.read_csv(path)
        lines += [f"**Stage {stage}**: {len(t)} points x {int(t['trials'].min())} trials per setting "
                  "(boards 3-8, noise 5-30 mm), best first" + (" (top 8)" if len(t) > 8 else "") + ":", "",
                  ]
        rows = [[r.point, *(f"{getattr(r, k):g}" for k in SPACE_KEYS),
                 f"{r.objective_zhang_pless_linear:.3f} / {r.objective_zhang_pless:.3f}", f"{r.objective:.3f}"]
                for r in t.head(8).itertuples()]
        lines += md_table(["point", *(LABELS[k] for k in SPACE_KEYS), "objective (Zhang linear / refined)", "best"],
                          rows)
        lines.append("")
    return lines


EDGE_FRACTION = 0.05
"""A winning setting within this fraction of its range from a bound of the searched space is flagged."""


def edge_lines(search_dir: Path, conf) -> list[str]:
    """A note for every setting at which the winner (``best.json``) sits at the edge of the searched range: the
    best match may lie beyond it."""
    path = search_dir / "best.json"
    if not path.exists():
        return []
    best = json.loads(path.read_text())
    notes = []
    for k in SPACE_KEYS:
        lo, hi = (float(v) for v in conf.space[k])
        for bound, name in ((lo, "lower"), (hi, "upper")):
            if abs(float(best[k]) - bound) <= EDGE_FRACTION * (hi - lo):
                notes.append(f"{LABELS[k]} {float(best[k]):g} is at the {name} end of the searched range "
                             f"({lo:g}-{hi:g})")
    if not notes:
        return []
    return ["**The winner sits at the edge of the space** (the best match may lie beyond it, so this preset is "
            "the closest among the settings searched, not necessarily the closest overall): " + "; ".join(notes)
            + ".", ""]


def build(tables: Path, preset: str, search_dir: Path) -> str:
    if not any((tables / f"summary_{sw}.csv").is_file() for sw in PAPER_SWEEPS):
        raise RunnerError(f"{tables}: no summary_<sweep>.csv (run `python -m experiments matched` first, or give "
                          "--tables the folder of the preset's tables)")
    presets = [preset] + (["default"] if (tables / "default" / "summary_boards.csv").exists() else [])
    folders = {preset: tables, **({"default": tables / "default"} if "default" in presets else {})}
    ct = claims_table(folders)
    ct.to_csv(tables / "claims.csv", index=False, float_format="%.6g")
    conf = load_search_conf()
    verdicts = sens = None
    if (search_dir / "verdicts_coarse.csv").exists():
        verdicts = pd.read_csv(search_dir / "verdicts_coarse.csv")
    if (search_dir / "verdicts_sensitivity.csv").exists():
        sens = pd.read_csv(search_dir / "verdicts_sensitivity.csv")
    timings = json.loads((tables / "timings.json").read_text()) if (tables / "timings.json").exists() else {}
    preset_yaml = (Path(__file__).resolve().parents[2] / "conf" / "preset" / f"{preset}.yaml")
    lines = [f"# The paper's claims under the `{preset}` preset and our default (generated)", "",
             f"Generated by `make reproduce-paper PRESET={preset}` (`python -m experiments matched`); do not edit by "
             "hand. Methods: the paper's four (`zhang_pless_linear`, `zhang_pless`, `vasconcelos`, `peng2022`) and "
             "`vasconcelos_msac` (Francisco as its authors' code runs it).", ""]
    for p, folder in folders.items():
        s = pd.concat([load_summary(folder, sw) for sw in PAPER_SWEEPS])
        half = 100 * float(((s["valid_hi95"] - s["valid_lo95"]) / 2).max())
        wall = timings.get(f"{p}_s")
        lo, hi = int(s["n_trials"].min()), int(s["n_trials"].max())
        n = f"{lo}" if lo == hi else f"{lo}-{hi}"
        g = ct[(ct["preset"] == p) & ct["term"].str.contains(":points:")]
        gap = float(((g["hi95"] - g["lo95"]) / 2).max()) if len(g) else float("nan")
        lines.append(f"- `{p}`: {n} trials per setting; widest 95% interval of a valid rate +-{half:.1f} points "
                     f"(Wilson), of a claimed valid-rate gap in points +-{gap:.1f} (paired bootstrap)"
                     + (f"; measured wall time {wall:.0f} s" if wall else "") + ".")
    lines += ["", "## The presets", "", "`default`: conf/scene/paper.yaml and the simulator's defaults (board tilt <= "
              "45 deg, 1 m boards, bearings over 60 deg, exact camera poses). "
              f"`{preset}` (`conf/preset/{preset}.yaml`), on top of the default:", "", "```yaml",
              preset_yaml.read_text().strip() if preset_yaml.exists() else "(missing)", "```", "",
              "## The objective, fixed before the search (`conf/search/paper.yaml`)", ""]
    lines += objective_lines(conf.objective) + [""]
    for p, folder in folders.items():
        sc = score({sw: load_trials(folder, sw) for sw in PAPER_SWEEPS}, conf.objective)
        lines.append(f"Objective of `{p}` at these trials: " + ", ".join(
            f"{r.objective:.3f} (Zhang = {r.zhang})" for r in sc.itertuples()) + ".")
    lines += ["", "## The search (`make search-paper`, `python -m experiments search`)", "",
              "Scrambled Sobol design over " + ", ".join(f"{LABELS[k]} {conf.space[k][0]:g}-{conf.space[k][1]:g}"
                                                          for k in SPACE_KEYS) +
              ", plus the default; common random numbers (every point draws trial t's random numbers alike). "
              "The fine stage re-runs the best coarse points and the default with more trials. The "
              "reproduction below does not reuse the search's trials: it is seeded by the settings as `make "
              "reproduce-paper` is, so the winner is judged on fresh data (no winner's curse from the search's "
              "noise).", ""]
    lines += _search_lines(search_dir)
    lines += edge_lines(search_dir, conf)
    lines += ["## Every claim under both presets", "",
              "Ours = Peng 2022 over the named method, per setting, with its paired 95% bootstrap interval "
              f"({N_BOOT} resamples of the trials). Verdicts with intervals (`experiments/paper/claims.py`): a "
              "setting counts as better or worse only when its whole interval is, else as a tie; *holds* = better "
              "somewhere, worse nowhere, and an interval reaches the claimed band (a single number: within a "
              "factor of two); *direction only* = so, but no interval reaches the band; *mixed* = worse "
              "somewhere, or our value does not exist at a setting; *does not hold* = better nowhere. Per-setting "
              "numbers: `claims.csv`.", ""]
    lines += claims_section(ct, presets, verdicts)
    lines += ["", "## Francisco under both readings", "",
              f"Each claim against Francisco under {READINGS[FRANCISCO]} (`{FRANCISCO}`) and under "
              f"{READINGS[FRANCISCO_CODE]} (`{FRANCISCO_CODE}`, MSAC selection: docs/METHOD.md), same intervals and "
              "rules; *fit* names the reading(s) under which the claim holds.", ""]
    lines += readings_section(folders, ct, presets)
    lines += ["", f"## How sensitive each verdict is (`{search_dir.name}/verdicts_sensitivity.csv`)", ""]
    lines += sensitivity_verdicts_section(sens, conf)
    held = verdicts if sens is None else pd.concat([d for d in (verdicts, sens) if d is not None])
    lines += ["", "## What it means", ""] + meaning(ct, presets, held)
    for p, folder in folders.items():
        for sw, spec in PAPER_SWEEPS.items():
            lines += ["", f"## `{p}`, sweep {sw}: valid-solution probability, % [95% Wilson interval]", ""]
            lines += method_table(load_summary(folder, sw), spec.x, valid_cell)
    lines += ["", f"Figures of `{preset}`: `figures/*.png` (the layout of the paper's Fig. 3-7)."]
    return "\n".join(lines).rstrip() + "\n"


def write_matched_report(tables: str | Path, preset: str, search_dir: str | Path) -> Path:
    path = Path(tables) / "REPORT.md"
    write_stamped(path, build(Path(tables), preset, Path(search_dir)))
    return path


def main(argv: Sequence[str] | None = None) -> None:
    ap = study_parser(__doc__)
    ap.add_argument("--tables", default="results/paper-matched")
    ap.add_argument("--preset", default="paper-matched")
    ap.add_argument("--search", default="results/search")
    a = ap.parse_args(argv)
    print(write_matched_report(a.tables, a.preset, a.search))
