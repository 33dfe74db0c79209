"""The capture planner's rig description: a YAML file read into ``calib_core.planning.views.PlanRig``.

Sections (units in the key names; docs/planning.md shows a whole file):

- ``camera``: camera.yaml's keys (``image_width``, ``image_height``, ``camera_matrix``, ``distortion_coefficients``)
  and ``corner_sigma_px`` (corner noise std per coordinate; 0: board poses taken as exact).
- ``lidar``: ``fov_deg``, ``resolution_deg``, ``max_range_m``, ``range_sigma_mm``.
- ``mounting``: the rough camera pose in the lidar frame, ``roll_deg``, ``pitch_deg``, ``yaw_deg``, ``x_m``,
  ``y_m``, ``z_m`` (``calib_core.geometry.mounting``: all zero, the camera looks along the lidar x axis).
- ``board``: board.yaml's keys (``cols``, ``rows``, ``square_m``, optional ``outline_m``).
- ``workspace``: ranges ``[low, high]`` of ``distance_m``, ``bearing_deg``, ``height_m``, ``turn_deg``,
  ``lean_deg``, ``roll_deg`` (a single number ``a`` for an angle reads ``[-a, a]``; for ``height_m`` it reads
  ``[a, a]``), ``steps`` (grid points per range), ``image_margin_px``, ``min_points``, ``min_depth_m``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from calib_core.data.camera import Camera
from calib_core.errors import ObservationError
from calib_core.geometry.mounting import UNIT_NAMES, T_from_params
from calib_core.planning.views import POSE_FIELDS, PlanRig, Workspace

from .dataset import DatasetError, board_from_dict, camera_from_dict, read_yaml

SECTIONS = ("camera", "lidar", "mounting", "board", "workspace")
LIDAR_KEYS = {"fov_deg": 180.0, "resolution_deg": 0.25, "max_range_m": 30.0, "range_sigma_mm": 20.0}
WORKSPACE_LIMITS = {"image_margin_px": 20.0, "min_points": 10, "min_depth_m": 0.5}
SYMMETRIC = ("bearing_deg", "turn_deg", "lean_deg", "roll_deg")


def _section(data: dict, name: str, path: Path, required: bool = True) -> dict:
    value = data.get(name, None if required else {})
    if value is None:
        raise DatasetError(f"missing section '{name}'", file=path)
    if not isinstance(value, dict):
        raise DatasetError(f"'{name}' must be a mapping", file=path)
    return value


def _number(sec: dict, key: str, where: str, path: Path, default=None, low: float | None = None) -> float:
    value = sec.get(key, default)
    if value is None:
        raise DatasetError(f"missing key '{where}.{key}'", file=path)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise DatasetError(f"'{where}.{key}' must be a finite number, got {value!r}", file=path)
    if low is not None and value < low:
        raise DatasetError(f"'{where}.{key}' must be >= {low:g}, got {value!r}", file=path)
    return float(value)


def _range(sec: dict, key: str, default: tuple[float, float], path: Path) -> tuple[float, float]:
    value = sec.get(key, default)
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = (-abs(value), abs(value)) if key in SYMMETRIC else (value, value)
    if not (isinstance(value, (list, tuple)) and len(value) == 2):
        raise DatasetError(f"'workspace.{key}' must be [low, high] or a number, got {value!r}", file=path)
    lo, hi = (_number({"v": v}, "v", f"workspace.{key}", path) for v in value)
    if hi < lo:
        raise DatasetError(f"'workspace.{key}': low {lo:g} above high {hi:g}", file=path)
    return lo, hi


def _workspace(sec: dict, path: Path) -> tuple[Workspace, dict]:
    unknown = sorted(set(sec) - set(POSE_FIELDS) - {"steps"} - set(WORKSPACE_LIMITS))
    if unknown:
        raise DatasetError(f"'workspace': unknown key(s) {', '.join(unknown)}", file=path)
    base = Workspace()
    ranges = {k: _range(sec, k, getattr(base, k), path) for k in POSE_FIELDS}
    if ranges["distance_m"][0] <= 0:
        raise DatasetError("'workspace.distance_m' must be positive", file=path)
    steps = sec.get("steps", list(base.steps))
    if isinstance(steps, dict):
        steps = [steps.get(k, n) for k, n in zip(POSE_FIELDS, base.steps, strict=True)]
    good = isinstance(steps, (list, tuple)) and len(steps) == 6
    if not (good and all(isinstance(n, int) and not isinstance(n, bool) and n >= 1 for n in steps)):
        raise DatasetError(f"'workspace.steps' must be 6 positive integers ({', '.join(POSE_FIELDS)}) or a mapping "
                           f"of them, got {steps!r}", file=path)
    limits = {k: _number(sec, k, "workspace", path, v, 0.0) for k, v in WORKSPACE_LIMITS.items()}
    return Workspace(**ranges, steps=tuple(steps)), limits


def rig_from_dict(data: dict, path: Path) -> PlanRig:
    """A PlanRig from the parsed YAML ``data``; DatasetError naming ``path`` and the section and key."""
    unknown = sorted(set(data) - set(SECTIONS))
    if unknown:
        raise DatasetError(f"unknown section(s) {', '.join(unknown)}; known: {', '.join(SECTIONS)}", file=path)
    cam_sec = _section(data, "camera", path)
    cam = camera_from_dict(cam_sec, path)
    try:
        camera = Camera(cam.K, cam.dist, cam.width, cam.height)
    except ObservationError as err:
        raise DatasetError(f"'camera': {err}", file=path) from None
    corner_sigma = _number(cam_sec, "corner_sigma_px", "camera", path, 0.5, 0.0)
    lidar = _section(data, "lidar", path, required=False)
    bad = sorted(set(lidar) - set(LIDAR_KEYS))
    if bad:
        raise DatasetError(f"'lidar': unknown key(s) {', '.join(bad)}; known: {', '.join(LIDAR_KEYS)}", file=path)
    lid = {k: _number(lidar, k, "lidar", path, v, 0.0) for k, v in LIDAR_KEYS.items()}
    if lid["resolution_deg"] <= 0 or lid["fov_deg"] <= 0 or lid["range_sigma_mm"] <= 0:
        raise DatasetError("'lidar': fov_deg, resolution_deg and range_sigma_mm must be > 0", file=path)
    mount = _section(data, "mounting", path)
    bad = sorted(set(mount) - set(UNIT_NAMES))
    if bad:
        raise DatasetError(f"'mounting': unknown key(s) {', '.join(bad)}; known: {', '.join(UNIT_NAMES)}", file=path)
    theta = np.array([_number(mount, k, "mounting", path, 0.0) for k in UNIT_NAMES])
    theta[:3] = np.radians(theta[:3])
    board = board_from_dict(_section(data, "board", path), path)
    workspace, limits = _workspace(_section(data, "workspace", path, required=False), path)
    return PlanRig(camera, T_from_params(theta), np.array(board.outline), board.corners, lid["fov_deg"],
                   lid["resolution_deg"], lid["max_range_m"], lid["range_sigma_mm"] / 1000.0, corner_sigma,
                   limits["image_margin_px"], limits["min_depth_m"], int(limits["min_points"]), workspace)


def load_plan_rig(path) -> PlanRig:
    """Read a rig description YAML (module docstring)."""
    path = Path(path)
    return rig_from_dict(read_yaml(path), path)
