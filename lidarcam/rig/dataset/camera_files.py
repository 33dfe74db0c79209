"""Camera files: the one reader (and writer) of every camera file the project takes, each form recognised by its keys.

Forms (docs/dataset.md has an example of each):

- **OpenCV keys** (today's ``camera.yaml``): ``image_width``, ``image_height``, ``camera_matrix`` (3x3, a nested
  list or ``{rows, cols, data}``), ``distortion_coefficients`` (OpenCV order k1, k2, p1, p2[, k3, ...]); also as an
  OpenCV FileStorage YAML or XML (``%YAML:1.0``, ``!!opencv-matrix``; OpenCV's sample spellings ``Camera_Matrix``,
  ``image_Width``; its calibration sample's ``fisheye_model: 1`` means equidistant coefficients).
- **ROS camera_info YAML** (``camera_calibration``): the same keys plus ``distortion_model`` (``plumb_bob`` or
  ``rational_polynomial``: pinhole + OpenCV distortion; ``equidistant``: pinhole + Kannala-Brandt k1..k4, OpenCV's
  ``cv2.fisheye``), ``rectification_matrix`` (3x3), ``projection_matrix`` (3x4), ``camera_name``.
- **Kalibr camchain YAML**: ``cam0: {camera_model, intrinsics, distortion_model, distortion_coeffs, resolution}``
  with Kalibr's models: ``pinhole`` (intrinsics fu, fv, pu, pv) with ``radtan`` (k1, k2, r1, r2), ``equidistant``
  (k1..k4) or ``none``; ``omni`` (xi, fu, fv, pu, pv) with ``radtan`` or ``none``; ``ds`` (xi, alpha, fu, fv, pu,
  pv); ``eucm`` (alpha, beta, fu, fv, pu, pv). With several cameras ``FILE:camN`` picks one (default ``cam0``,
  with a note in ``CameraModel.note``).
- **MATLAB text** (``.m`` / ``.txt``, a Bouguet toolbox export): ``K = [...]`` and ``kc = [...]``; the image size
  is given.

The result is a ``CameraModel`` naming its model by Kalibr's names (``calib_core.data.cameras``). A model or a key
the project does not know is a ``DatasetError`` of one line naming the file, the key and the accepted values: never
a silent misread (a fisheye's four coefficients are never read as OpenCV's k1, k2, p1, p2).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from calib_core.errors import ObservationError

from .model import CameraModel, DatasetError
from .yaml_files import camera_from_dict, matrix_field, read_yaml

ROS_MODELS = {"plumb_bob": "radtan", "rational_polynomial": "radtan", "equidistant": "equidistant"}
"""ROS ``distortion_model`` -> Kalibr's distortion model (pinhole camera)."""
RADTAN_SYNONYMS = ("radtan", "radial_tangential", "none", "")
"""Spellings of OpenCV's pinhole model read in the ROS/OpenCV form before ROS's names were checked: kept."""
KALIBR_INTRINSICS = {"pinhole": ("fu", "fv", "pu", "pv"), "omni": ("xi", "fu", "fv", "pu", "pv"),
                     "ds": ("xi", "alpha", "fu", "fv", "pu", "pv"), "eucm": ("alpha", "beta", "fu", "fv", "pu", "pv")}
"""Kalibr's ``intrinsics`` order per ``camera_model``."""
KALIBR_DISTORTIONS = {"pinhole": ("radtan", "equidistant", "none"), "omni": ("radtan", "none"), "ds": ("none",),
                      "eucm": ("none",)}
"""The ``distortion_model`` values each Kalibr ``camera_model`` takes here."""
KALIBR_DIST_LENGTH = {"radtan": 4, "equidistant": 4, "none": 0}
KALIBR_KEYS = ("camera_model", "intrinsics", "distortion_model", "distortion_coeffs", "resolution", "rostopic",
               "T_cn_cnm1", "T_cam_imu", "cam_overlaps", "timeshift_cam_imu", "line_delay")
"""The keys of one camera of a camchain (the last six Kalibr writes and this reader passes over)."""
LENS_PARAMS = ("xi", "alpha", "beta")
"""Keys of the models' own parameters beside the OpenCV keys (with a top-level Kalibr ``camera_model``)."""
FOREIGN_KEYS = ("model_type", "projection_model", "distortion_type", "intrinsics", "distortion_coeffs",
                "projection_parameters", "distortion_parameters", "mirror_parameters")
"""Keys naming a lens in another tool's form that the OpenCV/ROS form has no place for: refused, never passed
over."""
KALIBR_NAME = re.compile(r"^cam\d+$")


def read_camera(path, cam: str | None = None, size: tuple[int, int] | None = None) -> CameraModel:
    """The camera of a camera file in any form (module docstring). ``path`` may end in ``:camN`` to pick a camera
    of a Kalibr camchain (as ``cam`` does); ``size`` (width, height) is the image size where the file has none (MATLAB
    text). DatasetError naming the file and the key otherwise."""
    path, cam = _split_cam(path, cam)
    if path.suffix.lower() == ".xml":
        return _opencv_xml(path)
    if path.suffix.lower() in (".m", ".txt"):
        return _matlab_text(path, size)
    return camera_from_mapping(read_yaml(path), path, cam)


def load_camera(path) -> CameraModel:
    """A dataset folder's ``camera.yaml`` in any form (``read_camera``)."""
    return read_camera(path)


def _split_cam(path, cam: str | None) -> tuple[Path, str | None]:
    """``FILE:camN`` -> (FILE, camN) when FILE exists and ``FILE:camN`` does not."""
    text = str(path)
    m = re.match(r"^(.*):(cam\d+)$", text)
    if m and not Path(text).exists() and Path(m.group(1)).exists():
        if cam is not None and cam != m.group(2):
            raise DatasetError(f"camera {m.group(2)!r} in the file name and {cam!r} given: give one", file=m.group(1))
        return Path(m.group(1)), m.group(2)
    return Path(text), cam


def camera_from_mapping(data: dict, path, cam: str | None = None, prefix: str = "") -> CameraModel:
    """The camera of a parsed camera file ``data`` in any YAML form, recognised by its keys (a Kalibr camchain: a
    ``camN`` mapping or ``camera_model`` with ``intrinsics``; otherwise the OpenCV/ROS keys). ``prefix`` names the
    section holding ``data`` in errors (e.g. ``camera.`` in a plan rig file)."""
    path = Path(path)
    cams = {str(k): v for k, v in data.items() if KALIBR_NAME.match(str(k))}
    if cams:
        return _kalibr_chain(cams, path, cam, prefix)
    if cam is not None:
        raise DatasetError(f"camera {cam!r} asked for, but the file is not a Kalibr camchain (no cam0: ... section)",
                           file=path)
    if "camera_model" in data and "intrinsics" in data:
        return _kalibr(data, path, prefix.rstrip("."))
    return _opencv_ros(data, path, prefix)


def _opencv_ros(data: dict, path: Path, prefix: str = "") -> CameraModel:
    """OpenCV keys, with ROS's ``distortion_model`` or (with a top-level ``camera_model``) Kalibr's model names and
    the model's parameters (``xi``, ``alpha``, ``beta``) beside them."""
    foreign = [k for k in FOREIGN_KEYS if k in data]
    if foreign:
        raise DatasetError(f"key '{prefix}{foreign[0]}' is not a key of an OpenCV/ROS camera file (image_width, "
                           "image_height, camera_matrix, distortion_model, distortion_coefficients, "
                           "rectification_matrix, projection_matrix; camera_model with xi, alpha, beta) nor of a "
                           "Kalibr camchain (cam0: {camera_model, intrinsics, distortion_model, distortion_coeffs, "
                           "resolution})", file=path)
    if "camera_model" in data:
        cm, dm, params = _named_model(data, path, prefix)
    else:
        cm, dm, params = "pinhole", _distortion_model(data, path, prefix), ()
        stray = [k for k in LENS_PARAMS if k in data]
        if stray:
            raise DatasetError(f"key '{prefix}{stray[0]}': a model parameter needs camera_model (omni: xi; ds: xi, "
                               "alpha; eucm: alpha, beta)", file=path)
    if "image_Width" in data and "image_width" not in data:  # OpenCV sample spelling
        data = dict(data, image_width=data["image_Width"], image_height=data.get("image_Height"))
    for key, shape in (("rectification_matrix", (3, 3)), ("projection_matrix", (3, 4))):
        if key in data:
            matrix_field(data[key], prefix + key, path, shape)
    if (cm, dm) == ("pinhole", "radtan"):
        return camera_from_dict(data, path)
    cam = camera_from_dict({k: v for k, v in data.items() if k != "distortion_coefficients"}, path)
    dist = matrix_field(data.get("distortion_coefficients", []), prefix + "distortion_coefficients", path, (None,))
    n = KALIBR_DIST_LENGTH.get(dm) if cm != "omni" else None
    if n is not None and dist.size not in (0, n):
        raise DatasetError(f"key '{prefix}distortion_coefficients': the {dm} model takes {n} coefficients, got "
                           f"{dist.size}", file=path)
    return lens_camera(cm, dm, cam.K, dist, cam.width, cam.height, params, file=path,
                       key=prefix + "distortion_coefficients")


def _named_model(data: dict, path: Path, prefix: str) -> tuple[str, str, tuple[float, ...]]:
    """Kalibr's ``camera_model`` / ``distortion_model`` at the top of an OpenCV-keys file, and the model's
    parameters."""
    cm = str(data["camera_model"]).strip().lower()
    if cm not in KALIBR_INTRINSICS:
        raise DatasetError(f"key '{prefix}camera_model': {data['camera_model']!r} is not a model the project knows "
                           f"(accepted: {', '.join(KALIBR_INTRINSICS)})", file=path)
    raw = data.get("distortion_model", KALIBR_DISTORTIONS[cm][0])
    dm = str(raw).strip().lower()
    dm = ROS_MODELS.get(dm, dm) if cm == "pinhole" else ("radtan" if dm in ROS_MODELS and cm == "omni" else dm)
    if dm not in KALIBR_DISTORTIONS[cm]:
        raise DatasetError(f"key '{prefix}distortion_model': {raw!r} is not a model the project knows with "
                           f"camera_model {cm} (accepted: {', '.join(KALIBR_DISTORTIONS[cm])})", file=path)
    if dm == "none" and cm in ("pinhole", "omni"):
        dm = "radtan"
    names = KALIBR_INTRINSICS[cm][:-4]
    stray = [k for k in LENS_PARAMS if k in data and k not in names]
    if stray:
        raise DatasetError(f"key '{prefix}{stray[0]}' is not a parameter of the {cm} model (accepted: "
                           f"{', '.join(names) or 'none'})", file=path)
    missing = [k for k in names if k not in data]
    if missing:
        raise DatasetError(f"key '{prefix}{missing[0]}': missing (the {cm} model's parameter)", file=path)
    try:
        params = tuple(float(data[k]) for k in names)
    except (TypeError, ValueError):
        raise DatasetError(f"key '{prefix}{names[0]}': the {cm} model's {', '.join(names)} must be numbers",
                           file=path) from None
    return cm, dm, params


def lens_camera(camera_model: str, distortion_model: str, K: np.ndarray, dist, width: int, height: int,
                params=(), std=None, *, file=None, key: str = "camera_matrix") -> CameraModel:
    """The CameraModel of Kalibr's ``(camera_model, distortion_model)`` (``model`` None for pinhole + radtan, the
    OpenCV path) with ``K`` (pixels), ``dist``, the image size and the model's ``params`` (its ``param_names``
    order); DatasetError naming ``file`` and ``key`` when the model refuses a value."""
    from calib_core.data.cameras import camera_class

    dist = np.asarray(dist, float).ravel()
    if (camera_model, distortion_model) == ("pinhole", "radtan"):
        return CameraModel(int(width), int(height), np.asarray(K, float), dist, std)
    cls = camera_class(camera_model, distortion_model)
    try:
        model = cls(np.asarray(K, float), dist, int(width), int(height), std,
                    **dict(zip(cls.param_names, params, strict=True)))
    except ObservationError as err:
        raise DatasetError(f"key '{key}': the {cls.camera_model} model refuses it ({err})", file=file) from None
    return CameraModel(int(width), int(height), model.K, dist, model.std_intrinsics, model)


def _distortion_model(data: dict, path: Path, prefix: str) -> str:
    """Kalibr's distortion model of a pinhole camera in the OpenCV/ROS form: ``distortion_model`` (ROS's names) or
    OpenCV's ``fisheye_model`` flag; ``radtan`` when neither is there."""
    raw = data.get("distortion_model")
    fisheye = data.get("fisheye_model")
    if fisheye is not None and not isinstance(fisheye, (bool, int)):
        raise DatasetError(f"key '{prefix}fisheye_model': expected 0 or 1, got {fisheye!r}", file=path)
    if raw is None:
        return "equidistant" if fisheye else "radtan"
    if not isinstance(raw, str):
        raise DatasetError(f"key '{prefix}distortion_model': expected a name, got {raw!r}", file=path)
    name = raw.strip().lower()
    if name in ROS_MODELS:
        model = ROS_MODELS[name]
    elif name in RADTAN_SYNONYMS:
        model = "radtan"
    else:
        raise DatasetError(f"key '{prefix}distortion_model': {raw!r} is not a model the project knows (accepted: "
                           f"{', '.join(ROS_MODELS)}; omni, ds and eucm cameras in a Kalibr camchain)", file=path)
    if fisheye is not None and bool(fisheye) != (model == "equidistant"):
        raise DatasetError(f"key '{prefix}fisheye_model': {fisheye} contradicts distortion_model {raw!r}", file=path)
    return model


def _kalibr_chain(cams: dict, path: Path, cam: str | None, prefix: str) -> CameraModel:
    names = sorted(cams, key=lambda n: int(n[3:]))
    note = ""
    if cam is None:
        cam = "cam0" if "cam0" in cams else names[0]
        if len(names) > 1:
            note = (f"{path.name} is a camchain of {len(names)} cameras ({', '.join(names)}): {cam} read (another: "
                    f"--camera {path.name}:camN where a command takes a camera file; in a dataset folder, make it "
                    "cam0)")
    if cam not in cams:
        raise DatasetError(f"Kalibr camchain has no camera {cam!r} (has {', '.join(names)})", file=path)
    if not isinstance(cams[cam], dict):
        raise DatasetError(f"key '{prefix}{cam}': expected a mapping (camera_model, intrinsics, ...)", file=path)
    out = _kalibr(cams[cam], path, prefix + cam)
    return CameraModel(out.width, out.height, out.K, out.dist, None, out.model, note)


def _kalibr(c: dict, path: Path, name: str) -> CameraModel:
    """One camera of a camchain (``name``: its key, e.g. ``cam0``)."""
    at = f"{name}." if name else ""
    unknown = sorted(str(k) for k in c if k not in KALIBR_KEYS)
    if unknown:
        raise DatasetError(f"key '{at}{unknown[0]}' is not a Kalibr camera key (accepted: {', '.join(KALIBR_KEYS)})",
                           file=path)
    model = str(c.get("camera_model", "pinhole")).strip().lower()
    if model not in KALIBR_INTRINSICS:
        raise DatasetError(f"key '{at}camera_model': {c.get('camera_model')!r} is not a model the project knows "
                           f"(accepted: {', '.join(KALIBR_INTRINSICS)})", file=path)
    dmodel = str(c.get("distortion_model", KALIBR_DISTORTIONS[model][0])).strip().lower()
    if dmodel not in KALIBR_DISTORTIONS[model]:
        raise DatasetError(f"key '{at}distortion_model': {c.get('distortion_model')!r} is not a model the project "
                           f"knows with camera_model {model} (accepted: {', '.join(KALIBR_DISTORTIONS[model])})",
                           file=path)
    want = KALIBR_INTRINSICS[model]
    for key in ("intrinsics", "resolution"):
        if key not in c:
            raise DatasetError(f"key '{at}{key}': missing", file=path)
    k = matrix_field(c["intrinsics"], at + "intrinsics", path, (None,))
    if k.size != len(want):
        raise DatasetError(f"key '{at}intrinsics': camera_model {model} takes [{', '.join(want)}], got {k.size} "
                           "numbers", file=path)
    res = matrix_field(c["resolution"], at + "resolution", path, (2,))
    if not (np.all(res == np.round(res)) and np.all(res > 0)):
        raise DatasetError(f"key '{at}resolution': expected [width, height] in pixels, got {res.tolist()}", file=path)
    dist = matrix_field(c.get("distortion_coeffs", []), at + "distortion_coeffs", path, (None,))
    n = KALIBR_DIST_LENGTH[dmodel]
    if dist.size not in (0, n):
        raise DatasetError(f"key '{at}distortion_coeffs': distortion_model {dmodel} takes {n} coefficients, got "
                           f"{dist.size}", file=path)
    fu, fv, pu, pv = k[-4:]
    K = np.array([[fu, 0.0, pu], [0.0, fv, pv], [0.0, 0.0, 1.0]])
    if dmodel == "none":
        dmodel = "radtan" if model in ("pinhole", "omni") else "none"
        dist = np.zeros(0)
    return lens_camera(model, dmodel, K, dist if np.any(dist) else np.zeros(0), int(res[0]), int(res[1]),
                       tuple(float(v) for v in k[:-4]), file=path, key=at + "intrinsics")


def _opencv_xml(path: Path) -> CameraModel:
    """An OpenCV FileStorage XML file (OpenCV keys; ``distortion_model`` or ``fisheye_model`` as in the YAML)."""
    import cv2

    field = None

    def node(*names, required=True):
        nonlocal field
        field = names[0]
        for n in names:
            nd = fs.getNode(n)
            if not nd.empty():
                return nd
        if required:
            raise DatasetError(f"field {names[0]}: missing", file=path)
        return None

    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        if not fs.isOpened():
            raise DatasetError("not a readable OpenCV FileStorage file", file=path)
        try:
            K = node("camera_matrix", "Camera_Matrix").mat()
            dist = node("distortion_coefficients", "Distortion_Coefficients").mat()
            w = node("image_width", "image_Width").real()
            h = node("image_height", "image_Height").real()
            extra = {}
            nd = node("distortion_model", required=False)
            if nd is not None:
                extra["distortion_model"] = nd.string() if nd.isString() else nd.real()
            nd = node("fisheye_model", required=False)
            if nd is not None:
                extra["fisheye_model"] = int(nd.real())
            for key in FOREIGN_KEYS:
                if node(key, required=False) is not None:
                    extra[key] = True
        finally:
            fs.release()
    except (cv2.error, SystemError) as exc:  # OpenCV's parser on a malformed file or node
        why = getattr(exc, "err", None) or "malformed"
        where = "not an OpenCV FileStorage file" if field is None else f"field {field}: not readable by OpenCV"
        raise DatasetError(f"{where} ({why})", file=path) from None
    if K is None or K.shape != (3, 3):
        raise DatasetError("field camera_matrix: expected a 3x3 matrix", file=path)
    dist = [] if dist is None else np.asarray(dist, float).ravel().tolist()
    if not (np.isfinite(w) and np.isfinite(h) and w == int(w) and h == int(h)):
        raise DatasetError(f"field image_width / image_height: {w} x {h} is not an image size", file=path)
    return _opencv_ros({"image_width": int(w), "image_height": int(h), "camera_matrix": K.tolist(),
                        "distortion_coefficients": dist, **extra}, path)  # the checks of camera.yaml


def _matlab_text(path: Path, size: tuple[int, int] | None) -> CameraModel:
    """A MATLAB text export: ``K = [fx 0 cx; 0 fy cy; 0 0 1];`` and ``kc = [k1; k2; p1; p2; k3]'`` (OpenCV's order)."""
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


def _row(values) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def camera_yaml(camera: CameraModel, comment: str = "") -> str:
    """camera.yaml text of ``camera`` in the form that holds its model: OpenCV keys for pinhole + OpenCV
    distortion (as before), ROS's ``distortion_model: equidistant`` for pinhole + equidistant, a Kalibr camchain
    (``cam0``) for omni, ds and eucm. ``read_camera`` reads it back to the same intrinsics."""
    head = f"# {comment}\n" if comment else ""
    K = camera.K
    if camera.camera_model == "pinhole":
        rows = ", ".join(_row(r) for r in K)
        model = "" if camera.is_opencv_pinhole else "distortion_model: equidistant\n"
        return (f"{head}image_width: {camera.width}\nimage_height: {camera.height}\ncamera_matrix: [{rows}]\n"
                f"{model}distortion_coefficients: {_row(camera.dist)}\n")
    dist = np.asarray(camera.dist, float)
    dmodel = camera.distortion_model
    intr = [*camera.params, K[0, 0], K[1, 1], K[0, 2], K[1, 2]]
    coeffs = (np.r_[dist, np.zeros(4)][:4] if np.any(dist) else np.zeros(0)) if dmodel == "radtan" else dist
    if dmodel == "radtan" and np.any(dist[4:]):
        raise DatasetError(f"the {camera.name} camera has distortion terms beyond k1, k2, p1, p2: a Kalibr camchain "
                           "cannot hold them")
    return (f"{head}cam0:\n  camera_model: {camera.camera_model}\n  intrinsics: {_row(intr)}\n"
            f"  distortion_model: {dmodel}\n  distortion_coeffs: {_row(coeffs)}\n"
            f"  resolution: [{camera.width}, {camera.height}]\n")


def camera_formats() -> list[str]:
    """Lines for the user: the camera models and the camera file forms the project reads (``lidarcam formats``)."""
    from calib_core.data.cameras import CAMERA_MODELS

    models = ", ".join(f"{c}/{d}" for c, d in CAMERA_MODELS)
    return [
        f"camera models (Kalibr's camera_model/distortion_model): {models}",
        "camera files (recognised by their keys; docs/dataset.md has an example of each):",
        "  OpenCV keys   image_width, image_height, camera_matrix, distortion_coefficients (YAML, %YAML:1.0 or XML; "
        "fisheye_model: 1 for cv2.fisheye coefficients): pinhole/radtan, pinhole/equidistant",
        "  ROS           camera_info YAML of camera_calibration: the OpenCV keys + distortion_model plumb_bob | "
        "rational_polynomial | equidistant, rectification_matrix, projection_matrix",
        "  Kalibr        camchain YAML: cam0: {camera_model pinhole | omni | ds | eucm, intrinsics, distortion_model "
        "radtan | equidistant | none, distortion_coeffs, resolution}; FILE:camN picks another camera",
        "  MATLAB text   K = [...]; kc = [...] (import --camera only; pinhole/radtan)",
    ]
