"""The capture planner's rig description: a YAML file read into ``calib_core.planning.views.PlanRig``.

Sections (units in the key names; docs/planning.md shows a whole file):

- ``camera``: camera.yaml's keys in any form of ``lidarcam.rig.dataset.camera_files`` (OpenCV keys ``image_width``,
  ``image_height``, ``camera_matrix``, ``distortion_coefficients``; ROS's ``distortion_model``; a Kalibr
  ``cam0: {...}``) or ``file: camera file`` (relative to the rig file), and ``corner_sigma_px`` (corner noise std per
  coordinate; 0: board poses taken as exact).
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

from calib_core.errors import ObservationError
from calib_core.geometry.mounting import UNIT_NAMES, T_from_params
from calib_core.model.board_error import BoardErrorScale
from calib_core.planning.views import POSE_FIELDS, PlanRig, Workspace
from calib_core.refine.systematic import DEFAULT_PRIOR

from .dataset import DatasetError, board_from_dict, read_yaml
from .dataset.camera_files import camera_from_mapping, read_camera

TEMPLATE = "plan_template.yaml"
"""The rig description template, a file of this package (``lidarcam plan --template``)."""
SECTIONS = ("camera", "lidar", "mounting", "board", "workspace")
LIDAR_KEYS = {"fov_deg": 180.0, "resolution_deg": 0.25, "max_range_m": 30.0, "range_sigma_mm": 20.0,
              "board_offset_mm": 1000.0 * DEFAULT_PRIOR.offset_m, "board_tilt_mm": 1000.0 * DEFAULT_PRIOR.tilt_m}
"""The lidar section's keys and defaults; ``board_offset_mm`` / ``board_tilt_mm`` the per-board systematic error
(``calib_core.model.board_error``), by default the calibration's prior (``calib_core.refine.systematic``)."""
WORKSPACE_LIMITS = {"image_margin_px": 20.0, "min_points": 10, "min_depth_m": 0.5}
SYMMETRIC = ("bearing_deg", "turn_deg", "lean_deg", "roll_deg")
MAX_POSE_BEAMS = 20_000_000
"""Most candidate poses (the product of ``workspace.steps``) times lidar beams (``fov_deg / resolution_deg``) the
planner evaluates: its (poses, beams) arrays stay under about 0.2 GB each (160 MB of float64)."""


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


def _check_size(workspace: Workspace, lid: dict, path: Path) -> None:
    """DatasetError, before any array is made, when the plan would evaluate more than ``MAX_POSE_BEAMS``."""
    if lid["fov_deg"] > 360.0:
        raise DatasetError(f"'lidar.fov_deg' must be at most 360, got {lid['fov_deg']:g}", file=path)
    poses = math.prod(workspace.steps)
    beams = lid["fov_deg"] / lid["resolution_deg"] + 1
    if poses * beams > MAX_POSE_BEAMS:
        raise DatasetError(f"'workspace.steps' ({poses:,} poses) x 'lidar' fov_deg / resolution_deg ({beams:,.0f} "
                           f"beams) is {poses * beams:.3g} pose-beams, above {MAX_POSE_BEAMS:.0e} (about "
                           f"{poses * beams * 8 / 2**30:.3g} GiB per array): fewer steps or a coarser resolution",
                           file=path)


def _camera(cam_sec: dict, path: Path):
    """The ``camera`` section's camera: its keys in any camera file form (``camera_files``), or ``file`` naming a
    camera file (relative to the rig file; ``FILE:camN`` for a camchain's camera), beside ``corner_sigma_px``."""
    keys = {k: v for k, v in cam_sec.items() if k != "corner_sigma_px"}
    if "file" not in keys:
        return camera_from_mapping(keys, path, prefix="camera.")
    if set(keys) != {"file"}:
        raise DatasetError(f"'camera': 'file' names the camera file; drop {', '.join(sorted(set(keys) - {'file'}))}",
                           file=path)
    return read_camera(path.parent / str(keys["file"]))


def rig_from_dict(data: dict, path: Path) -> PlanRig:
    """A PlanRig from the parsed YAML ``data``; DatasetError naming ``path`` and the section and key."""
    unknown = sorted(set(data) - set(SECTIONS))
    if unknown:
        raise DatasetError(f"unknown section(s) {', '.join(unknown)}; known: {', '.join(SECTIONS)}", file=path)
    cam_sec = _section(data, "camera", path)
    cam = _camera(cam_sec, path)
    try:
        camera = cam.core()
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
    _check_size(workspace, lid, path)
    return PlanRig(camera, T_from_params(theta), np.array(board.outline), board.corners, lid["fov_deg"],
                   lid["resolution_deg"], lid["max_range_m"], lid["range_sigma_mm"] / 1000.0, corner_sigma,
                   limits["image_margin_px"], limits["min_depth_m"], int(limits["min_points"]), workspace,
                   BoardErrorScale(lid["board_offset_mm"] / 1000.0, lid["board_tilt_mm"] / 1000.0))


def template_text() -> str:
    """The rig description template shipped with the package (the simulator's default rig, every key)."""
    return Path(__file__).with_name(TEMPLATE).read_text()


def load_plan_rig(path) -> PlanRig:
    """Read a rig description YAML (module docstring)."""
    path = Path(path)
    return rig_from_dict(read_yaml(path), path)
