"""CLI verb ``lidarcam demo OUT`` (sample data: a simulated dataset folder and a short ROS 2 bag, with the
commands that calibrate each) and ``lidarcam bag --list-topics REC`` (a bag's topics with their message types and
counts).

``add_parsers(subparsers)`` registers ``demo``; ``list_topics`` serves ``bag --list-topics``.
"""

from __future__ import annotations

import json
import shlex
from pathlib import Path

DEMO_SIM = dict(n_boards=12, cam_width=640, cam_height=480, focal_px=600.0, lidar_res_deg=0.25, noise_mm=5.0,
                render_supersample=2, dist_min_m=2.0, dist_max_m=4.0, max_tilt_deg=55.0)
"""The demo's rig: 12 board poses at 2-4 m tilted up to 55 deg, a 640x480 camera, a 0.25 deg lidar with 5 mm range
noise."""
TOPICS = {"image": "/camera/image_raw", "scan": "/scan", "info": "/camera/camera_info"}


def demo_commands(out: Path) -> list[list[str]]:
    """The commands that calibrate the demo's folder and its bag (``lidarcam`` argv lists)."""
    o = str(out)
    return [
        ["extract", f"{o}/dataset", "--out", f"{o}/dataset_obs.json"],
        ["calibrate", f"{o}/dataset_obs.json", "--out", f"{o}/dataset_result.json"],
        ["bag", f"{o}/recording", "--image-topic", TOPICS["image"], "--scan-topic", TOPICS["scan"],
         "--camera-info-topic", TOPICS["info"], "--board", f"{o}/recording.board.yaml", "--out", f"{o}/bag_dataset"],
        ["extract", f"{o}/bag_dataset", "--out", f"{o}/bag_obs.json", "--range-sigma", "0.005"],
        ["calibrate", f"{o}/bag_obs.json", "--out", f"{o}/bag_result.json"],
    ]


def write_demo(out, seed: int = 1) -> dict:
    """Write ``out/dataset/`` (images, scans, board, camera: ``simulate.dataset``), ``out/recording/`` (a ROS 2
    sqlite3 bag of about 11 s: ``simulate.recording``) and ``out/truth.json`` (both true extrinsics)."""
    import yaml

    from simulate import SimOptions
    from simulate.dataset import write_dataset
    from simulate.recording import RecordingOptions, write_recording_bag

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    sim = SimOptions(**DEMO_SIM)
    ds = write_dataset(sim, seed, out / "dataset")
    T_ds = yaml.safe_load((ds / "ground_truth.yaml").read_text())["T_lidar_cam"]
    rec = RecordingOptions(fps=15.0, scan_hz=20.0, still_s=0.8, move_s=0.6, eased=False, ros=2, storage="sqlite3",
                           image_format="png", image_topic=TOPICS["image"], scan_topic=TOPICS["scan"],
                           info_topic=TOPICS["info"])
    truth = write_recording_bag(sim, seed, out / "recording", rec)
    doc = {"dataset": {"T_lidar_cam": T_ds}, "recording": {"T_lidar_cam": truth.T_lidar_cam.tolist()},
           "note": "T_lidar_cam maps camera points into the lidar frame (metres)"}
    (out / "truth.json").write_text(json.dumps(doc, indent=1) + "\n")
    return doc


def cmd_demo(args) -> int:
    """``lidarcam demo OUT``: write the sample data and print the commands that calibrate it."""
    from .outputs import writable_folder

    out = writable_folder(args.out, "OUT")
    write_demo(out, args.seed)
    print(f"wrote {out}/dataset (a dataset folder: camera.yaml, board.yaml, NNN.png + NNN.csv), {out}/recording "
          f"(a ROS 2 bag) and {out}/truth.json (the simulated extrinsics)")
    print("calibrate the folder:")
    cmds = demo_commands(out)
    for c in cmds[:2]:
        print("  lidarcam " + shlex.join(c))
    print("calibrate the bag (lidarcam bag --list-topics REC lists its topics):")
    for c in cmds[2:]:
        print("  lidarcam " + shlex.join(c))
    return 0


def list_topics(path) -> int:
    """Print every topic of the bag at ``path`` with its message type and message count."""
    from lidarcam.rig.bag import BagSource

    with BagSource(path) as src:
        counts, topics = src.message_counts(), src.topics()
    w = max((len(t) for t in topics), default=5)
    print(f"{'topic':<{w}}  {'messages':>8}  type")
    for t in sorted(topics):
        print(f"{t:<{w}}  {counts[t]:>8}  {topics[t]}")
    return 0


def add_parsers(subparsers) -> None:
    """Register the ``demo`` verb on an argparse subparsers object."""
    p = subparsers.add_parser(
        "demo", help="write sample data (a simulated dataset folder and a ROS 2 bag) and print how to calibrate it",
        description="Write OUT/dataset (rendered images, scans, board.yaml, camera.yaml), OUT/recording (a short "
                    "ROS 2 bag of the board moving and resting in front of the rig) and OUT/truth.json, then print "
                    "the lidarcam commands that calibrate each.")
    p.add_argument("out", help="folder to write")
    p.add_argument("--seed", type=int, default=1, help="simulation seed (default: %(default)s)")
    p.set_defaults(func=cmd_demo)
