"""Corner error of each board kind against the rendered truth, and the calibration of rendered rigs (the
measurement behind docs/dataset.md's table of board kinds).

Per rig (a lens and a board kind, ``RIGS``) and seed: ``simulate.dataset.write_dataset`` renders a dataset folder with
every third board slid out of the image (``cut_every=3``); every pose's corners are detected as ``lidarcam extract``
does (``lidarcam.rig.detect``) and compared with the true corners projected through the true camera at the true pose
(ground_truth.yaml); then ``lidarcam extract DIR`` and ``lidarcam calibrate`` run with no option beyond the folder.

    python dev/board_kinds.py OUT_DIR [N_SEEDS] [RIG ...]      (default 3 seeds, every rig)

Prints one markdown row per rig: OpenCV's version, the corners' mean offset (x, y) and RMS against the truth (px),
their 95th percentile, the poses with a board found and used / with enough true corners in the image
(``lidarcam.rig.detect.check_spread``) / rendered, the poses cut by the image edge among them,
the corners per pose, and the calibration's worst rotation and translation error over the seeds (deg, mm) and in
units of its own 1-sigma.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FISHEYE = dict(cam_model="pinhole-equidistant", cam_params="-0.01,0.02,-0.01,0.002", focal_px=300.0, cam_width=800,
               cam_height=600, dist_min_m=0.7, dist_max_m=1.6)
DS = dict(cam_model="ds", cam_params="-0.2,0.6", focal_px=300.0, cam_width=800, cam_height=640, dist_min_m=0.7,
          dist_max_m=1.6)
OMNI = dict(cam_model="omni-radtan", cam_params="0.8,-0.05,0.01,0.0,0.0", focal_px=500.0, cam_width=800,
            cam_height=600, dist_min_m=1.0, dist_max_m=2.0)
RIGS = {
    "pinhole-checkerboard": ({}, None),
    "pinhole-charuco": ({}, ("charuco", 7, 5, 0.12, 0.09)),
    "pinhole-aprilgrid": ({}, ("aprilgrid", 6, 5, 0.12, 0.0)),
    "equidistant-charuco": (FISHEYE, ("charuco", 6, 5, 0.15, 0.11)),
    "ds-aprilgrid": (DS, ("aprilgrid", 4, 4, 0.17, 0.0)),
    "omni-kalibr-checkerboard": (OMNI, "kalibr"),
}
"""Rig name -> (SimOptions lens fields, Pattern arguments, or None for the checkerboard, ``kalibr`` for the
checkerboard written as a Kalibr target YAML)."""
SCENE = dict(n_boards=12, cam_width=640, cam_height=480, focal_px=600.0, lidar_res_deg=0.25, noise_mm=5.0,
             render_supersample=2, dist_min_m=1.2, dist_max_m=3.0, max_tilt_deg=50.0)


def rig_dataset(name: str, seed: int, out: Path) -> Path:
    from simulate import SimOptions
    from simulate.dataset import write_dataset
    from simulate.patterns import Pattern

    lens, pat = RIGS[name]
    pattern = None if pat in (None, "kalibr") else Pattern(*pat)
    folder = write_dataset(SimOptions(**{**SCENE, **lens}), seed, out, pattern=pattern,
                           cut_every=3 if pattern is not None else 0)
    if pat == "kalibr":   # the same checkerboard as Kalibr's target YAML
        import yaml

        b = yaml.safe_load((folder / "board.yaml").read_text())
        (folder / "board.yaml").write_text(yaml.safe_dump({
            "target_type": "checkerboard", "targetCols": b["cols"], "targetRows": b["rows"],
            "rowSpacingMeters": b["square_m"], "colSpacingMeters": b["square_m"], "outline_m": b["outline_m"],
            "origin_square": b["origin_square"]}))
    return folder


def corner_errors(folder: Path) -> dict:
    """Per pose of a dataset folder: detection errors against the truth (pixels), poses used, cut poses."""
    from calib_core.geometry.transforms import transform_points
    from lidarcam.rig.dataset import load_dataset
    from lidarcam.rig.detect import check_spread, detect_board
    from lidarcam.rig.extract_options import ExtractionError

    ds = load_dataset(folder)
    gt = ds.ground_truth["poses"]
    lens = ds.camera.lens
    errs, used, cut, per_pose, eligible = [], 0, 0, [], 0
    for pose in ds.poses:
        T = np.asarray(gt[pose.name]["T_cam_board"], float)
        X = transform_points(T, ds.board.corners)
        if lens is not None:
            uv = lens.project(X)
        else:
            import cv2

            uv = cv2.projectPoints(X, np.zeros(3), np.zeros(3), ds.camera.K, ds.camera.dist)[0].reshape(-1, 2)
        inside = (uv[:, 0] >= 0) & (uv[:, 0] <= ds.camera.width - 1) & (uv[:, 1] >= 0) & \
            (uv[:, 1] <= ds.camera.height - 1)
        is_cut = not inside.all()
        cut += is_cut
        try:
            if ds.board.identified:
                check_spread(ds.board, np.flatnonzero(inside))
            eligible += 1
        except ExtractionError:
            pass
        try:
            det = detect_board(pose.read_image(), ds.camera, ds.board)
        except ExtractionError:
            continue
        used += 1
        ids = np.arange(len(ds.board.corners)) if det.ids is None else det.ids
        errs.append(det.corners - uv[ids])
        per_pose.append(len(ids))
    e = np.concatenate(errs) if errs else np.zeros((0, 2))
    return {"err": e, "used": used, "poses": len(ds.poses), "cut": cut, "per_pose": per_pose, "eligible": eligible}


def calibrate(folder: Path) -> tuple[float, float, float, float]:
    """(rotation error deg, translation error mm, their 1-sigma) of ``lidarcam extract`` + ``calibrate``."""
    obs, res = folder.with_suffix(".obs.json"), folder.with_suffix(".res.json")
    lc = [sys.executable, "-m", "lidarcam"]
    subprocess.run(lc + ["extract", str(folder), "--out", str(obs)], check=True, capture_output=True)
    subprocess.run(lc + ["calibrate", str(obs), "--out", str(res)], check=True, capture_output=True)
    import yaml

    r = json.loads(res.read_text())
    T = np.asarray(r["T_lidar_cam"], float)
    T0 = np.asarray(yaml.safe_load((folder / "ground_truth.yaml").read_text())["T_lidar_cam"], float)
    c = np.clip((np.trace(T[:3, :3].T @ T0[:3, :3]) - 1) / 2, -1, 1)
    return (float(np.degrees(np.arccos(c))), 1000 * float(np.linalg.norm(T[:3, 3] - T0[:3, 3])),
            float(r["sigma_rot_deg"]), float(r["sigma_trans_mm"]))


def main(argv: list[str]) -> None:
    import cv2

    out = Path(argv[0])
    n = int(argv[1]) if len(argv) > 1 else 3
    rigs = argv[2:] or list(RIGS)
    print(f"OpenCV {cv2.__version__}")
    print("| rig | corner offset x, y (px) | RMS (px) | 95% (px) | poses used / with enough corners in view / all "
          "| cut by the edge | corners/pose | worst error deg, mm | worst error / 1-sigma |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name in rigs:
        e, used, poses, cut, per, cal, elig = [], 0, 0, 0, [], [], 0
        for seed in range(1, n + 1):
            folder = rig_dataset(name, seed, out / f"{name}-{seed}")
            r = corner_errors(folder)
            e.append(r["err"])
            used, poses, cut, per = used + r["used"], poses + r["poses"], cut + r["cut"], per + r["per_pose"]
            elig += r["eligible"]
            cal.append(calibrate(folder))
        err = np.concatenate(e)
        norm = np.linalg.norm(err, axis=1)
        c = np.array(cal)
        print(f"| {name} | {err[:, 0].mean():+.3f}, {err[:, 1].mean():+.3f} | {np.sqrt(np.mean(norm ** 2)):.3f} | "
              f"{np.percentile(norm, 95):.3f} | {used}/{elig}/{poses} | {cut} | {min(per)}-{max(per)} | "
              f"{c[:, 0].max():.2f}, {c[:, 1].max():.1f} | {np.max(c[:, 0] / c[:, 2]):.1f}, "
              f"{np.max(c[:, 1] / c[:, 3]):.1f} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
