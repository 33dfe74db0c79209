"""The capture planner checked against the simulator (``make plan-check``; sizes in ``conf/plan/check.yaml``).

1. Prediction: for the planner's own D-optimal sets of 4, 8 and 16 boards, with and without corner noise, the
   predicted ``rot_sigma_deg`` and ``trans_sigma_mm`` against the RMS error of ``lidarcam`` over fresh
   measurements of the same board poses (rotation error: the angle of ``R R_true^T``; translation: ``|t -
   t_true|``; the prediction is the root of a covariance trace, i.e. an RMS of exactly these).
2. Planned against random: at K = 4, 6, 8 boards (corner noise on), the planned poses' RMS errors against those of
   random feasible poses of the same workspace (the median over the random draws), each set measured afresh.
3. A vertical-boards workspace: what the planner names before any data.

Every calibration is stored as it finishes (one JSON per cell under ``results/plan/cells/``); a rerun skips the
cells already there (same configuration) and resumes exactly. Writes ``results/plan/REPORT.md``,
``summary.json`` and ``plan_check.png``.
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from calib_core import calibrate
from calib_core.data.camera import Camera
from calib_core.geometry.metrics import pose_errors
from calib_core.geometry.mounting import T_from_params
from calib_core.model.board_error import BoardErrorScale
from calib_core.planning.capture import plan_capture
from calib_core.planning.views import PlanRig, Workspace, board_poses_lidar, feasibility
from simulate import SimOptions, board_range_sigma_m, observe_poses
from simulate.camera import BoardSpec, CameraError, camera_matrix, checkerboard_corners

from ..engine.cli import positive_float, positive_int, study_parser
from ..engine.fingerprint import package_hash
from ..summary.intervals import bootstrap_interval
from .plan_report import write_plan_report

ROOT = Path(__file__).resolve().parents[2]
CONF = ROOT / "conf" / "plan" / "check.yaml"
OUT = ROOT / "results" / "plan"


def rig_of(o: SimOptions, T_lidar_cam: np.ndarray, workspace: Workspace | None = None) -> PlanRig:
    """The planner's rig of the simulator's settings ``o`` (its board frame, camera, lidar and noise; the
    per-board systematic scale the simulated files state, ``simulate.board_range_sigma_m``, as the calibration
    takes it)."""
    cam = Camera(camera_matrix(o.focal_px, o.cam_width, o.cam_height), [], o.cam_width, o.cam_height)
    sc = 0.0 if o.pose_mode == "exact" else o.pixel_noise_px
    return PlanRig(cam, T_lidar_cam, BoardSpec.of(o).outline(), checkerboard_corners(o), o.lidar_fov_deg,
                   o.lidar_res_deg, o.lidar_max_range_m, o.noise_mm / 1000.0, sc, o.image_margin_px + 15.0,
                   o.min_depth_m, o.min_points_per_board, workspace or Workspace(),
                   BoardErrorScale(board_range_sigma_m(o), 0.0))


def random_feasible(rig: PlanRig, k: int, rng: np.random.Generator, batch: int = 256) -> np.ndarray:
    """(k,6) poses drawn uniformly from the workspace's ranges, each feasible
    (``calib_core.planning.views.feasibility``)."""
    ws, out = rig.workspace, []
    ranges = np.array([ws.distance_m, ws.bearing_deg, ws.height_m, ws.turn_deg, ws.lean_deg, ws.roll_deg])
    while len(out) < k:
        p = rng.uniform(ranges[:, 0], ranges[:, 1], (batch, 6))
        ok = feasibility(rig, board_poses_lidar(rig, p))[0] < 0
        out.extend(p[ok][: k - len(out)])
    return np.array(out)


def errors(obs, method: str) -> tuple[float, float] | None:
    """(rotation error rad, translation error m) of ``method`` on ``obs``; None when it fails."""
    res = calibrate(obs, method=method)
    if not res.ok:
        return None
    e_R, e_t = pose_errors(res.T_lidar_cam, obs.T_lidar_cam_true)
    return float(np.radians(e_R)), float(e_t)


def run_cell(task: dict) -> dict:
    """Calibrate fresh measurements ``task["redraws"]`` times of the poses ``task["T_lidar_board"]``."""
    o = SimOptions.from_dict(task["options"])
    T_lc, T_lb = np.array(task["T_lidar_cam"]), np.array(task["T_lidar_board"])
    rot, trans, failed = [], [], 0
    for r in range(task["redraws"]):
        try:
            e = errors(observe_poses(o, T_lc, T_lb, task["seed"], r), task["method"])
        except CameraError:
            e = None
        if e is None:
            failed += 1
            continue
        rot.append(e[0])
        trans.append(e[1])
    return {**{k: task[k] for k in ("key", "part", "mode", "boards", "set")}, "rot_err": rot, "trans_err": trans,
            "failed": failed, "code": _code()}


def _code() -> str:
    """The fingerprint of the code a cell's numbers come from: the library and the simulator."""
    return f"{package_hash('calib_core')}+{package_hash('simulate')}"


def _key(task: dict) -> str:
    """A cell's file name: its settings and the code that computes it, so a cell of other code is never read."""
    blob = json.dumps({**{k: v for k, v in task.items() if k != "key"}, "code": _code()}, sort_keys=True)
    return hashlib.sha1(blob.encode()).hexdigest()[:12]


def _drop_stale(cells: Path) -> int:
    """Remove the stored cells computed by other code (or stored without a fingerprint); their count."""
    def code_of(f: Path) -> str | None:
        try:
            return json.loads(f.read_text()).get("code")
        except (ValueError, AttributeError):  # a damaged cell: computed again
            return None

    stale = [f for f in cells.glob("*.json") if code_of(f) != _code()]
    for f in stale:
        f.unlink()
    return len(stale)


def tasks(conf) -> tuple[list[dict], dict]:
    """Every cell of the check, and the planner's predictions and plans they test."""
    base = SimOptions(**OmegaConf.to_container(conf.sim))
    m = conf.mounting
    T_lc = T_from_params(np.r_[np.radians([m.roll_deg, m.pitch_deg, m.yaw_deg]), m.x_m, m.y_m, m.z_m])
    out, pred = [], {}

    def add(part, mode, n, s, o, T_lb, redraws):
        t = {"part": part, "mode": mode, "boards": int(n), "set": int(s), "options": o.to_dict(),
             "T_lidar_cam": T_lc.tolist(), "T_lidar_board": np.asarray(T_lb).tolist(), "redraws": int(redraws),
             "seed": int(conf.seed) + 1000 * int(n) + int(s), "method": str(conf.method)}
        t["key"] = _key(t)
        out.append(t)

    for mode in ("exact", "pixel"):
        o = SimOptions(**{**base.to_dict(), "pose_mode": mode})
        rig = rig_of(o, T_lc)
        for n in conf.prediction.boards:
            plan = plan_capture(rig, int(n))
            pred[f"{mode}:{n}"] = {"rot_sigma_deg": plan.after[-1].rot_sigma_deg,
                                   "trans_sigma_mm": plan.after[-1].trans_sigma_mm}
            add("prediction", mode, n, 0, o, plan.T_lidar_board, conf.prediction.redraws)
    o = SimOptions(**{**base.to_dict(), "pose_mode": "pixel"})
    rig = rig_of(o, T_lc)
    rng = np.random.default_rng(int(conf.seed))
    for k in conf.versus.boards:
        plan = plan_capture(rig, int(k))
        pred[f"planned:{k}"] = {"rot_sigma_deg": plan.after[-1].rot_sigma_deg,
                                "trans_sigma_mm": plan.after[-1].trans_sigma_mm}
        add("versus", "planned", k, 0, o, plan.T_lidar_board, conf.versus.redraws)
        for s in range(int(conf.versus.random_sets)):
            add("versus", "random", k, s + 1, o, board_poses_lidar(rig, random_feasible(rig, int(k), rng)),
                conf.versus.redraws)
    vert = plan_capture(rig_of(o, T_lc, Workspace(lean_deg=(0.0, 0.0))), int(conf.vertical.boards))
    pred["vertical"] = {"undetermined": list(vert.plan_undetermined), "message": vert.plan_message,
                        "boards": int(conf.vertical.boards)}
    return out, pred


def main(argv=None) -> int:
    ap = study_parser(__doc__)
    ap.add_argument("--conf", default=str(CONF), help="sizes and settings (default: %(default)s)")
    ap.add_argument("--out", default=str(OUT), help="results folder (default: %(default)s)")
    ap.add_argument("--jobs", type=positive_int, default=2, help="parallel workers (default: %(default)s)")
    ap.add_argument("--scale", type=positive_float, default=1.0, help="multiply every redraw count (e.g. 0.1 to try)")
    args = ap.parse_args(argv)
    conf = OmegaConf.load(args.conf)
    for part in ("prediction", "versus"):
        conf[part].redraws = max(2, int(round(conf[part].redraws * args.scale)))
    out = Path(args.out)
    cells = out / "cells"
    cells.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    todo, pred = tasks(conf)
    print(f"plan-check: {len(todo)} cells, planning took {time.perf_counter() - t0:.1f} s", flush=True)
    stale = _drop_stale(cells)
    missing = [t for t in todo if not (cells / f"{t['key']}.json").exists()]
    print(f"plan-check: {len(todo) - len(missing)} cells reused, {len(missing)} to compute"
          + (f" ({stale} stored cells of other code removed)" if stale else ""), flush=True)
    from joblib import Parallel, delayed

    done = len(todo) - len(missing)
    for res in Parallel(n_jobs=args.jobs, return_as="generator_unordered")(delayed(run_cell)(t) for t in missing):
        (cells / f"{res['key']}.json").write_text(json.dumps(res) + "\n")
        done += 1
        print(f"  [{done}/{len(todo)}] {res['part']} {res['mode']} {res['boards']} boards set {res['set']}: "
              f"{len(res['rot_err'])} ok, {res['failed']} failed ({time.perf_counter() - t0:.0f} s)", flush=True)
    results = [json.loads((cells / f"{t['key']}.json").read_text()) for t in todo]
    summary = summarise(results, pred, conf)
    summary["seconds"] = round(time.perf_counter() - t0, 1)
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    write_plan_report(out, summary)
    print(f"wrote {out / 'REPORT.md'}")
    return 0


def _rms_ci(x: np.ndarray, seed: int) -> tuple[float, float, float]:
    x = np.asarray(x, float)
    stat = float(np.sqrt(np.mean(x**2)))
    lo, hi = bootstrap_interval((x,), lambda a, axis: np.sqrt(np.mean(a**2, axis=axis)), seed)
    return stat, lo, hi


def _ratio_ci(rand_rms: np.ndarray, planned: np.ndarray, seed: int) -> tuple[float, float, float]:
    """median(random RMS) / RMS(planned errors), with a bootstrap interval over both samples."""
    def stat(r, p, axis):
        return np.median(r, axis=axis) / np.sqrt(np.mean(p**2, axis=axis))

    value = float(stat(rand_rms, planned, None))
    lo, hi = bootstrap_interval((rand_rms, planned), stat, seed)
    return value, lo, hi


def summarise(results: list[dict], pred: dict, conf) -> dict:
    """The check's figures: predicted against empirical RMS, planned against random, the vertical verdict."""
    out = {"prediction": [], "versus": [], "vertical": pred["vertical"], "method": str(conf.method),
           "redraws": {"prediction": int(conf.prediction.redraws), "versus": int(conf.versus.redraws)},
           "random_sets": int(conf.versus.random_sets)}
    for r in (r for r in results if r["part"] == "prediction"):
        p = pred[f"{r['mode']}:{r['boards']}"]
        rot = _rms_ci(np.degrees(r["rot_err"]), 1)
        tr = _rms_ci(1000 * np.asarray(r["trans_err"]), 2)
        out["prediction"].append({"mode": r["mode"], "boards": r["boards"], "n": len(r["rot_err"]),
                                  "failed": r["failed"], "pred_rot_deg": p["rot_sigma_deg"], "emp_rot_deg": rot,
                                  "pred_trans_mm": p["trans_sigma_mm"], "emp_trans_mm": tr,
                                  "ratio_rot": rot[0] / p["rot_sigma_deg"], "ratio_trans": tr[0] / p["trans_sigma_mm"]})
    for k in conf.versus.boards:
        cell = [r for r in results if r["part"] == "versus" and r["boards"] == int(k)]
        planned = next(r for r in cell if r["mode"] == "planned")
        rand = [r for r in cell if r["mode"] == "random"]
        row = {"boards": int(k), "pred": pred[f"planned:{k}"], "failed_planned": planned["failed"],
               "failed_random": int(sum(r["failed"] for r in rand))}
        for name, key, scale in (("rot_deg", "rot_err", np.degrees(1.0)), ("trans_mm", "trans_err", 1000.0)):
            p = scale * np.asarray(planned[key])
            rr = np.array([np.sqrt(np.mean((scale * np.asarray(r[key])) ** 2)) for r in rand if r[key]])
            row[f"planned_{name}"] = float(np.sqrt(np.mean(p**2)))
            row[f"random_median_{name}"] = float(np.median(rr))
            row[f"random_{name}"] = rr.tolist()
            row[f"ratio_{name}"] = _ratio_ci(rr, p, 3)
            row[f"beaten_{name}"] = int(np.sum(rr > row[f"planned_{name}"]))
        out["versus"].append(row)
    return out
