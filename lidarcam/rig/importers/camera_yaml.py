"""Camera intrinsics from the files calibration tools write.

- ROS ``camera_info`` YAML (``camera_calibration``): ``image_width``, ``image_height``, ``camera_matrix``
  ``{rows, cols, data}``, ``distortion_model`` (``plumb_bob`` / ``rational_polynomial``), ``distortion_coefficients``.
- OpenCV FileStorage YAML or XML (``%YAML:1.0`` / ``<opencv_storage>``): ``camera_matrix``,
  ``distortion_coefficients`` (OpenCV sample spelling ``Camera_Matrix`` / ``Distortion_Coefficients`` too) and the
  image size as ``image_width`` / ``image_height`` (also OpenCV's sample
  spelling ``image_Width`` / ``image_Height``).
- MATLAB text (``.m`` / ``.txt``, e.g. a Bouguet toolbox export): ``K = [fx 0 cx; 0 fy cy; 0 0 1];`` and
  ``kc = [k1; k2; p1; p2; k3]'`` (OpenCV's order); the image size is not in the file and is given.
- Kalibr camchain YAML: ``cam0: {camera_model: pinhole, intrinsics: [fu, fv, pu, pv], distortion_model: radtan,
  distortion_coeffs: [k1, k2, r1, r2], resolution: [w, h]}`` (``cam`` selects another camera).

Only OpenCV's pinhole + radial-tangential (rational) model is represented; another model (Kalibr ``equidistant``,
ROS ``equidistant``) is refused with the field named, never silently reinterpreted.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..dataset import CameraModel, DatasetError, camera_from_dict, matrix_field, read_yaml

RADTAN_MODELS = {"plumb_bob", "rational_polynomial", "radtan", "radial_tangential", "none", ""}


def _kalibr(cam: dict, path: Path, name: str) -> CameraModel:
    model = str(cam.get("camera_model", "pinhole")).lower()
    if model != "pinhole":
        raise DatasetError(f"field {name}.camera_model: {model!r} is not supported (pinhole only)", file=path)
    dmodel = str(cam.get("distortion_model", "radtan")).lower()
    if dmodel not in RADTAN_MODELS:
        raise DatasetError(f"field {name}.distortion_model: {dmodel!r} is not supported (radtan only)", file=path)
    try:
        fu, fv, pu, pv = (float(v) for v in cam["intrinsics"])
        w, h = (int(v) for v in cam["resolution"])
    except KeyError as exc:
        raise DatasetError(f"field {name}.{exc.args[0]}: missing", file=path) from None
    except (TypeError, ValueError):
        raise DatasetError(f"field {name}.intrinsics / resolution: expected [fu, fv, pu, pv] and [w, h]",
                           file=path) from None
    dist = matrix_field(cam.get("distortion_coeffs", []), f"{name}.distortion_coeffs", path, (None,))
    K = np.array([[fu, 0.0, pu], [0.0, fv, pv], [0.0, 0.0, 1.0]])
    return CameraModel(w, h, K, dist)


def _opencv_xml(path: Path) -> CameraModel:
    import cv2

    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    if not fs.isOpened():
        raise DatasetError("not a readable OpenCV FileStorage file", file=path)
    try:
        def node(*names):
            for n in names:
                nd = fs.getNode(n)
                if not nd.empty():
                    return nd
            raise DatasetError(f"field {names[0]}: missing", file=path)

        K = node("camera_matrix", "Camera_Matrix").mat()
        dist = node("distortion_coefficients", "Distortion_Coefficients").mat()
        w = int(node("image_width", "image_Width").real())
        h = int(node("image_height", "image_Height").real())
    finally:
        fs.release()
    if K is None or K.shape != (3, 3):
        raise DatasetError("field camera_matrix: expected a 3x3 matrix", file=path)
    dist = np.zeros(0) if dist is None else np.asarray(dist, float).ravel()
    return CameraModel(w, h, np.asarray(K, float), dist)


def _matlab_text(path: Path, size: tuple[int, int] | None) -> CameraModel:
    import re

    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"cannot read as text ({exc})", file=path) from None
    if size is None:
        raise DatasetError("MATLAB text holds no image size: give it (the images' size)", file=path)
    found = {}
    for name, count in (("K", 9), ("kc", None)):
        m = re.search(rf"(?m)^\s*{name}\s*=\s*\[([^\]]*)\]", text)
        if m is None:
            if name == "kc":
                continue
            raise DatasetError(f"field {name}: missing ('{name} = [...]')", file=path)
        try:
            v = np.array([float(t) for t in re.split(r"[\s,;]+", m.group(1).strip()) if t])
        except ValueError:
            raise DatasetError(f"field {name}: not a list of numbers", file=path) from None
        if count is not None and v.size != count:
            raise DatasetError(f"field {name}: expected {count} numbers, got {v.size}", file=path)
        found[name] = v
    return CameraModel(int(size[0]), int(size[1]), found["K"].reshape(3, 3), found.get("kc", np.zeros(0)))


def read_camera_file(path, cam: str = "cam0", size: tuple[int, int] | None = None) -> CameraModel:
    """Intrinsics from a ROS / OpenCV (YAML or XML) / Kalibr / MATLAB text file (``size`` (width, height): the
    image size where the file has none); DatasetError naming the file and field."""
    path = Path(path)
    if path.suffix.lower() == ".xml":
        return _opencv_xml(path)
    if path.suffix.lower() in (".m", ".txt"):
        return _matlab_text(path, size)
    data = read_yaml(path)
    if cam in data and isinstance(data[cam], dict):
        return _kalibr(data[cam], path, cam)
    if any(isinstance(v, dict) and "intrinsics" in v for v in data.values()):
        raise DatasetError(f"Kalibr camchain has no camera {cam!r} (has {', '.join(map(str, data))})", file=path)
    dmodel = str(data.get("distortion_model", "plumb_bob")).lower()
    if dmodel not in RADTAN_MODELS:
        raise DatasetError(f"field distortion_model: {dmodel!r} is not supported (plumb_bob or "
                           "rational_polynomial)", file=path)
    if "image_Width" in data and "image_width" not in data:  # OpenCV sample spelling
        data = dict(data, image_width=data["image_Width"], image_height=data.get("image_Height"))
    return camera_from_dict(data, path)
