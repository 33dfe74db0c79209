"""Reading calibration recordings: ROS 1 ``.bag`` files and ROS 2 bags (sqlite3 or mcap folders) through the
pure-Python ``rosbags`` library, streamed message by message (a bag is never loaded whole).

Topics: ``sensor_msgs/Image`` or ``sensor_msgs/CompressedImage`` (decoded with ``rosbags-image``, to 8-bit
grey), ``sensor_msgs/LaserScan`` (beam ``i`` at bearing ``angle_min + i angle_increment``, radians
counter-clockwise from the lidar x axis; ranges outside ``[range_min, range_max]`` or not finite are no-returns,
NaN), ``sensor_msgs/CameraInfo`` (K, D as OpenCV's camera matrix and distortion). Times are the messages' header
stamps in nanoseconds (the bag's receive time when a stamp is zero); ``bag_ns`` is the bag's own time, the key to
read one message again.

Every problem with the recording is a ``BagError`` naming the file and, where it applies, the topic.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .dataset import CameraModel, DatasetError, camera_files
from .dataset.camera_files import ROS_MODELS, camera_from_mapping

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
SCAN_TYPES = ("sensor_msgs/msg/LaserScan",)
INFO_TYPES = ("sensor_msgs/msg/CameraInfo",)
OPENCV_MODELS = ("plumb_bob", "rational_polynomial", "")


class BagError(DatasetError):
    """A bag that cannot be read, or a topic that is missing or of the wrong type; one line naming both."""


@dataclass(frozen=True)
class ImageFrame:
    """One image of the recording: ``stamp_ns`` (header stamp), ``bag_ns`` (bag time), ``gray`` (H, W) uint8."""

    stamp_ns: int
    bag_ns: int
    gray: np.ndarray


@dataclass(frozen=True)
class LaserScanMsg:
    """One scan: ``stamp_ns``, ``bag_ns``; ``bearing`` (K,) radians; ``range`` (K,) metres, NaN for no return."""

    stamp_ns: int
    bag_ns: int
    bearing: np.ndarray
    range: np.ndarray


class BagSource:
    """An open recording (use as a context manager): topic checks and streaming readers.

    ``BagSource(path)`` opens a ROS 1 ``.bag`` file or a ROS 2 bag folder (or its ``.db3`` / ``.mcap`` file).
    """

    def __init__(self, path) -> None:
        self.path = Path(path)
        if self.path.is_file() and self.path.suffix in (".db3", ".mcap"):
            self.path = self.path.parent
        self._reader = None

    def __enter__(self) -> BagSource:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        if not self.path.exists():
            raise BagError("no such bag (file or ROS 2 bag folder)", file=self.path)
        try:
            self._reader = AnyReader([self.path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
            self._reader.open()
        except Exception as exc:  # noqa: BLE001 -- rosbags raises several unrelated types for a bad file
            raise BagError(f"not a readable ROS 1 or ROS 2 bag ({type(exc).__name__}: {_first_line(exc)})",
                           file=self.path) from None
        return self

    def __exit__(self, *exc) -> None:
        if self._reader is not None:
            self._reader.close()
            self._reader = None

    def topics(self) -> dict[str, str]:
        """Topic -> message type of every connection in the bag."""
        return {c.topic: c.msgtype for c in self._reader.connections}

    def message_counts(self) -> dict[str, int]:
        """Topic -> number of messages in the bag."""
        counts: dict[str, int] = {}
        for c in self._reader.connections:
            counts[c.topic] = counts.get(c.topic, 0) + int(c.msgcount)
        return counts

    def connections(self, topic: str, types: tuple[str, ...], role: str) -> list:
        """The connections of ``topic``; BagError when it is absent or carries another message type."""
        conns = [c for c in self._reader.connections if c.topic == topic]
        if not conns:
            have = ", ".join(f"{t} ({m.rsplit('/', 1)[-1]})" for t, m in sorted(self.topics().items()))
            raise BagError(f"{role} topic {topic!r} not in the bag (topics: {have or 'none'})", file=self.path)
        bad = sorted({c.msgtype for c in conns if c.msgtype not in types})
        if bad:
            raise BagError(f"{role} topic {topic!r} carries {bad[0]}, expected {' or '.join(types)}",
                           file=self.path)
        return conns

    def messages(self, conns: list, start: int | None = None, stop: int | None = None) -> Iterator:
        """(connection, bag_ns, deserialised message), in bag-time order, for ``start <= bag_ns < stop``."""
        stream = iter(self._reader.messages(connections=conns, start=start, stop=stop))
        while True:
            try:
                conn, bag_ns, raw = next(stream)
            except StopIteration:
                return
            except Exception as exc:  # noqa: BLE001 -- the storage's own errors (a corrupt sqlite3 page, a cut mcap)
                raise BagError(f"cannot read its messages ({type(exc).__name__}: {_first_line(exc)})",
                               file=self.path) from None
            try:
                msg = self._reader.deserialize(raw, conn.msgtype)
            except Exception as exc:  # noqa: BLE001
                raise BagError(f"topic {conn.topic!r}: message at {bag_ns} ns does not decode "
                               f"({type(exc).__name__}: {_first_line(exc)})", file=self.path) from None
            yield conn, bag_ns, msg


def _first_line(exc: Exception) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else "no detail"


def stamp_ns(msg, bag_ns: int) -> int:
    """The header stamp of ``msg`` in nanoseconds, or ``bag_ns`` when the stamp is zero."""
    st = msg.header.stamp
    t = int(st.sec) * 10**9 + int(st.nanosec)
    return t if t > 0 else int(bag_ns)


def decode_image(msg, topic: str, path: Path) -> np.ndarray:
    """An Image or CompressedImage message as 8-bit grey (H, W); BagError for an unsupported encoding."""
    import cv2
    from rosbags.image import message_to_cvimage

    try:
        if hasattr(msg, "format"):  # CompressedImage: decode straight to grey
            img = cv2.imdecode(np.frombuffer(bytes(msg.data), np.uint8), cv2.IMREAD_GRAYSCALE)
        else:
            img = message_to_cvimage(msg, "mono8")
    except Exception as exc:  # noqa: BLE001 -- unknown encodings, corrupt compressed data
        raise BagError(f"image topic {topic!r}: cannot decode ({type(exc).__name__}: {_first_line(exc)})",
                       file=path) from None
    if img is None or img.size == 0 or img.ndim != 2:
        raise BagError(f"image topic {topic!r}: empty or not convertible to grey", file=path)
    if img.dtype != np.uint8:
        img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    return np.ascontiguousarray(img)


def scan_arrays(msg) -> tuple[np.ndarray, np.ndarray]:
    """(bearing (K,), range (K,)) of a LaserScan; ranges outside ``[range_min, range_max]`` become NaN."""
    r = np.asarray(msg.ranges, np.float64).copy()
    bearing = float(msg.angle_min) + float(msg.angle_increment) * np.arange(len(r))
    lo, hi = float(msg.range_min), float(msg.range_max)
    bad = ~np.isfinite(r) | (r < lo) | ((r > hi) if hi > lo else False)
    r[bad] = np.nan
    return bearing, r


def iter_images(src: BagSource, topic: str, start: int | None = None, stop: int | None = None
                ) -> Iterator[ImageFrame]:
    """The images of ``topic`` (bag time in ``[start, stop)``), decoded to grey, one at a time."""
    conns = src.connections(topic, IMAGE_TYPES, "image")
    for _, bag_ns, msg in src.messages(conns, start, stop):
        yield ImageFrame(stamp_ns(msg, bag_ns), bag_ns, decode_image(msg, topic, src.path))


def iter_scans(src: BagSource, topic: str) -> Iterator[LaserScanMsg]:
    """The scans of ``topic`` in bag-time order, one at a time."""
    conns = src.connections(topic, SCAN_TYPES, "scan")
    for _, bag_ns, msg in src.messages(conns):
        b, r = scan_arrays(msg)
        yield LaserScanMsg(stamp_ns(msg, bag_ns), bag_ns, b, r)


def read_camera_info(src: BagSource, topic: str) -> CameraModel:
    """The first CameraInfo of ``topic`` as a CameraModel, read as its ROS camera_info YAML would be
    (``lidarcam.rig.dataset.camera_files``: ``plumb_bob`` / ``rational_polynomial`` pinhole + OpenCV distortion,
    ``equidistant`` pinhole + Kannala-Brandt k1..k4); BagError for a missing message, a zero K or a distortion model
    or length the project does not take."""
    conns = src.connections(topic, INFO_TYPES, "camera-info")
    for _, _, msg in src.messages(conns):
        K = np.asarray(getattr(msg, "K", getattr(msg, "k", None)), float).reshape(3, 3)
        D = np.asarray(getattr(msg, "D", getattr(msg, "d", [])), float).ravel()
        model = str(msg.distortion_model)
        if model not in OPENCV_MODELS and model not in ROS_MODELS:
            raise BagError(f"camera-info topic {topic!r}: distortion model {model!r} is not one the project knows "
                           f"({', '.join(ROS_MODELS)}); give --camera camera.yaml", file=src.path)
        if not (K[0, 0] > 0 and K[1, 1] > 0):
            raise BagError(f"camera-info topic {topic!r}: K is zero (uncalibrated camera); give --camera "
                           "camera.yaml", file=src.path)
        if not np.any(D):
            D = np.zeros(0)
        info = {"image_width": int(msg.width), "image_height": int(msg.height), "camera_matrix": K.tolist(),
                "distortion_model": model or "plumb_bob", "distortion_coefficients": D.tolist()}
        try:
            return camera_from_mapping(info, src.path)
        except DatasetError as err:
            raise BagError(f"camera-info topic {topic!r}: {err.message.replace('key ', 'field ')}; give --camera "
                           "camera.yaml", file=src.path) from None
    raise BagError(f"camera-info topic {topic!r} has no message", file=src.path)


def camera_yaml(camera: CameraModel) -> str:
    """camera.yaml text (docs/dataset.md) of a camera model: OpenCV keys for pinhole + OpenCV distortion, ROS's
    ``equidistant``, Kalibr's camchain for the others (``lidarcam.rig.dataset.camera_files.camera_yaml``)."""
    what = "pinhole, OpenCV distortion" if camera.is_opencv_pinhole else camera.name
    return camera_files.camera_yaml(camera, f"from the bag's CameraInfo ({what})")
