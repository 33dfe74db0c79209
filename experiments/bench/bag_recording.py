"""Measure the bag path end to end on a simulated recording: read + pick + pair (``lidarcam bag``), extract,
calibrate; check the kept frames are still ones and the extrinsic error.

    python -m experiments bag-recording                       # 2 minutes, 30 fps, 40 Hz, 10 mm, ROS 1 jpeg
    python -m experiments bag-recording --seconds 30 --ros 2 --storage mcap

Writing the bag (rendering every frame) is timed apart; ``--work DIR`` keeps the bag and reuses it on the next
run. Wall and CPU seconds of the conversion are both reported (the machine may be shared). Writes
``<out>/recording.json`` with the figures.
"""

from __future__ import annotations

import json
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from ..engine.cli import finite_float, nonnegative_float, positive_float, positive_int, study_parser
from ..engine.paths import repo_relative


def _recording(args, work: Path):
    """Write the bag into ``work`` (or reuse the one there): (bag path, truth dict, write seconds)."""
    from simulate import SimOptions
    from simulate.recording import RecordingOptions, write_recording_bag

    bag = work / ("rec.bag" if args.ros == 1 else "rec")
    if (work / "truth.json").exists():
        return bag, json.loads((work / "truth.json").read_text()), float("nan")
    period = args.still_s + args.move_s
    n = max(3, int((args.seconds + args.move_s) // period))
    sim = SimOptions(n_boards=n, noise_mm=args.noise_mm, dist_min_m=2.0, dist_max_m=5.0, render_supersample=2)
    rec = RecordingOptions(fps=args.fps, scan_hz=args.scan_hz, still_s=args.still_s, move_s=args.move_s,
                           time_offset_s=args.offset_s, image_format=args.format, ros=args.ros,
                           storage=args.storage, eased=not args.linear)
    t0 = time.perf_counter()
    tr = write_recording_bag(sim, args.seed, bag, rec)
    truth = {"T_lidar_cam": tr.T_lidar_cam.tolist(), "still": tr.still.tolist(), "n_images": tr.n_images,
             "n_scans": tr.n_scans, "time_offset_s": tr.time_offset_s}
    (work / "truth.json").write_text(json.dumps(truth) + "\n")
    return bag, truth, time.perf_counter() - t0


def measure(args) -> dict:
    from calib_core import calibrate
    from calib_core.geometry.metrics import pose_errors
    from lidarcam.rig.dataset import load_dataset
    from lidarcam.rig.extract import ExtractOptions, extract
    from lidarcam.rig.frombag import bag_to_dataset
    from lidarcam.rig.stills import PickOptions

    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="lidarcam-bag-"))
    work.mkdir(parents=True, exist_ok=True)
    bag, truth, t_write = _recording(args, work)
    size = sum(p.stat().st_size for p in ([bag] if bag.is_file() else bag.iterdir()))
    shutil.rmtree(work / "ds", ignore_errors=True)
    t0, c0 = time.perf_counter(), time.process_time()
    conv = bag_to_dataset(bag, work / "ds", "/camera/image_raw", "/scan", work / "rec.board.yaml",
                          camera_info_topic="/camera/camera_info",
                          opts=PickOptions(estimate_offset=True, max_poses=args.max_poses))
    t_pick, c_pick = time.perf_counter() - t0, time.process_time() - c0
    obs, _ = extract(load_dataset(work / "ds"), ExtractOptions(range_sigma_m=args.noise_mm / 1000))
    res = calibrate(obs)
    t_total, c_total = time.perf_counter() - t0, time.process_time() - c0
    still_iv = np.asarray(truth["still"])
    t = np.array([p["image_stamp_ns"] for p in conv.poses]) / 1e9
    still = ((t[:, None] >= still_iv[:, 0]) & (t[:, None] <= still_iv[:, 1])).any(axis=1)
    e_R, e_t = pose_errors(res.T_lidar_cam, np.asarray(truth["T_lidar_cam"])) if res.ok else (np.nan, np.nan)
    out = {"seconds": truth["n_images"] / args.fps, "images": truth["n_images"], "scans": truth["n_scans"],
           "still_stretches": len(still_iv), "bag_mb": size / 2**20, "write_s": t_write,
           "read_pick_wall_s": t_pick, "read_pick_cpu_s": c_pick, "total_wall_s": t_total, "total_cpu_s": c_total,
           "poses_kept": len(conv.poses), "poses_all_still": bool(still.all()), "boards_used": obs.n_boards,
           "ok": bool(res.ok), "e_R_deg": float(e_R), "e_t_mm": 1000 * float(e_t),
           "offset_true_ms": 1000 * truth["time_offset_s"], "offset_used_ms": 1000 * conv.sync["offset_s"],
           "offset_source": conv.sync["offset_source"], "normal_spread_deg": conv.normal_spread_deg,
           "summary": conv.summary()}
    if not args.work:
        shutil.rmtree(work, ignore_errors=True)
    return out


def main(argv=None) -> int:
    p = study_parser(__doc__)
    p.add_argument("--seconds", type=positive_float, default=120.0)
    p.add_argument("--fps", type=positive_float, default=30.0)
    p.add_argument("--scan-hz", type=positive_float, default=40.0)
    p.add_argument("--still-s", type=nonnegative_float, default=2.0)
    p.add_argument("--move-s", type=nonnegative_float, default=2.0)
    p.add_argument("--noise-mm", type=nonnegative_float, default=10.0)
    p.add_argument("--offset-s", type=finite_float, default=0.03)
    p.add_argument("--max-poses", type=positive_int, default=20)
    p.add_argument("--format", default="jpeg", choices=["raw", "png", "jpeg"])
    p.add_argument("--ros", type=int, default=1, choices=[1, 2])
    p.add_argument("--storage", default="sqlite3", choices=["sqlite3", "mcap"])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="results/bag")
    p.add_argument("--work", help="keep the bag, its truth and the dataset here; a later run reuses the bag")
    p.add_argument("--linear", action="store_true", help="constant-speed moves (default: eased)")
    args = p.parse_args(argv)
    fig = measure(args)
    print(fig.pop("summary"))
    for k, v in fig.items():
        print(f"{k:>32}: {v:.3f}" if isinstance(v, float) else f"{k:>32}: {v}")
    Path(args.out).mkdir(parents=True, exist_ok=True)
    shown = {**vars(args), **{k: repo_relative(v) for k in ("out", "work") if (v := getattr(args, k))}}
    (Path(args.out) / "recording.json").write_text(json.dumps({"args": shown, **fig}, indent=1) + "\n")
    return 0 if fig["ok"] and fig["poses_all_still"] else 1
