"""File formats: observation JSON (``lidarcam.observations/1``) and the YAML export of an extrinsic."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from ..errors import ObservationError
from ..geometry.metrics import sigma_rot_deg, sigma_trans_m
from ..geometry.transforms import invert_T, quaternion_xyzw
from .camera import Camera, CameraModel
from .cameras import camera_class
from .exports import FrameExport
from .observations import MAX_BOARDS, BoardObservation, Observations, check_outline_kind, orthonormalised

OBS_SCHEMA = "lidarcam.observations/1"


def observations_to_dict(obs: Observations) -> dict:
    """Plain-JSON form of ``obs`` under schema ``lidarcam.observations/1``."""
    d: dict = {"schema": OBS_SCHEMA,
               "boards": [{"T_cam_board": b.T_cam_board.tolist(), **_outline_dict(b),
                           "scan": b.scan.tolist(), **_corners_dict(b)} for b in obs.boards]}
    if obs.camera is not None:
        d["camera"] = obs.camera.to_dict()
    if obs.T_lidar_cam_true is not None:
        d["ground_truth"] = {"T_lidar_cam": obs.T_lidar_cam_true.tolist()}
    if obs.meta:
        d["meta"] = obs.meta
    return d


BOARD_KEYS = ("T_cam_board", "outline", "scan")
"""Keys every board object must hold (``outline`` may be left out when ``outline_kind`` is ``"none"``)."""
MAX_FILE_BYTES = 256 * 2**20
"""Largest observation file read (bytes); larger ones are refused before reading."""
MAX_JSON_DEPTH = 64
"""Deepest nesting of brackets accepted in an observation file (the format needs 4)."""


def _board_from_dict(rb, i: int, notes: list[str]) -> BoardObservation:
    """One board of the ``boards`` list (ObservationError naming the board and field)."""
    if not isinstance(rb, dict):
        raise ObservationError(f"must be an object, got {type(rb).__name__}", board=i)
    try:
        kind = check_outline_kind(rb.get("outline_kind", "exact"))
    except ObservationError as err:
        raise err.within(board=i) from None
    for key in BOARD_KEYS:
        if key not in rb and not (key == "outline" and kind == "none"):
            raise ObservationError("missing key", board=i, field=key)
    try:
        T, note = orthonormalised(rb["T_cam_board"], "T_cam_board")
        if note:
            notes.append(f"board {i}: {note}")
        return BoardObservation(T, rb.get("outline"), rb["scan"], rb.get("corners_px"), rb.get("corners_board"),
                                outline_kind=kind)
    except ObservationError as err:
        raise err.within(board=i) from None


def _outline_dict(b: BoardObservation) -> dict:
    """``outline`` (when known) and ``outline_kind`` (when not the default ``exact``) of one board."""
    d = {} if b.outline is None else {"outline": b.outline.tolist()}
    return d if b.outline_exact else {**d, "outline_kind": b.outline_kind}


def _corners_dict(b: BoardObservation) -> dict:
    if not b.has_corners:
        return {}
    return {"corners_px": b.corners_px.tolist(), "corners_board": b.corners_board.tolist()}


def camera_from_dict(raw) -> CameraModel:
    """The optional file-level ``camera`` object: ``K`` (3x3), ``dist`` (OpenCV order for ``radtan``, k1..k4 for
    ``equidistant``), ``width``, ``height``, the optional ``std_intrinsics`` (1-sigma of fx, fy, cx, cy[, the
    model's parameters][, dist]) and, optionally, Kalibr's ``camera_model`` (``pinhole`` when absent: ``Camera``),
    ``distortion_model`` and the model's parameters (``xi``, ``alpha``, ``beta``: ``calib_core.data.cameras``)."""
    if not isinstance(raw, dict):
        raise ObservationError("must be an object", field="camera")
    for key in ("K", "width", "height"):
        if key not in raw:
            raise ObservationError("missing key", field=f"camera.{key}")
    args = (raw["K"], raw.get("dist") or [], raw["width"], raw["height"], raw.get("std_intrinsics"))
    if "camera_model" not in raw and "distortion_model" not in raw:
        return Camera(*args)
    model, dist_model = raw.get("camera_model", "pinhole"), raw.get("distortion_model")
    if not isinstance(model, str) or not (dist_model is None or isinstance(dist_model, str)):
        raise ObservationError("camera_model and distortion_model must be strings", field="camera.camera_model")
    try:
        cls = camera_class(model, dist_model)
    except KeyError as exc:
        raise ObservationError(exc.args[0], field="camera.camera_model") from None
    unknown = sorted(set(raw) - CAMERA_KEYS - set(cls.param_names))
    if unknown:
        raise ObservationError(f"unknown key for the {model} model (its parameters: "
                               f"{', '.join(cls.param_names) or 'none'})", field=f"camera.{unknown[0]}")
    params = {n: raw[n] for n in cls.param_names if n in raw}
    for n, v in params.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ObservationError(f"must be a number, got {v!r}"[:120], field=f"camera.{n}")
    return cls(*args, **params)


CAMERA_KEYS = {"K", "dist", "width", "height", "std_intrinsics", "camera_model", "distortion_model"}
"""The ``camera`` object's keys every model shares (a model adds its parameters)."""


def observations_from_dict(data, source: str | None = None) -> Observations:
    """Parse and validate the ``lidarcam.observations/1`` form; errors name ``source``, board and field.

    Rotations within ``LOAD_ROTATION_TOL`` of orthonormal are re-orthonormalised; the notes saying so are in
    ``meta["load_notes"]``.
    """
    def fail(msg, board=None, field=None):
        return ObservationError(msg, file=source, board=board, field=field)

    if not isinstance(data, dict):
        raise fail(f"top level must be a JSON object, got {type(data).__name__}")
    schema = data.get("schema")
    if schema is None:
        raise fail("missing key", field="schema")
    if schema != OBS_SCHEMA:
        raise fail(f"unsupported schema {str(schema)[:80]!r} (expected {OBS_SCHEMA!r})", field="schema")
    raw_boards = data.get("boards")
    if raw_boards is None:
        raise fail("missing key", field="boards")
    if not isinstance(raw_boards, list):
        raise fail(f"must be a list, got {type(raw_boards).__name__}", field="boards")
    if len(raw_boards) > MAX_BOARDS:
        raise fail(f"{len(raw_boards)} boards, more than the limit of {MAX_BOARDS}", field="boards")
    notes: list[str] = []
    try:
        boards = [_board_from_dict(rb, i, notes) for i, rb in enumerate(raw_boards)]
    except ObservationError as err:
        raise err.within(file=source) from None
    T_true = None
    if "ground_truth" in data and data["ground_truth"] is not None:
        gt = data["ground_truth"]
        if not isinstance(gt, dict) or "T_lidar_cam" not in gt:
            raise fail("missing key", field="ground_truth.T_lidar_cam")
        try:
            T_true, note = orthonormalised(gt["T_lidar_cam"], "ground_truth.T_lidar_cam")
        except ObservationError as err:
            raise err.within(file=source) from None
        if note:
            notes.append(note)
    meta = data.get("meta")
    if meta is None:
        meta = {}
    if not isinstance(meta, dict):
        raise fail(f"must be an object, got {type(meta).__name__}", field="meta")
    meta = dict(meta)
    if notes:
        meta["load_notes"] = notes
    try:
        camera = camera_from_dict(data["camera"]) if data.get("camera") is not None else None
        return Observations(tuple(boards), T_true, meta, camera)
    except ObservationError as err:
        raise err.within(file=source) from None


def decode_text(raw: bytes, source: str) -> str:
    """The text of an observation file: UTF-8 (a UTF-8 byte-order mark is accepted); ObservationError for
    UTF-16/32, binary data or invalid UTF-8."""
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")) or (len(raw) > 1 and (raw[0] == 0 or raw[1] == 0)):
        raise ObservationError("UTF-16/UTF-32 or binary data, not UTF-8 JSON text (save the file as UTF-8)",
                               file=source)
    if b"\x00" in raw:
        raise ObservationError("binary data (NUL bytes), not JSON text", file=source)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ObservationError(f"not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset {exc.start})",
                               file=source) from None


def _nesting_depth(text: str) -> int:
    """Deepest bracket nesting of JSON text, strings skipped (no recursion, vectorised)."""
    b = np.frombuffer(re.sub(r'"(?:[^"\\]|\\.)*"', '""', text).encode(), np.uint8)
    step = np.isin(b, (ord("["), ord("{"))).astype(np.int64) - np.isin(b, (ord("]"), ord("}")))
    return int(np.cumsum(step).max(initial=0))


def read_json(path):
    """The parsed JSON of a lidarcam file (size, encoding and nesting bounded first); ObservationError naming the
    file otherwise. NaN/Infinity literals parse to floats: the caller's checks reject them naming the field."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ObservationError(f"{size} bytes, more than the limit of {MAX_FILE_BYTES}", file=str(path))
        raw = path.read_bytes()
    except OSError as exc:
        raise ObservationError(f"cannot read ({exc.strerror})", file=str(path)) from None
    text = decode_text(raw, str(path))
    depth = _nesting_depth(text)
    if depth > MAX_JSON_DEPTH:
        raise ObservationError(f"brackets nested {depth} deep, more than the limit of {MAX_JSON_DEPTH}",
                               file=str(path))
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise ObservationError(f"not valid JSON ({str(exc)[:200]})", file=str(path)) from None


def load_observations(path) -> Observations:
    """Read and validate an observation JSON file; raises ObservationError naming file, board, field."""
    data = read_json(path)
    return observations_from_dict(data, source=str(path))


def save_observations(obs: Observations, path) -> None:
    """Write ``obs`` as ``lidarcam.observations/1`` JSON (floats in full precision: round trip is exact)."""
    Path(path).write_text(json.dumps(observations_to_dict(obs), indent=1, allow_nan=False) + "\n")


def _fmt_matrix(M: np.ndarray, indent: str) -> str:
    return "\n".join(f"{indent}- [{', '.join(repr(float(v)) for v in row)}]" for row in M)


def extrinsic_yaml(T_lidar_cam: np.ndarray, extra: dict | None = None, covariance: np.ndarray | None = None,
                   ros: FrameExport | None = None) -> str:
    """YAML text of an extrinsic: both 4x4 directions, quaternion (x, y, z, w) and translation, commented.

    ``extra`` adds top-level scalar keys (method name, 1-sigma figures, ...). ``covariance`` (6x6, rotation
    tangent of ``T_lidar_cam`` in the lidar frame (rad) then translation (m)) adds its 1-sigma figures
    ``sigma_rot_deg`` and ``sigma_trans_mm`` (unless in ``extra``) and the matrix. ``ros``
    (``calib_core.data.exports.frame_export``) adds a ``ros:`` block: frame names, the direction published, the
    ``static_transform_publisher`` lines for ROS 1 and ROS 2 and the URDF joint.
    """
    extra = dict(extra or {})
    if covariance is not None:
        cov = np.asarray(covariance, float)
        extra.setdefault("sigma_rot_deg", sigma_rot_deg(cov))
        extra.setdefault("sigma_trans_mm", 1000 * sigma_trans_m(cov))
    T = np.asarray(T_lidar_cam, float)
    Ti = invert_T(T)
    lines = ["# lidarcam extrinsic calibration. Units: metres. T_a_b maps points of frame b into frame a.",
             "# lidar frame: scan plane z = 0, x forward; camera frame: z optical axis, y down."]
    for k, v in extra.items():
        if isinstance(v, float) and not math.isfinite(v):
            v = ".nan"
        lines.append(f"{k}: {v}")
    for name, M, comment in (("T_lidar_cam", T, "maps camera points into the lidar frame: p_L = T_lidar_cam p_C"),
                             ("T_cam_lidar", Ti, "maps lidar points into the camera frame: p_C = T_cam_lidar p_L")):
        q = quaternion_xyzw(M[:3, :3])
        lines += [f"# {comment}", f"{name}:", "  matrix:", _fmt_matrix(M, "    "),
                  "  # rotation as a unit quaternion, order (x, y, z, w), scalar last",
                  f"  quaternion_xyzw: [{', '.join(repr(float(v)) for v in q)}]",
                  "  # translation (metres): the origin of the source frame in the target frame",
                  f"  translation: [{', '.join(repr(float(v)) for v in M[:3, 3])}]"]
    if covariance is not None:
        lines += ["# 6x6 covariance of T_lidar_cam: rotation vector of the left perturbation exp(w) R in the lidar",
                  "# frame (rad), then translation (m); sigma_rot_deg / sigma_trans_mm are the roots of the traces",
                  "covariance:", _fmt_matrix(cov, "  ")]
    if ros is not None:
        lines += _ros_block(ros)
    return "\n".join(lines) + "\n"


def _ros_block(ros: FrameExport) -> list[str]:
    def vec(v):
        return f"[{', '.join(repr(float(x)) for x in v)}]"

    return [f"# ROS: the transform published for {ros.parent} -> {ros.child} maps {ros.child} points into the "
            f"{ros.parent} frame; here it is {ros.source}",
            "ros:", f"  parent_frame: {ros.parent}", f"  child_frame: {ros.child}",
            f"  T_parent_child: {ros.source}", f"  translation: {vec(ros.xyz)}",
            f"  quaternion_xyzw: {vec(ros.quaternion_xyzw)}",
            "  # URDF origin rpy: fixed-axis roll (x), pitch (y), yaw (z), radians",
            f"  urdf_rpy: {vec(ros.rpy)}",
            f"  static_transform_publisher_args: \"{ros.tf_args}\"",
            f"  ros1: \"{ros.ros1}\"", f"  ros2: \"{ros.ros2}\"",
            "  urdf_joint: |", *("    " + ln for ln in ros.urdf_joint().splitlines())]
