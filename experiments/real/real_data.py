"""``make real-data``: the five public rigs in ``../shared/real-data/`` end to end -> ``results/real/``.

Per data set: import (lidarcam.rig.public_sets, the same functions and options as docs/real-rigs.md's commands), camera
intrinsics from the images where the given ones are rough (lidarcam.rig.intrinsics), extraction with near-duplicates
merged
and the background learnt from the poses (lidarcam.rig.extract), a leaderboard of the methods with leave-one-pose-out
residuals and spreads (experiments.real.real_eval), the degeneracy verdict, the scan drawn on the image, and on the sets
with at least 8 usable boards the paper's real experiment (experiments.real.real_subsets: Fig. 8, Fig. 9, valid rates).
Writes ``REPORT.md``, ``summary.json``, figures, and the observations under ``obs/`` (the leaderboard's real
suite reads them; those of the sets without a licence are not committed, see .gitignore).

    python -m experiments real-data [--data ../shared/real-data] [--out results/real] [--subsets 50]

A missing data-set folder under an existing data root is reported as skipped (one line); a missing data root, or
one holding none of the sets, is an error (one line, exit 2) and nothing is written.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from calib_core.data.io import save_observations
from calib_core.data.lines import range_sigma
from calib_core.geometry.transforms import invert_T
from calib_core.refine.joint import JOINT_INTRINSICS_MODEL, JOINT_MODEL
from lidarcam.rig import public_sets as ps
from lidarcam.rig.dataset import DatasetError
from lidarcam.rig.extract import direction_line, extract, format_diagnostics, noise_line
from lidarcam.rig.intrinsics import format_intrinsics, refit_camera
from lidarcam.rig.markdown import md_table
from lidarcam.rig.report import capture_advice, save_overlay

from ..engine.cli import nonnegative_int, positive_int, study_parser
from ..engine.fingerprint import write_stamped
from ..engine.keep import write_json_unless_timings
from ..engine.paths import repo_relative
from . import real_subsets as sub
from .real_eval import (
    degeneracy_note,
    leaderboard,
    leaderboard_md,
    planar_calibration,
    uncertainty_md,
)

ROOT = Path(__file__).resolve().parents[2]
REPORT_TIMING_COLUMNS = ("time (s)",)
REPORT_TIMING_PATTERNS = (r"\(\S+: \d+ s in one worker\)", r"Total: \d+ s wall")
"""What differs between two runs of unchanged code in REPORT.md: the time columns and the time sentences."""
METHODS = ("zhang_pless_linear", "zhang_pless", "vasconcelos", "peng2022", "lidarcam")
OVERLAY_METHOD = "lidarcam"
SHORT = {ps.EDENSHIN: "edenshin", ps.KAZMIERCZAK: "kazmierczak", ps.NOWICKI: "nowicki", ps.ACFR: "acfr",
         ps.YONGKGU: "yongkgu"}
LOADERS = {ps.EDENSHIN: ps.load_edenshin, ps.KAZMIERCZAK: ps.load_kazmierczak, ps.NOWICKI: ps.load_nowicki,
           ps.ACFR: ps.load_acfr, ps.YONGKGU: ps.load_yongkgu}
SUBSET_MIN_BOARDS = 8
"""The subset experiment runs on the sets with at least this many usable boards (the paper's largest count)."""


def _best(rows, prefer=OVERLAY_METHOD):
    """The preferred method's row where it solved, else the one with the lowest held-out residual."""
    by = {r["method"]: r for r in rows if r["ok"]}
    if prefer in by:
        return by[prefer]

    def key(r):
        cv = (r.get("cv") or {}).get("rms_mm")
        return (0, cv) if cv is not None and np.isfinite(cv) else (1, r.get("fit_rms_mm", np.inf))

    return min(by.values(), key=key, default=None)


def _best_held_out(rows):
    """The row of the best held-out method (lowest pooled held-out RMS among those that solved on all boards)."""
    ok = [r for r in rows if r["ok"] and np.isfinite((r.get("cv") or {}).get("rms_mm", np.nan))]
    return min(ok, key=lambda r: r["cv"]["rms_mm"], default=None)


def _images(rs) -> dict:
    import cv2

    if rs.dataset is not None:
        return {p.name: p.read_image() for p in rs.dataset.poses if p.image_path is not None}
    if rs.name == ps.EDENSHIN:
        return {"4": cv2.imread(str(rs.folder / "data4.jpg"), cv2.IMREAD_GRAYSCALE)}
    if rs.name == ps.YONGKGU:
        return {"11": cv2.imread(str(rs.folder / "im12.bmp"), cv2.IMREAD_GRAYSCALE)}
    return {}


def _local_note(rs) -> str:
    """For a set without a licence: its images stay out of the repository, so a picture drawn on one is written
    by ``make real-data`` for local reading and not committed (.gitignore)."""
    return (" (drawn on this set's own image; the set states no licence, so the picture is written locally by "
            "`make real-data` and not committed)") if rs.name in ps.UNLICENSED else ""


def _overlays(rs, obs, T, method, out: Path, names, images: dict, full_scans: dict) -> list[str]:
    md = []
    poses = list(obs.meta.get("poses", []))
    for name in [n for n in names if n in poses]:
        b = obs.boards[poses.index(name)]
        gray = images.get(name)
        note = ""
        if gray is None:  # no image published: a grey canvas with the board's corners
            import cv2

            gray = np.full((rs.camera.height, rs.camera.width), 96, np.uint8)
            for u, v in (b.corners_px if b.has_corners else np.zeros((0, 2))):
                cv2.circle(gray, (int(round(u)), int(round(v))), 2, 255, -1)
            note = " (no image published for this pose: grey canvas with its detected corners)"
        p = out / f"overlay_{SHORT[rs.name]}_{name}.png"
        save_overlay(p, gray, rs.camera, invert_T(T), b.T_cam_board, b.outline, full_scans.get(name), b.scan,
                     f"{rs.name} pose {name}: {method}")
        md.append(f"![pose {name}]({p.name}){note}{_local_note(rs)}")
    return md


def _observations(rs) -> tuple:
    """(observations, extraction Markdown, intrinsics Markdown) of a loaded set."""
    if rs.observations is not None:
        return rs.observations, [], []
    ds, intr = rs.dataset, []
    if rs.refit_intrinsics:
        ds, fit = refit_camera(ds)
        rs.camera = fit.camera
        intr = ["### Camera intrinsics from the images", "", "The given intrinsics are rough; refitted from the "
                "detected boards (`--refit-intrinsics`):", ""] + format_intrinsics(fit) + [""]
    obs, diags = extract(ds, rs.options)
    merged = ", ".join(f"{k} + {'/'.join(v)}" for k, v in obs.meta.get("merged", {}).items()) or "none"
    md = ["### Extraction", "", "```", format_diagnostics(diags), "```", "",
          f"{sum(d.used for d in diags)} of {len(diags)} poses used, {obs.n_boards} boards after merging "
          f"near-duplicates (merged: {merged}). {noise_line(obs.meta)[0].upper()}{noise_line(obs.meta)[1:]}; "
          f"{direction_line(obs.meta)}.", ""]
    return obs, md, intr


def _covariance_md(rows) -> list[str]:
    r = next((r for r in rows if r["method"] == "lidarcam"), None)
    if r is None or not r["ok"]:
        return []
    model = r.get("covariance_model") or "-"
    why = {JOINT_MODEL: "every board carries its image corners and the file its camera, so the joint model over "
                        "corners and ranges ran (board poses estimated, the intrinsics taken as exact: the file "
                        "states no std_intrinsics)",
           JOINT_INTRINSICS_MODEL: "every board carries its image corners and the file its camera with "
                                   "std_intrinsics, so the joint model ran with the intrinsics as parameters under "
                                   "that prior (board poses estimated)"}.get(model, (
        "the boards carry no image corners, so only the range-only model can run (board poses taken as exact)"))
    return [f"Covariance model of `lidarcam`: **{model}**: {why}.", ""]


def fair_references(rows) -> dict[str, dict]:
    """Method -> the row its subsets are judged against: the all-board answer of the best held-out method other
    than itself (``_best_held_out`` over the other methods' rows). No method is judged against its own answer, and
    every method of a set by the same rule; a method with no other method solved on all boards has none."""
    out = {}
    for m in METHODS:
        ref = _best_held_out([r for r in rows if r["method"] != m])
        if ref is not None:
            out[m] = ref
    return out


def _reference_sigmas(ref) -> tuple[float | None, float | None, str]:
    """(rotation deg, translation mm, which) 1-sigma of a reference answer: reported, else its leave-one-out spread."""
    sr, st, which = ref.get("sigma_rot_deg"), ref.get("sigma_trans_mm"), "reported"
    if not sr:  # a method without a covariance: the spread of its leave-one-out answers
        sr, st, which = ref.get("loo_sigma_rot_deg"), ref.get("loo_sigma_trans_mm"), "leave-one-out"
    return sr, st, which


def _subset_md(rs, obs, rows, out: Path, images: dict, n_subsets: int, n_jobs: int) -> tuple[list[str], dict]:
    refs = fair_references(rows)
    if not refs:
        return ["No method solved on all boards: no reference for the subset experiment.", ""], {}
    T_prior = refs[sub.PRIOR_METHOD]["T_lidar_cam"] if sub.PRIOR_METHOD in refs else None
    df = sub.run_subsets(SHORT[rs.name], obs, METHODS, out, n_jobs=n_jobs, n=n_subsets, T_prior=T_prior)
    judged = {m: m for m in METHODS} | ({sub.PRIOR_LABEL: sub.PRIOR_METHOD} if T_prior is not None else {})
    parts, ref_rows = [], []
    for label, m in judged.items():
        d = df[df["method"] == label]
        if m not in refs:
            parts.append(d.assign(e_R_deg=np.nan, e_t_m=np.nan, valid=False, valid_3sigma=False))
            ref_rows.append([f"`{m}`", "none", "-"])
            continue
        sr, st, which = _reference_sigmas(refs[m])
        parts.append(sub.valid_columns(d, np.asarray(refs[m]["T_lidar_cam"]), sr, None if st is None else st / 1000))
        if label == m:
            ref_rows.append([f"`{m}`", f"`{refs[m]['method']}`",
                             f"{sr:.2f} deg / {st:.1f} mm ({which})" if sr else "-"])
    df = pd.concat(parts).sort_index()
    fig9 = out / f"fig9_{SHORT[rs.name]}.png"
    sub.fig9(df, METHODS, fig9, f"{rs.name}: {n_subsets} random subsets per board count")
    md = ["### The paper's real experiment (Sec. 3.2)", "",
          f"{n_subsets} seeded random subsets of the {obs.n_boards} boards per board count, every method. Fig. 9: "
          "theta_R and mu_t (eq. 15) of each answer:", "", f"![Fig. 9]({fig9.name})", "",
          "Valid rate, each method against the all-board answer of the best held-out method other than itself (no "
          "method is judged against its own answer): within 8 deg / 0.8 m [95% Wilson interval over the subsets], "
          "and within 3 of that answer's 1-sigma; a failure or a refusal counts as invalid:", ""]
    md += sub.valid_table(df, list(judged)) + [""]
    if T_prior is not None:
        md += [f"`{sub.PRIOR_LABEL}`: `{sub.PRIOR_METHOD}` given a rough guess of the mounting, as a user with a tape "
               f"measure has one: for each subset the reference answer of `{sub.PRIOR_METHOD}` with a rotation error "
               f"drawn from N(0, {sub.PRIOR_SIGMA_DEG:g} deg) about each axis and a translation error from N(0, "
               f"{sub.PRIOR_SIGMA_MM:g} mm) along each (seeded by the set and the subset), given with those sigmas "
               f"(`calibrate(obs, \"{sub.PRIOR_METHOD}\", prior=...)`). Where the data leave a tie, the prior decides; "
               "where the boards leave axes free (every board vertical), the prior's values hold them, so the answer "
               "is as close as the guess there and its 1-sigma the guess's (the 3-sigma column tests that); "
               f"alone, the guess is within {sub.VALID_DEG:g} deg / {sub.VALID_M:g} m of the reference in "
               f"{100 * sub.guesses_valid(SHORT[rs.name], df, T_prior):.0f}% of the subsets.", ""]
    md += ["References:", ""] + md_table(["method judged", "reference", "its 1-sigma"], ref_rows, "lll") + [""]
    own = next((r for r in rows if r["method"] == sub.PRIOR_METHOD and r["ok"]), None)
    T_own = None if own is None else np.asarray(own["T_lidar_cam"])
    unc_md, unc = sub.uncertainty_table(df, sub.PRIOR_METHOD, T_own)
    md += [f"`{sub.PRIOR_METHOD}` per board count: how often it refuses, naming an axis as not determined by the "
           "subset's boards (`calib_core.checks.degeneracy`; the axes named, counted over the subsets), its NEES "
           f"(`e^T P^-1 e` with the subset's own covariance, 6 when honest) against its own all-board answer "
           "(that answer's error left out: an upper bound where the subset shares boards with it), and its valid "
           "and within-3-sigma rates from the table above with their ratio (1 when every valid answer is also "
           "within 3 sigmas), then the same against its own all-board answer with each subset's own 1-sigma (the "
           "test of the subset's reported uncertainty):", ""] + unc_md + [""]
    md += _fig8(rs, obs, df, out, images)
    rates = {m: {int(k): float(d["valid"].mean()) for k, d in df[df["method"] == m].groupby("n_boards")}
             for m in judged}
    return md, {"reference": {m: r["method"] for m, r in refs.items()}, "valid": rates,
                "per_count": {"method": sub.PRIOR_METHOD, **_per_count(unc)}}


def _per_count(r: pd.DataFrame) -> dict:
    """``uncertainty_table``'s rows as JSON: per board count, its columns (None for NaN)."""
    def val(v):
        if isinstance(v, str):
            return v
        return None if not math.isfinite(float(v)) else (int(v) if float(v).is_integer() and not
                                                          isinstance(v, float) else float(v))

    return {str(int(x.pop("n_boards"))): {k: val(v) for k, v in x.items()} for x in r.to_dict("records")}


def _fig8(rs, obs, df, out: Path, images: dict) -> list[str]:
    """Fig. 8: on one image, the board's scan through two methods' answers from the first 4-board subset that
    holds a pose with an image and on which both solved."""
    poses = list(obs.meta.get("poses", []))
    with_image = [poses.index(n) for n in images if n in poses]
    two = ("peng2022", "lidarcam")
    for s in df[df["n_boards"] == 4]["subset"].unique():
        d = df[(df["subset"] == s) & df["method"].isin(two)]
        idx = [int(i) for i in str(s).split()]
        shown = [i for i in with_image if i in idx]
        if len(d) == 2 and d["ok"].astype(bool).all() and shown:
            i = shown[0]
            answers = {m: np.array(json.loads(d[d["method"] == m]["T"].iloc[0])) for m in two}
            p = out / f"fig8_{SHORT[rs.name]}.png"
            sub.fig8(images[poses[i]], rs.camera, obs.boards[i], answers, p,
                     f"{rs.name} pose {poses[i]}: boards {s} (4), laser points through peng2022 (red) and lidarcam "
                     "(cyan)")
            return ["Fig. 8: the laser points of one pose through two methods calibrated on 4 boards:", "",
                    f"![Fig. 8]({p.name}){_local_note(rs)}", ""]
    return []


def _undetermined(obs, T, sigma) -> tuple[str, ...]:
    """The mounting axes the library's degeneracy analysis names as not determined."""
    from calib_core.checks.degeneracy import undetermined_directions

    d = undetermined_directions(obs, T, sigma)
    return tuple(d.axes) if not d.determined else ()


def run_set(name: str, folder: Path, out: Path, n_subsets: int, n_jobs: int) -> tuple[list[str], dict]:
    """One data set end to end: its report section and summary."""
    rs = LOADERS[name](folder)
    obs, extraction_md, intrinsics_md = _observations(rs)
    (out / "obs").mkdir(exist_ok=True)
    shown = replace(obs, meta={**obs.meta, "dataset": repo_relative(folder)}) if obs.meta else obs
    save_observations(shown, out / "obs" / f"{SHORT[name]}.json")
    sigma = range_sigma(obs)  # from the scan lines alone, no extrinsic
    rows = leaderboard(obs, METHODS, sigma, rs.published)
    best = _best(rows)
    T = None if best is None else np.asarray(best["T_lidar_cam"])
    md = [f"## {name}", "", *[f"- {n}" for n in rs.notes], ""] + intrinsics_md + extraction_md
    summary: dict = {"rows": rows, "range_sigma_mm": 1000 * sigma, "n_boards": obs.n_boards,
                     "poses": obs.meta.get("poses")}
    verdict = degeneracy_note(obs, T, sigma) if T is not None else ("no method solved", None)
    md += ["### Leaderboard", ""] + leaderboard_md(rows, sigma, rs.published is not None) + [""]
    md += _covariance_md(rows) + uncertainty_md(rows) + [""]
    md += ["### Degeneracy", "", verdict[0], ""]
    md += ["### Capture plan", "", capture_advice(obs), ""]
    axes = _undetermined(obs, T, sigma) if verdict[1] is False else ()
    if axes:
        planar, T_planar = planar_calibration(obs, axes)
        md += ["### Calibration of the determined part", ""] + planar + [""]
        summary["planar"] = planar
        if T_planar is not None:
            T, best = T_planar, {"method": "lidarcam (planar)"}
    images = _images(rs)
    if T is not None:
        full = {p.name: p.scan.points for p in rs.dataset.poses if p.scan is not None} if rs.dataset else {}
        if name == ps.EDENSHIN:
            full = {"4": np.fromfile(folder / "lidar40.bin", dtype="<f4").reshape(-1, 4)[:, :2]}
        names = list(images)[:: max(1, len(images) // 3)][:4] or list(obs.meta.get("poses", []))[:2]
        md += ["### Scan on the image", "", "Through the extrinsic named in each title; colour: distance to the board "
               "plane (mm); large dots: the board's segment; yellow: the pattern's outline (a lower bound of the "
               "board's).", ""] + _overlays(rs, obs, T, best["method"], out, names, images, full) + [""]
    if obs.n_boards >= SUBSET_MIN_BOARDS and n_subsets > 0:
        smd, summary["subsets"] = _subset_md(rs, obs, rows, out, images, n_subsets, n_jobs)
        md += smd
    return md, summary


def _timed_set(name: str, folder: Path, out: Path, n_subsets: int) -> tuple[str, list[str], dict, str]:
    """``run_set`` in one worker, timed; an import failure is the section's one line. Returns the name, the
    section, the summary and what the run printed (held back, so that the parent prints each set's lines under
    its own heading whole, not interleaved with another worker's)."""
    t1 = time.perf_counter()
    log = io.StringIO()
    with contextlib.redirect_stdout(log), contextlib.redirect_stderr(log):
        try:
            section, summary = run_set(name, folder, out, n_subsets, n_jobs=1)
        except DatasetError as err:
            section, summary = [f"## {name}", "", f"Import failed: {err}", ""], {"error": str(err)}
    summary["seconds"] = time.perf_counter() - t1
    return name, section, summary, log.getvalue()


def print_set(name: str, seconds: float, log: str) -> None:
    """One data set's block: its heading, the lines its run printed, its time."""
    print("\n".join([f"== {name}", *log.rstrip("\n").splitlines(), f"== {name}: {seconds:.0f} s"]), flush=True)


def present_sets(data: Path) -> list[str]:
    """The data sets found under the root ``data``; DatasetError (one line) if the root is not a folder or holds
    none of them, so a mistyped ``--data`` never overwrites the report with an empty one."""
    if not data.is_dir():
        raise DatasetError("data root not found (--data, or REAL_DATA= for make real-data); nothing written",
                           file=str(data))
    present = [n for n in LOADERS if (data / n).is_dir()]
    if not present:
        raise DatasetError(f"none of the data sets {', '.join(LOADERS)} under this root; nothing written",
                           file=str(data))
    return present


def main(argv=None) -> int:
    ap = study_parser(__doc__)
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "real-data"), help="folder of the data sets")
    ap.add_argument("--out", default=str(ROOT / "results" / "real"), help="output folder")
    ap.add_argument("--subsets", type=nonnegative_int, default=sub.N_SUBSETS,
                    help="random subsets per board count (0: none)")
    ap.add_argument("--jobs", type=positive_int, default=2, help="parallel workers (one data set each at a time)")
    args = ap.parse_args(argv)
    data, out = Path(args.data), Path(args.out)
    present = present_sets(data)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    md = ["# lidarcam on real data", "", "Written by `make real-data` (`python -m experiments real-data`) from "
          f"`{repo_relative(data)}`; each data set's SOURCE.md gives its repository, licence and formats; "
          "[docs/real-rigs.md](../../docs/real-rigs.md) has the commands that give the same boards.", ""]
    from joblib import Parallel, delayed

    for n in LOADERS:
        if n not in present:
            print(f"skipped {n}: {repo_relative(data / n)} not found", flush=True)
    done = {}
    for name, section, summ, log in Parallel(n_jobs=args.jobs, return_as="generator_unordered")(
            delayed(_timed_set)(n, data / n, out, args.subsets) for n in present):
        print_set(name, summ["seconds"], log)
        done[name] = section, summ
    summary = {}
    for name in LOADERS:
        if name not in done:
            md += [f"## {name}", "", f"Skipped: `{repo_relative(data / name)}` not found.", ""]
            continue
        section, summary[name] = done[name]
        md += section + [f"({name}: {summary[name]['seconds']:.0f} s in one worker)", ""]
    md += [f"Total: {time.perf_counter() - t0:.0f} s wall ({args.jobs} workers, one data set each at a time)."]
    # timings alone differ between runs: a report that differs only in them is kept as it is
    write_stamped(out / "REPORT.md", "\n".join(md) + "\n", timing_columns=REPORT_TIMING_COLUMNS,
                  timing_patterns=REPORT_TIMING_PATTERNS)
    write_json_unless_timings(out / "summary.json", summary, keys=("seconds",))
    print(f"wrote {out / 'REPORT.md'} ({time.perf_counter() - t0:.0f} s)")
    return 0
