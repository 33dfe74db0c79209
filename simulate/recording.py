"""A simulated calibration recording written as a ROS 1 or ROS 2 bag: a board held still at a few poses and
carried between them, filmed at ``fps`` and scanned at ``scan_hz``, with a constant lidar clock offset.

``write_recording_bag(options, seed, path, rec)`` draws a scene as ``write_dataset`` does (``sample_scene``;
every still pose detected in its rendered image), then plays a timeline: still at pose 0 for ``still_s``, an
eased move (slerp + linear, zero speed at both ends) to pose 1 over ``move_s``, still at pose 1, ... Images
(``sensor_msgs/Image`` mono8 or ``CompressedImage`` png/jpeg) are stamped with the true time; scans
(``sensor_msgs/LaserScan``, one full sweep of ``lidar_fov_deg``) with the true time plus ``time_offset_s``;
a ``CameraInfo`` message precedes them (``plumb_bob`` with zero D for the pinhole; ``equidistant`` with k1..k4
for a fisheye, ``cam_model`` ``pinhole-equidistant``, whose images are rendered through the lens). The truth
(extrinsic, still intervals, offset) is returned; the board is written next to the bag as
``<bag stem>.board.yaml`` (the dataset layout's board.yaml).
Units: metres, radians, seconds; stamps in nanoseconds.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from calib_core.geometry.transforms import invert_T

from . import trial_rngs
from .camera import BoardSpec, CameraError, camera_matrix, render_board_image
from .dataset import RoomOptions, room_ranges, write_board_yaml
from .lens import is_default, true_camera
from .lens_render import render_lens_view
from .lidar import beam_bearings, board_ranges
from .options import SimOptions
from .patterns import Pattern, texture_source
from .rig import refuse_rig_conditions
from .scene import sample_scene


@dataclass(frozen=True)
class RecordingOptions:
    """The recording's timing and encoding.

    Attributes:
        fps, scan_hz: image and scan rates (Hz).
        still_s, move_s: how long the board rests at each pose and travels between poses (s).
        time_offset_s: scan stamps = true time + this (a lidar clock ahead of the camera's when > 0).
        eased: moves start and stop at zero speed (smoothstep); False: constant speed, abrupt start and stop.
        image_format: ``raw`` (sensor_msgs/Image mono8), ``png`` or ``jpeg`` (CompressedImage).
        ros: 1 (``.bag``) or 2 (a rosbag2 folder); storage: ``sqlite3`` or ``mcap`` (ROS 2 only).
        image_topic, scan_topic, info_topic: topic names.
        start_s: true time of the first frame (s since the epoch of the stamps).
        dropout_prob: share of beams with no return (written as inf); range_min_m: shorter ranges are invalid.
    """

    fps: float = 30.0
    scan_hz: float = 40.0
    still_s: float = 1.0
    move_s: float = 1.0
    time_offset_s: float = 0.0
    eased: bool = True
    image_format: str = "raw"
    ros: int = 1
    storage: str = "sqlite3"
    image_topic: str = "/camera/image_raw"
    scan_topic: str = "/scan"
    info_topic: str = "/camera/camera_info"
    start_s: float = 1000.0
    dropout_prob: float = 0.002
    range_min_m: float = 0.05


@dataclass(frozen=True, eq=False)
class RecordingTruth:
    """What the recording holds: ``T_lidar_cam`` 4x4, ``T_lidar_board`` (N,4,4) still poses, ``still`` (N,2) true
    start/end times of each still stretch (s, image clock), ``time_offset_s``, frame and scan counts."""

    T_lidar_cam: np.ndarray
    T_lidar_board: np.ndarray
    still: np.ndarray
    time_offset_s: float
    n_images: int
    n_scans: int


def board_trajectory(T_lidar_board: np.ndarray, still_s: float, move_s: float, eased: bool = True):
    """(duration_s, pose(t) -> 4x4, still (N,2)): rest at each pose, moves between them (smoothstep-eased or at
    constant speed)."""
    n = len(T_lidar_board)
    period = still_s + move_s
    still = np.array([[k * period, k * period + still_s] for k in range(n)])
    rots = Rotation.from_matrix(T_lidar_board[:, :3, :3])

    def pose(t: float) -> np.ndarray:
        k = min(int(t // period), n - 1)
        u = (t - k * period - still_s) / move_s if move_s > 0 else 0.0
        if u <= 0 or k == n - 1:
            return T_lidar_board[k]
        u = min(u, 1.0)
        s = u * u * (3 - 2 * u) if eased else u
        T = np.eye(4)
        T[:3, :3] = Slerp([0, 1], rots[k:k + 2])([s]).as_matrix()[0]
        T[:3, 3] = (1 - s) * T_lidar_board[k, :3, 3] + s * T_lidar_board[k + 1, :3, 3]
        return T

    return n * still_s + (n - 1) * move_s, pose, still


class _BagOut:
    """A ROS 1 or ROS 2 bag writer with the sensor_msgs types of the right distribution."""

    def __init__(self, path: Path, rec: RecordingOptions) -> None:
        from rosbags.typesys import Stores, get_typestore

        self.ros1 = rec.ros == 1
        self.ts = get_typestore(Stores.ROS1_NOETIC if self.ros1 else Stores.ROS2_HUMBLE)
        if self.ros1:
            from rosbags.rosbag1 import Writer

            self.w = Writer(path)
        else:
            from rosbags.rosbag2 import StoragePlugin, Writer

            plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[rec.storage]
            self.w = Writer(path, version=9, storage_plugin=plugin)
        self.w.open()
        self.conns: dict[str, object] = {}
        self.seq = 0

    def header(self, t_ns: int, frame: str):
        T = self.ts.types
        stamp = T["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)
        if self.ros1:
            self.seq += 1
            return T["std_msgs/msg/Header"](seq=self.seq, stamp=stamp, frame_id=frame)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)

    def write(self, topic: str, msg, t_ns: int) -> None:
        typ = msg.__msgtype__
        if topic not in self.conns:
            self.conns[topic] = self.w.add_connection(topic, typ, typestore=self.ts)
        data = self.ts.serialize_ros1(msg, typ) if self.ros1 else self.ts.serialize_cdr(msg, typ)
        self.w.write(self.conns[topic], t_ns, data)

    def camera_info(self, topic: str, t_ns: int, K: np.ndarray, width: int, height: int, lens=None) -> None:
        """The CameraInfo of the pinhole ``K`` (``plumb_bob``, zero D) or of ``lens``: ``equidistant`` with its
        k1..k4 (as ROS's camera_calibration writes a fisheye)."""
        model, D = "plumb_bob", np.zeros(5)
        if lens is not None:
            model, D, K = "equidistant", np.asarray(lens.dist, float).ravel()[:4], np.asarray(lens.K, float)
        P = np.hstack([K, np.zeros((3, 1))])
        names = ("D", "K", "R", "P") if self.ros1 else ("d", "k", "r", "p")
        vals = (D, K.ravel(), np.eye(3).ravel(), P.ravel())
        T = self.ts.types
        roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        msg = T["sensor_msgs/msg/CameraInfo"](header=self.header(t_ns, "camera"), height=height, width=width,
                                              distortion_model=model, binning_x=0, binning_y=0, roi=roi,
                                              **{n: np.asarray(v, np.float64) for n, v in zip(names, vals,
                                                                                            strict=True)})
        self.write(topic, msg, t_ns)

    def image(self, topic: str, t_ns: int, img: np.ndarray, fmt: str) -> None:
        T = self.ts.types
        if fmt == "raw":
            msg = T["sensor_msgs/msg/Image"](header=self.header(t_ns, "camera"), height=img.shape[0],
                                             width=img.shape[1], encoding="mono8", is_bigendian=0,
                                             step=img.shape[1], data=img.ravel())
        else:
            ok, buf = cv2.imencode(".png" if fmt == "png" else ".jpg", img,
                                   [] if fmt == "png" else [cv2.IMWRITE_JPEG_QUALITY, 95])
            msg = T["sensor_msgs/msg/CompressedImage"](header=self.header(t_ns, "camera"), format=fmt,
                                                       data=np.frombuffer(buf.tobytes(), np.uint8))
        self.write(topic, msg, t_ns)

    def scan(self, topic: str, t_ns: int, bearings: np.ndarray, ranges: np.ndarray, rec: RecordingOptions,
             max_range: float) -> None:
        msg = self.ts.types["sensor_msgs/msg/LaserScan"](
            header=self.header(t_ns, "laser"), angle_min=float(bearings[0]), angle_max=float(bearings[-1]),
            angle_increment=float(bearings[1] - bearings[0]), time_increment=0.0, scan_time=1.0 / rec.scan_hz,
            range_min=rec.range_min_m, range_max=float(max_range), ranges=ranges.astype(np.float32),
            intensities=np.zeros(0, np.float32))
        self.write(topic, msg, t_ns)

    def close(self) -> None:
        self.w.close()


def _renderer(o: SimOptions, K: np.ndarray, rng: np.random.Generator, pattern: Pattern | None = None, lens=None):
    """render(T_cam_board, key) -> noisy uint8 image (the checkerboard, or ``pattern``; through the pinhole ``K`` or
    through ``lens``, a ``calib_core.data.cameras`` model); the noise-free render is cached per ``key`` (still
    poses)."""
    spec = BoardSpec.of(o)
    cache: dict = {}
    texture = None if pattern is None else texture_source(pattern, spec.size_m)

    def ideal(T_cam_board):
        try:
            if lens is not None:
                return render_lens_view(lens, T_cam_board, spec, o.render_supersample, texture).astype(np.float32)
            return render_board_image(K, T_cam_board, spec, o.cam_width, o.cam_height,
                                      o.render_supersample, texture=texture).astype(np.float32)
        except CameraError:
            return np.full((o.cam_height, o.cam_width), 128.0, np.float32)

    def render(T_cam_board, key=None):
        img = cache.get(key) if key is not None else None
        if img is None:
            img = cv2.GaussianBlur(ideal(T_cam_board), (0, 0), 0.7)
            if key is not None:
                cache[key] = img
        noisy = img + rng.normal(0.0, o.image_noise_std, img.shape).astype(np.float32)
        return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)

    return render


def write_recording_bag(options: SimOptions, seed: int, path, rec: RecordingOptions | None = None, *,
                        trial: int = 0, pattern: Pattern | None = None) -> RecordingTruth:
    """Write a simulated calibration recording (module docstring) to ``path`` (a ``.bag`` file for ROS 1, a
    folder for ROS 2) and ``board.yaml`` beside it; return its truth. ``options.n_boards`` still poses.
    ``pattern``: a ChArUco board or an AprilGrid (``simulate.patterns``) instead of the checkerboard. A lens
    (``cam_model`` ``pinhole-equidistant``, ``simulate.lens``) renders through the model and its CameraInfo is
    ``equidistant`` with k1..k4; other lenses are refused (ValueError)."""
    rec = rec or RecordingOptions()
    o = options
    refuse_rig_conditions(o, "write_recording_bag")
    path = Path(path)
    rng_geo, rng_lidar, rng_cam = trial_rngs(o, seed, trial)
    K = camera_matrix(o.focal_px, o.cam_width, o.cam_height)
    spec = BoardSpec.of(o)
    cols, rows = spec.squares_x - 1, spec.squares_y - 1
    lens = None if is_default(o) else true_camera(o, K)
    if lens is not None and lens.name != "pinhole-equidistant":
        raise ValueError(f"write_recording_bag: a CameraInfo holds no {lens.name} lens (only pinhole-equidistant, "
                         "as 'equidistant')")
    render = _renderer(o, K, rng_cam, pattern, lens)

    def accept(T_lidar_cam, T_lidar_board) -> bool:
        if pattern is not None or lens is not None:
            return True
        img = render(invert_T(T_lidar_cam) @ T_lidar_board)
        return bool(cv2.findChessboardCornersSB(img, (cols, rows), flags=cv2.CALIB_CB_ACCURACY)[0])

    scene = sample_scene(o, rng_geo, accept=accept)
    duration, pose, still = board_trajectory(scene.T_lidar_board, rec.still_s, rec.move_s, rec.eased)
    T_cam_lidar = invert_T(scene.T_lidar_cam)
    bearings = beam_bearings(o.lidar_fov_deg, o.lidar_res_deg)
    rng_room = np.random.default_rng(np.random.SeedSequence(entropy=int(seed), spawn_key=(7919, int(trial))))
    room = RoomOptions()
    r_room = room_ranges(bearings, rng_room.uniform(room.wall_min_m, room.wall_max_m, 4),
                         float(rng_room.uniform(-np.pi / 4, np.pi / 4)), room)
    sigma = o.noise_mm / 1000.0

    def still_key(t):
        k = np.flatnonzero((still[:, 0] <= t) & (t <= still[:, 1]))
        return int(k[0]) if len(k) else None

    t_img = np.arange(0.0, duration, 1.0 / rec.fps)
    t_scan = np.arange(0.0, duration, 1.0 / rec.scan_hz)
    events = sorted([(t, 0) for t in t_img] + [(t + rec.time_offset_s, 1) for t in t_scan])
    ns = int(round(rec.start_s * 1e9))
    out = _BagOut(path, rec)
    try:
        out.camera_info(rec.info_topic, ns - 10**6, K, o.cam_width, o.cam_height, lens)
        for t, kind in events:
            t_ns = ns + int(round(t * 1e9))
            if kind == 0:
                out.image(rec.image_topic, t_ns, render(T_cam_lidar @ pose(t), still_key(t)), rec.image_format)
            else:
                tt = t - rec.time_offset_s
                rb = board_ranges(bearings, pose(tt)[None], scene.outline)[0]
                r = np.minimum(rb, r_room) + rng_lidar.normal(0.0, sigma, len(bearings))
                r[(rng_lidar.random(len(r)) < rec.dropout_prob) | (r > o.lidar_max_range_m)] = np.inf
                out.scan(rec.scan_topic, t_ns, bearings, r, rec, o.lidar_max_range_m)
    finally:
        out.close()
    board_yaml = path.parent / f"{path.name.removesuffix('.bag')}.board.yaml"
    if pattern is None:
        write_board_yaml(board_yaml, o, scene.outline)
    else:
        board_yaml.write_text(pattern.board_yaml(np.asarray(scene.outline) - pattern.offset(spec.size_m)))
    return RecordingTruth(scene.T_lidar_cam, scene.T_lidar_board, still + rec.start_s, rec.time_offset_s,
                          len(t_img), len(t_scan))
