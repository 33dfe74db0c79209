"""File formats: observation JSON (``lidarcam.observations/1``) and the YAML export of an extrinsic."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .camera import Camera
from .errors import ObservationError
from .exports import FrameExport
from .metrics import sigma_rot_deg, sigma_trans_m
from .observations import BoardObservation, Observations
from .transforms import invert_T, quaternion_xyzw

OBS_SCHEMA = "lidarcam.observations/1"


def observations_to_dict(obs: Observations) -> dict:
    """Plain-JSON form of ``obs`` under schema ``lidarcam.observations/1``."""
    d: dict = {"schema": OBS_SCHEMA,
               "boards": [{"T_cam_board": b.T_cam_board.tolist(), "outline": b.outline.tolist(),
                           "scan": b.scan.tolist(), **_corners_dict(b)} for b in obs.boards]}
    if obs.camera is not None:
        d["camera"] = obs.camera.to_dict()
    if obs.T_lidar_cam_true is not None:
        d["ground_truth"] = {"T_lidar_cam": obs.T_lidar_cam_true.tolist()}
    if obs.meta:
        d["meta"] = obs.meta
    return d


def _corners_dict(b: BoardObservation) -> dict:
    if not b.has_corners:
        return {}
    return {"corners_px": b.corners_px.tolist(), "corners_board": b.corners_board.tolist()}


def camera_from_dict(raw) -> Camera:
    """The optional file-level ``camera`` object: ``K`` (3x3), ``dist`` (OpenCV order), ``width``, ``height``."""
    if not isinstance(raw, dict):
        raise ObservationError("must be an object", field="camera")
    for key in ("K", "width", "height"):
        if key not in raw:
            raise ObservationError("missing key", field=f"camera.{key}")
    return Camera(raw["K"], raw.get("dist") or [], raw["width"], raw["height"])


def observations_from_dict(data, source: str | None = None) -> Observations:
    """Parse and validate the ``lidarcam.observations/1`` form; errors name ``source``, board and field."""
    def fail(msg, board=None, field=None):
        return ObservationError(msg, file=source, board=board, field=field)

    if not isinstance(data, dict):
        raise fail("top level must be a JSON object")
    schema = data.get("schema")
    if schema is None:
        raise fail("missing key", field="schema")
    if schema != OBS_SCHEMA:
        raise fail(f"unsupported schema {schema!r} (expected {OBS_SCHEMA!r})", field="schema")
    raw_boards = data.get("boards")
    if raw_boards is None:
        raise fail("missing key", field="boards")
    if not isinstance(raw_boards, list):
        raise fail("must be a list", field="boards")
    boards = []
    for i, rb in enumerate(raw_boards):
        if not isinstance(rb, dict):
            raise fail("must be an object", board=i)
        for key in ("T_cam_board", "outline", "scan"):
            if key not in rb:
                raise fail("missing key", board=i, field=key)
        try:
            boards.append(BoardObservation(rb["T_cam_board"], rb["outline"], rb["scan"], rb.get("corners_px"),
                                           rb.get("corners_board")))
        except ObservationError as err:
            raise err.within(file=source, board=i) from None
    T_true = None
    if "ground_truth" in data and data["ground_truth"] is not None:
        gt = data["ground_truth"]
        if not isinstance(gt, dict) or "T_lidar_cam" not in gt:
            raise fail("missing key", field="ground_truth.T_lidar_cam")
        T_true = gt["T_lidar_cam"]
    meta = data.get("meta") or {}
    try:
        camera = camera_from_dict(data["camera"]) if data.get("camera") is not None else None
        return Observations(tuple(boards), T_true, dict(meta), camera)
    except ObservationError as err:
        raise err.within(file=source) from None


def load_observations(path) -> Observations:
    """Read and validate an observation JSON file; raises ObservationError naming file, board, field."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ObservationError(f"cannot read ({exc.strerror})", file=str(path)) from None
    try:
        # NaN/Infinity literals parse to floats here so that validation rejects them naming board and field
        data = json.loads(text)
    except ValueError as exc:
        raise ObservationError(f"not valid JSON ({exc})", file=str(path)) from None
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
    (``calib_core.exports.frame_export``) adds a ``ros:`` block: frame names, the direction published, the
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
