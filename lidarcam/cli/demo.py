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
DEMO_FISHEYE = dict(n_boards=12, cam_model="pinhole-equidistant", cam_params="-0.01,0.02,-0.01,0.002", focal_px=300.0,
                   cam_width=800, cam_height=600, lidar_res_deg=0.25, noise_mm=5.0, render_supersample=2,
                   dist_min_m=0.7, dist_max_m=1.6, max_tilt_deg=50.0)
"""The demo's wide-angle rig: a fisheye (equidistant, about 150 deg across the image's 800 px) and a ChArUco board
(``DEMO_CHARUCO``) at 0.7-1.6 m, every third board cut by the image edge."""
DEMO_CHARUCO = dict(kind="charuco", cols=6, rows=5, square=0.15, marker=0.11, dictionary="DICT_5X5_100")
"""The fisheye rig's board: 6 x 5 squares of 0.15 m with 0.11 m markers (``simulate.patterns.Pattern``)."""
DEMO_ENTRIES = frozenset({"dataset", "recording", "recording.board.yaml", "truth.json", "fisheye_charuco",
                          "fisheye_recording", "fisheye_recording.board.yaml"})
"""What ``write_demo`` writes into its folder."""
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
        ["extract", f"{o}/fisheye_charuco", "--out", f"{o}/fisheye_obs.json"],
        ["calibrate", f"{o}/fisheye_obs.json", "--out", f"{o}/fisheye_result.json"],
        ["bag", f"{o}/fisheye_recording", "--image-topic", TOPICS["image"], "--scan-topic", TOPICS["scan"],
         "--camera-info-topic", TOPICS["info"], "--board", f"{o}/fisheye_recording.board.yaml", "--out",
         f"{o}/fisheye_bag_dataset"],
        ["extract", f"{o}/fisheye_bag_dataset", "--out", f"{o}/fisheye_bag_obs.json", "--range-sigma", "0.005"],
        ["calibrate", f"{o}/fisheye_bag_obs.json", "--out", f"{o}/fisheye_bag_result.json"],
    ]


def is_demo_folder(folder: Path) -> bool:
    """Whether ``folder`` holds only what ``write_demo`` and the commands it prints write (an earlier demo's)."""
    made = {Path(c[c.index("--out") + 1]).name for c in demo_commands(folder)}
    return {e.name for e in folder.iterdir()} <= DEMO_ENTRIES | made


def write_demo(out, seed: int = 1) -> dict:
    """Write ``out/dataset/`` (images, scans, board, camera: ``simulate.dataset``), ``out/recording/`` (a ROS 2
    sqlite3 bag of about 11 s: ``simulate.recording``), ``out/fisheye_charuco/`` (a fisheye and a ChArUco board,
    some boards cut by the image edge), ``out/fisheye_recording/`` (a ROS 2 bag of that fisheye rig, its CameraInfo
    ``equidistant``) and ``out/truth.json`` (the true extrinsics)."""
    import yaml

    from simulate import SimOptions
    from simulate.dataset import write_dataset
    from simulate.patterns import Pattern
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
    fe = write_dataset(SimOptions(**DEMO_FISHEYE), seed, out / "fisheye_charuco", pattern=Pattern(**DEMO_CHARUCO),
                       cut_every=3)
    T_fe = yaml.safe_load((fe / "ground_truth.yaml").read_text())["T_lidar_cam"]
    fe_truth = write_recording_bag(SimOptions(**DEMO_FISHEYE), seed, out / "fisheye_recording", rec,
                                   pattern=Pattern(**DEMO_CHARUCO))
    doc = {"dataset": {"T_lidar_cam": T_ds}, "recording": {"T_lidar_cam": truth.T_lidar_cam.tolist()},
           "fisheye_charuco": {"T_lidar_cam": T_fe},
           "fisheye_recording": {"T_lidar_cam": fe_truth.T_lidar_cam.tolist()},
           "note": "T_lidar_cam maps camera points into the lidar frame (metres)"}
    (out / "truth.json").write_text(json.dumps(doc, indent=1) + "\n")
    return doc


def cmd_demo(args) -> int:
    """``lidarcam demo OUT``: write the sample data and print the commands that calibrate it."""
    from .outputs import replaced_folder

    out = Path(args.out)
    with replaced_folder(out, "OUT", is_demo_folder, "an earlier demo's output") as scratch:
        write_demo(scratch, args.seed)
    print(f"wrote {out}/dataset (a dataset folder: camera.yaml, board.yaml, NNN.png + NNN.csv), {out}/recording "
          f"(a ROS 2 bag), {out}/fisheye_charuco (a fisheye camera and a ChArUco board, some boards cut by the "
          f"image edge), {out}/fisheye_recording (a ROS 2 bag of the fisheye + ChArUco rig) and {out}/truth.json "
          "(the simulated extrinsics)")
    print("calibrate the folder:")
    cmds = demo_commands(out)
    for c in cmds[:2]:
        print("  lidarcam " + shlex.join(c))
    print("calibrate the bag (lidarcam bag --list-topics REC lists its topics):")
    for c in cmds[2:5]:
        print("  lidarcam " + shlex.join(c))
    print("calibrate the fisheye + ChArUco folder:")
    for c in cmds[5:7]:
        print("  lidarcam " + shlex.join(c))
    print("calibrate the fisheye + ChArUco bag (its CameraInfo is 'equidistant', as ROS's camera_calibration "
          "writes a fisheye):")
    for c in cmds[7:]:
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
        "demo", help="write sample data (simulated dataset folders and a ROS 2 bag) and print how to calibrate them",
        description="Write OUT/dataset (rendered images, scans, board.yaml, camera.yaml), OUT/recording (a short "
                    "ROS 2 bag of the board moving and resting in front of the rig), OUT/fisheye_charuco (a fisheye "
                    "camera and a ChArUco board, some boards cut by the image edge), OUT/fisheye_recording (a ROS 2 "
                    "bag of that fisheye rig) and OUT/truth.json, then print the lidarcam commands that calibrate "
                    "each.")
    p.add_argument("out", help="folder to write (new, empty, or an earlier demo's, which is replaced; written "
                   "whole or not at all)")
    from .argtypes import seed_type

    p.add_argument("--seed", type=seed_type, default=1, help="simulation seed (default: %(default)s)")
    p.set_defaults(func=cmd_demo)
