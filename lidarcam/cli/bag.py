"""CLI verb ``lidarcam bag BAG --image-topic T --scan-topic T --board board.yaml --out DATASET``: a ROS 1 / ROS 2
recording -> a dataset folder (docs/dataset.md) of still frames paired with scans, and picking.json.

``add_parsers(subparsers)`` registers the verb. A bad bag, topic or file raises a LidarcamError, which
``lidarcam.cli.main`` prints as one line and exits 2.
"""

from __future__ import annotations

from pathlib import Path

from lidarcam.rig.extract_options import SCAN_DIRECTIONS


def cmd_bag(args) -> int:
    """``lidarcam bag``: pick, pair and write; prints the reason counts and the sync (``--list-topics``: the
    bag's topics only)."""
    from lidarcam.rig.dataset import DatasetError
    from lidarcam.rig.extract import ExtractOptions
    from lidarcam.rig.frombag import bag_to_dataset
    from lidarcam.rig.stills import PickOptions

    from .importer import is_dataset_folder
    from .outputs import replaced_folder
    from .wording import cli_hint

    opts = PickOptions(max_poses=args.max_poses, still_px=args.still_px, quiet_grey=args.quiet_grey,
                       min_run=args.min_run, scan_still_m=args.scan_still, min_angle_deg=args.min_angle,
                       min_move_m=args.min_move, sync_tol_s=args.sync_tol, time_offset_s=args.time_offset,
                       estimate_offset=args.estimate_offset, max_offset_s=args.max_offset_time)
    if args.list_topics:
        from .demo import list_topics

        return list_topics(args.bag)
    need = [f for f, v in (("--image-topic", args.image_topic), ("--scan-topic", args.scan_topic),
                           ("--board", args.board), ("--out", args.out)) if v is None]
    if need:
        raise DatasetError(f"{', '.join(need)} required (or --list-topics to see the bag's topics)", file=args.bag)
    from .rig import check_noise_flags

    check_noise_flags(args)
    eo = ExtractOptions(max_offset_m=args.max_offset, range_sigma_m=args.range_sigma)
    with replaced_folder(args.out, "--out", is_dataset_folder, "a dataset folder") as scratch:
        conv = bag_to_dataset(args.bag, scratch, args.image_topic, args.scan_topic, args.board,
                              camera_info_topic=args.camera_info_topic, camera_path=args.camera, opts=opts,
                              extract_opts=eo, scan_direction=args.scan_direction)
    conv.out = Path(args.out)
    print(conv.summary())
    est = conv.sync.get("estimate")
    if est is not None and not est["reliable"]:
        print(f"warning: time offset estimate unreliable (peak correlation {est['correlation']:.2f}); "
              f"used {1000 * conv.sync['offset_s']:.1f} ms")
    print(f"wrote {conv.out} ({len(conv.poses)} poses) and {conv.out / 'picking.json'}")
    if not conv.poses:
        print("no still frame passed: see the reasons in picking.json")
        return 1
    print(f"capture plan: {cli_hint(_capture_advice(conv.out, eo))}")
    return 0


def _capture_advice(folder, eo) -> str:
    """The capture planner's verdict on the poses written to ``folder``, extracted as ``lidarcam extract`` would."""
    from lidarcam.rig.dataset import load_dataset
    from lidarcam.rig.extract import extract
    from lidarcam.rig.report import capture_advice

    obs, _ = extract(load_dataset(folder), eo)
    return capture_advice(obs) if obs.n_boards else "no plan: no pose of the folder gives a board"


def add_parsers(subparsers) -> None:
    """Register the ``bag`` verb on an argparse subparsers object."""
    from .argtypes import finite_float

    p = subparsers.add_parser(
        "bag", help="a ROS 1 / ROS 2 bag -> a dataset folder of still frames paired with scans",
        description="Read a ROS 1 .bag or a ROS 2 bag (sqlite3 or mcap) without ROS, pick the frames where the "
                    "board is detected and still, pair each with the nearest scan, and write the dataset layout "
                    "of docs/dataset.md plus picking.json (why each frame was kept or skipped). Then run "
                    "`lidarcam extract DATASET` and `lidarcam calibrate`.")
    p.add_argument("bag", help="ROS 1 .bag file or ROS 2 bag folder")
    p.add_argument("--list-topics", action="store_true",
                   help="list the bag's topics with their message types and counts, and stop")
    p.add_argument("--image-topic", help="sensor_msgs/Image or CompressedImage topic")
    p.add_argument("--scan-topic", help="sensor_msgs/LaserScan topic")
    p.add_argument("--camera-info-topic", help="sensor_msgs/CameraInfo topic (else --camera)")
    p.add_argument("--camera", help="camera file (OpenCV keys, ROS camera_info or Kalibr camchain), when the bag has "
                   "no usable CameraInfo")
    p.add_argument("--board", help="board.yaml of the checkerboard (docs/dataset.md)")
    p.add_argument("--out", help="dataset folder to write")
    g = p.add_argument_group("picking")
    g.add_argument("--max-poses", type=int, default=20, help="keep at most this many poses (default: %(default)s)")
    g.add_argument("--still-px", type=finite_float, default=0.5, metavar="PX",
                   help="largest RMS corner motion to a neighbouring frame (default: %(default)s px)")
    g.add_argument("--quiet-grey", type=finite_float, default=0.0, metavar="G",
                   help="thumbnail change under which a frame is quiet, grey levels (default: automatic)")
    g.add_argument("--min-run", type=int, default=3, help="fewest quiet frames in a still run (default: %(default)s)")
    g.add_argument("--scan-still", type=finite_float, default=0.0, metavar="M",
                   help="largest median shift of the board segment within a still run, metres (default: "
                        "automatic, 4 sigma of the median at --range-sigma)")
    g.add_argument("--min-angle", type=finite_float, default=5.0, metavar="DEG",
                   help="poses closer than this in rotation ... (default: %(default)s deg)")
    g.add_argument("--min-move", type=finite_float, default=0.10, metavar="M",
                   help="... and this in board-centre position are one pose (default: %(default)s m)")
    g = p.add_argument_group("time sync")
    g.add_argument("--sync-tol", type=finite_float, default=None, metavar="S",
                   help="refuse an image whose nearest scan is further than this (default: half the scan period)")
    g.add_argument("--time-offset", type=finite_float, default=0.0, metavar="S",
                   help="scan clock minus image clock, seconds (default: %(default)s)")
    g.add_argument("--estimate-offset", action="store_true",
                   help="estimate a constant clock offset from the moving board (falls back to --time-offset "
                        "when the estimate is unreliable)")
    g.add_argument("--max-offset-time", type=finite_float, default=0.5, metavar="S",
                   help="search the offset within +- this (default: %(default)s s)")
    g = p.add_argument_group("scan segment")
    g.add_argument("--max-offset", type=finite_float, default=0.5, metavar="M",
                   help="bound on the lidar-camera separation (default: %(default)s m)")
    g.add_argument("--range-sigma", type=float, default=None, metavar="M",
                   help="lidar range noise, 1 sigma (default: 0.02 m for the picking; the capture plan's extraction "
                   "estimates it from the boards' segments, as lidarcam extract does)")
    g.add_argument("--scan-direction", choices=SCAN_DIRECTIONS, default=None,
                   help="which way the lidar counts its bearings: ccw (counter-clockwise about its z axis, up; "
                   "ROS's convention) or cw (a driver that counts clockwise: read mirrored); written to the "
                   "folder's lidar.yaml (default: nothing declared, ccw)")
    p.set_defaults(func=cmd_bag)

