"""``make real-data``: the three public rigs in ``../shared/real-data/`` end to end -> ``results/real/``.

Per data set: import (rig.public_sets, rig.importers), camera intrinsics from the images where the given ones
are rough (rig.intrinsics), extraction with near-duplicates merged and the background learnt from the poses
(rig.extract), a leaderboard of the methods (experiments.real_eval), the degeneracy verdict, and the scan drawn
on the image for two or more poses. Writes ``REPORT.md``, ``summary.json`` and ``overlay_*.png``.

    python -m experiments.real_data [--data ../shared/real-data] [--out results/real]

A missing data-set folder is reported as skipped (one line), never an error: the EdenShin and Kazmierczak data
carry no licence and are not part of the project.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from calib_core.geometry.transforms import invert_T
from rig.dataset import DatasetError
from rig.extract import ExtractOptions, extract, format_diagnostics
from rig.intrinsics import calibrate_intrinsics, find_corners, format_intrinsics
from rig.public_sets import ACFR, EDENSHIN, KAZMIERCZAK, load_acfr, load_edenshin, load_kazmierczak
from rig.report import capture_verdict, save_overlay

from .fingerprint import write_stamped
from .real_eval import (
    degeneracy_verdict,
    leaderboard,
    leaderboard_md,
    planar_calibration,
    range_noise_m,
)

ROOT = Path(__file__).resolve().parents[1]
METHODS = ("zhang_pless_linear", "zhang_pless", "vasconcelos", "peng2022", "lidarcam")
OVERLAY_METHOD = "lidarcam"


def _best_T(rows, prefer=OVERLAY_METHOD):
    """The preferred method's extrinsic, else the one with the lowest held-out (then in-sample) residual."""
    by = {r["method"]: r for r in rows if r["ok"]}
    if prefer in by:
        r = by[prefer]
    else:
        def key(r):
            cv = (r.get("cv") or {}).get("rms_mm")
            return (0, cv) if cv is not None and np.isfinite(cv) else (1, r.get("fit_rms_mm", np.inf))

        r = min(by.values(), key=key, default=None)
    return (None, None) if r is None else (np.asarray(r["T_lidar_cam"]), r["method"])


def _overlays(rs, obs, T, method, out: Path, names: list[str], images: dict, full_scans: dict) -> list[str]:
    """Overlay PNGs for poses ``names`` (image or a grey canvas with the stored corners); Markdown lines."""
    md = []
    poses = list(obs.meta.get("poses", []))
    for name in names:
        if name not in poses:
            continue
        b = obs.boards[poses.index(name)]
        gray = images.get(name)
        note = ""
        if gray is None:  # no image published: a grey canvas with the detected corners
            import cv2

            gray = np.full((rs.camera.height, rs.camera.width), 96, np.uint8)
            for u, v in rs.extra.get("corners", {}).get(name, np.zeros((0, 2))):
                cv2.circle(gray, (int(round(u)), int(round(v))), 2, 255, -1)
            note = " (no image published for this pose: grey canvas with its detected corners)"
        p = out / f"overlay_{rs.name.split('-')[0]}_{name}.png"
        save_overlay(p, gray, rs.camera, invert_T(T), b.T_cam_board, b.outline, full_scans.get(name), b.scan,
                     f"{rs.name} pose {name}: {method}")
        md.append(f"![pose {name}]({p.name}){note}")
    return md


def _section(rs, obs, rows, sigma, verdict, extra_md, overlays_md, published: bool) -> list[str]:
    md = [f"## {rs.name}", "", *[f"- {n}" for n in rs.notes], ""] + extra_md
    md += ["### Leaderboard", ""] + leaderboard_md(rows, sigma, published) + [""]
    md += ["### Degeneracy", "", verdict[0], ""]
    md += ["### Capture plan", "", capture_verdict(obs, _best_T(rows)[0]), ""]
    md += ["### Scan on the image", "", "Through the extrinsic named in each title (`lidarcam` where it solves); "
           "colour: distance to the board plane (mm); large dots: the board's segment; yellow: the board outline "
           "from the camera.", ""]
    return md + overlays_md + [""]


def run_edenshin(folder: Path, out: Path) -> tuple[list[str], dict]:
    rs = load_edenshin(folder)
    obs = rs.observations
    calib = rs.extra["bouguet"]
    rs.extra["corners"] = {str(v.index): v.corners_px for v in calib.views}
    sigma = range_noise_m(obs)
    rows = leaderboard(obs, METHODS, sigma, rs.published)
    T, m = _best_T(rows)
    verdict = degeneracy_verdict(obs, T, sigma)
    import cv2

    images = {"4": cv2.imread(str(folder / "data4.jpg"), cv2.IMREAD_GRAYSCALE)}
    full = {"4": np.fromfile(folder / "lidar40.bin", dtype="<f4").reshape(-1, 4)[:, :2]}
    ov = _overlays(rs, obs, T, m, out, ["4", "12"], images, full)
    s = calib.sigma
    extra = [f"Intrinsics (Bouguet): fc = {calib.camera.K[0, 0]:.2f}, {calib.camera.K[1, 1]:.2f} px "
             f"(1-sigma {s['fc'][0]:.2f}, {s['fc'][1]:.2f}), cc = {calib.camera.K[0, 2]:.2f}, "
             f"{calib.camera.K[1, 2]:.2f} px (1-sigma {s['cc'][0]:.2f}, {s['cc'][1]:.2f}); "
             f"{obs.n_boards} poses, {sum(len(b.scan) for b in obs.boards)} board points.", "",
             "Published extrinsic (RADLOCC `PHI`, `DELTA` converted with `rig.importers.radlocc`): "
             "the `vs published` column.", ""]
    return (_section(rs, obs, rows, sigma, verdict, extra, ov, True),
            {"rows": rows, "range_sigma_mm": 1000 * sigma, "verdict": verdict[0]})


def _with_corners(rs):
    """The data set's poses with their detector corners (found once; an empty array where none was found)."""
    poses, corners = [], {}
    for p in rs.dataset.poses:
        c = None if p.error else find_corners(p.read_image(), rs.board)
        corners[p.name] = c
        poses.append(dataclasses.replace(p, corners=np.zeros((0, 2)) if c is None else c))
    return tuple(poses), corners


def _extraction_md(diags, obs) -> list[str]:
    return ["### Extraction", "", "```", format_diagnostics(diags), "```", "",
            f"{obs.n_boards} boards after merging near-duplicates: "
            + (", ".join(f"{k} + {'/'.join(v)}" for k, v in obs.meta.get("merged", {}).items()) or "none"), ""]


def run_kazmierczak(folder: Path, out: Path) -> tuple[list[str], dict]:
    rs = load_kazmierczak(folder)
    poses, corners = _with_corners(rs)
    fit = calibrate_intrinsics({p.name: p.read_image() for p in poses if corners[p.name] is not None}, rs.board,
                               corners={k: v for k, v in corners.items() if v is not None})
    rs.camera = fit.camera
    ds = dataclasses.replace(rs.dataset, camera=fit.camera, poses=poses)
    # the Hokuyo's range depends on the square's colour, which bends the board's segment by a few cm: the arc
    # test is loosened for this rig (its board segments score 19-33 against the default 15)
    opts = ExtractOptions(outline_kind="lower_bound", range_sigma_m=0.03, max_curvature_chi2=60.0)
    obs, diags = extract(ds, opts)
    print(format_diagnostics(diags), flush=True)
    sigma = range_noise_m(obs)
    rows = leaderboard(obs, METHODS, sigma)
    T, m = _best_T(rows)
    verdict = degeneracy_verdict(obs, T, sigma)
    images = {p.name: p.read_image() for p in poses}
    full = {p.name: p.scan.points for p in poses if p.scan is not None}
    ov = _overlays(rs, obs, T, m, out, ["32", "41", "53", "60"], images, full)
    extra = ["### Camera intrinsics from the images", "",
             "The author's intrinsics are rough (principal point fixed at the image centre, 0.85 px); refitted "
             "from the detected boards:", ""] + format_intrinsics(fit) + [""]
    extra += ["Extraction options: outline not known (the pattern's outline is a lower bound), range sigma 30 mm "
              "for the segment split (the Hokuyo reads the black and white squares at ranges a few cm apart)."]
    extra += [""] + _extraction_md(diags, obs)
    used = [d for d in diags if d.used]
    return (_section(rs, obs, rows, sigma, verdict, extra, ov, False),
            {"rows": rows, "range_sigma_mm": 1000 * sigma, "verdict": verdict[0], "n_used": len(used),
             "n_detected": sum(c is not None for c in corners.values()), "intrinsics_rms_px": fit.rms_px})


def run_acfr(folder: Path, out: Path) -> tuple[list[str], dict]:
    rs = load_acfr(folder)
    poses, _ = _with_corners(rs)
    ds = dataclasses.replace(rs.dataset, poses=poses)
    obs, diags = extract(ds, ExtractOptions(outline_kind="lower_bound"))
    print(format_diagnostics(diags), flush=True)
    sigma = range_noise_m(obs)
    rows = leaderboard(obs, METHODS, sigma)
    T, m = _best_T(rows)
    verdict = degeneracy_verdict(obs, T, sigma)
    axes = _verdict_axes(obs, T, sigma)
    planar, T_planar = planar_calibration(obs, axes) if axes else ([], None)
    if T_planar is not None:
        T, m = T_planar, "lidarcam (planar)"
    images = {p.name: p.read_image() for p in poses}
    full = {p.name: p.scan.points for p in poses}
    ov = _overlays(rs, obs, T, m, out, ["00", "03"], images, full)
    extra = _extraction_md(diags, obs)
    section = _section(rs, obs, rows, sigma, verdict, extra, ov, False)
    if planar:
        i = section.index("### Scan on the image")
        section[i:i] = ["### Calibration of the determined part", ""] + planar + [""]
    return (section,
            {"rows": rows, "range_sigma_mm": 1000 * sigma, "verdict": verdict[0],
             "segments_deg": {d.name: d.bearing_deg for d in diags}, "ranges_m": {d.name: d.range_m for d in diags}})


def _verdict_axes(obs, T, sigma) -> tuple[str, ...]:
    """The mounting axes the library's degeneracy analysis names as not determined (empty without it)."""
    try:
        from calib_core.checks.degeneracy import undetermined_directions
    except ImportError:
        return ()
    d = undetermined_directions(obs, T, sigma)
    return tuple(d.axes) if not d.determined else ()


RUNNERS = ((EDENSHIN, run_edenshin), (KAZMIERCZAK, run_kazmierczak), (ACFR, run_acfr))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "real-data"), help="folder of the data sets")
    ap.add_argument("--out", default=str(ROOT / "results" / "real"), help="output folder")
    args = ap.parse_args(argv)
    data, out = Path(args.data), Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    md = ["# lidarcam on real data", "", "Written by `make real-data` (`python -m experiments.real_data`) from "
          f"`{args.data}`; each data set's SOURCE.md gives its repository, licence and formats.", ""]
    summary = {}
    for name, run in RUNNERS:
        folder = data / name
        print(f"== {name}", flush=True)
        if not folder.is_dir():
            md += [f"## {name}", "", f"Skipped: `{folder}` not found.", ""]
            print(f"skipped: {folder} not found")
            continue
        t1 = time.perf_counter()
        try:
            section, summary[name] = run(folder, out)
        except DatasetError as err:
            section, summary[name] = [f"## {name}", "", f"Import failed: {err}", ""], {"error": str(err)}
        summary.setdefault(name, {})["seconds"] = time.perf_counter() - t1
        md += section + [f"({name}: {time.perf_counter() - t1:.0f} s)", ""]
    md += [f"Total: {time.perf_counter() - t0:.0f} s wall."]
    write_stamped(out / "REPORT.md", "\n".join(md) + "\n")
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=str) + "\n")
    print(f"wrote {out / 'REPORT.md'} ({time.perf_counter() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    from .entry import run_main

    run_main(main)
