"""The dataset's YAML files (plain or OpenCV FileStorage): camera.yaml's OpenCV keys (``camera_files`` reads the
file), windows.yaml, ground_truth.yaml, and the checked numeric matrices they hold (board.yaml:
``lidarcam.rig.dataset.boards``)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import yaml

from .model import CameraModel, DatasetError


class _Loader(yaml.SafeLoader):
    """SafeLoader that reads OpenCV's ``%YAML:1.0`` files and ``!!opencv-matrix`` mappings."""


def _opencv_matrix(loader, node):
    return loader.construct_mapping(node, deep=True)


_Loader.add_constructor("tag:yaml.org,2002:opencv-matrix", _opencv_matrix)
_Loader.add_constructor("tag:yaml.org,2002:opencv-nd-matrix", _opencv_matrix)


def read_yaml(path: Path) -> dict:
    """Parse a YAML file (plain, or OpenCV FileStorage ``%YAML:1.0``) into a dict; DatasetError with the line."""
    try:
        text = path.read_text()
    except OSError as exc:
        raise DatasetError(f"cannot read ({exc.strerror})", file=path) from None
    except UnicodeDecodeError as exc:
        raise DatasetError(f"not a text file (byte {exc.start} is not UTF-8)", file=path) from None
    # OpenCV writes "%YAML:1.0" (not valid YAML) or "%YAML 1.2" (PyYAML reads 1.1): drop the directive
    text = re.sub(r"^\s*%YAML[: ]?[0-9.]*[^\n]*\n", "", text, count=1)
    try:
        data = yaml.load(text, Loader=_Loader)  # noqa: S506 (a SafeLoader subclass)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = None if mark is None else mark.line + 1
        raise DatasetError(f"not valid YAML ({getattr(exc, 'problem', None) or exc})", file=path, line=line) from None
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise DatasetError("top level must be a mapping", file=path)
    return data


def _numbers(value, name: str, path: Path):
    """``value`` when it is a number or nested lists of numbers (a string or a boolean is not)."""
    stack = [value]
    while stack:
        v = stack.pop()
        if isinstance(v, (list, tuple)):
            stack.extend(v)
        elif isinstance(v, bool) or not isinstance(v, (int, float)):
            raise DatasetError(f"'{name}': not a numeric matrix ({type(v).__name__} {str(v)[:20]!r})", file=path)
    return value


def matrix_field(value, name: str, path: Path, shape: tuple[int | None, ...]) -> np.ndarray:
    """A numeric array from a nested list, a flat list (shape (N,) only) or an ``{rows, cols, data}`` mapping."""
    if isinstance(value, dict):
        if "data" not in value:
            raise DatasetError(f"'{name}': matrix mapping needs 'data'", file=path)
        try:
            data = np.asarray(_numbers(value["data"], name, path), dtype=float).ravel()
            r, c = int(value.get("rows", len(data))), int(value.get("cols", 1))
        except (TypeError, ValueError):
            raise DatasetError(f"'{name}': not a numeric matrix", file=path) from None
        if r * c != data.size:
            raise DatasetError(f"'{name}': rows*cols = {r}x{c} but {data.size} numbers", file=path)
        a = data.reshape(r, c)
    else:
        try:
            a = np.asarray(_numbers(value, name, path), dtype=float)
        except (TypeError, ValueError):
            raise DatasetError(f"'{name}': not a numeric matrix", file=path) from None
    if len(shape) == 1:
        if a.ndim == 2 and 1 in a.shape:
            a = a.ravel()
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape, strict=True)):
        want = "x".join("N" if s is None else str(s) for s in shape)
        raise DatasetError(f"'{name}': expected shape {want}, got {'x'.join(map(str, a.shape)) or 'scalar'}",
                           file=path)
    if not np.all(np.isfinite(a)):
        raise DatasetError(f"'{name}': contains NaN or inf", file=path)
    return a


def _require(data: dict, key: str, path: Path):
    if key not in data:
        raise DatasetError(f"missing key '{key}'", file=path)
    return data[key]


def camera_from_dict(data: dict, path: Path) -> CameraModel:
    """A pinhole CameraModel from the OpenCV keys (already parsed; the checks of every form that has them, the lens
    model left to ``lidarcam.rig.dataset.camera_files``, which reads camera files); errors name ``path``."""
    try:
        w, h = int(_require(data, "image_width", path)), int(_require(data, "image_height", path))
    except (TypeError, ValueError):
        raise DatasetError("image_width and image_height must be integers", file=path) from None
    if w <= 0 or h <= 0:
        raise DatasetError(f"image size must be positive, got {w}x{h}", file=path)
    K = matrix_field(_require(data, "camera_matrix", path), "camera_matrix", path, (3, 3))
    if not (K[0, 0] > 0 and K[1, 1] > 0 and np.allclose(K[2], [0, 0, 1]) and K[1, 0] == 0):
        raise DatasetError("'camera_matrix' must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0",
                           file=path)
    dist = matrix_field(data.get("distortion_coefficients", []), "distortion_coefficients", path, (None,))
    if dist.size not in (0, 4, 5, 8, 12, 14):
        raise DatasetError(f"'distortion_coefficients': OpenCV takes 4, 5, 8, 12 or 14, got {dist.size}", file=path)
    K.setflags(write=False)
    dist.setflags(write=False)
    return CameraModel(w, h, K, dist)


def load_windows(path) -> dict[str, tuple[float, float]]:
    """windows.yaml: ``units: deg | rad`` (default rad) and ``windows: {pose: [bearing_min, bearing_max]}``."""
    path = Path(path)
    data = read_yaml(path)
    units = str(data.get("units", "rad")).lower()
    if units not in ("rad", "deg"):
        raise DatasetError(f"'units' must be rad or deg, got {units!r}", file=path)
    raw = data.get("windows", {})
    if not isinstance(raw, dict):
        raise DatasetError("'windows' must map pose names to [bearing_min, bearing_max]", file=path)
    out = {}
    for name, w in raw.items():
        try:
            lo, hi = (float(v) for v in w)
        except (TypeError, ValueError):
            raise DatasetError(f"window of pose {name!r} must be [bearing_min, bearing_max]", file=path) from None
        if units == "deg":
            lo, hi = math.radians(lo), math.radians(hi)
        if not lo < hi:
            raise DatasetError(f"window of pose {name!r}: bearing_min must be < bearing_max", file=path)
        out[str(name)] = (lo, hi)
    return out


def load_ground_truth(path: Path) -> dict:
    """ground_truth.yaml as a dict; its ``T_lidar_cam`` (a 4x4 list or ``{matrix: ...}``) checked and made a 4x4
    array (DatasetError naming the file otherwise)."""
    gt = read_yaml(path)
    value = gt.get("T_lidar_cam")
    if value is None:
        return gt
    if isinstance(value, dict):
        if "matrix" not in value:
            raise DatasetError("'T_lidar_cam' mapping needs 'matrix'", file=path)
        value = value["matrix"]
    T = matrix_field(value, "T_lidar_cam", path, (4, 4))
    if not np.allclose(T[3], [0, 0, 0, 1]) or abs(np.linalg.det(T[:3, :3]) - 1) > 1e-4:
        raise DatasetError("'T_lidar_cam': not a rigid transform (last row 0 0 0 1, rotation of determinant 1)",
                           file=path)
    return {**gt, "T_lidar_cam": T}
