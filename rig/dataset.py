"""Real-rig dataset folders: camera.yaml, board.yaml, per-pose images and scans (see docs/dataset.md).

Layout of a dataset folder::

    camera.yaml        intrinsics, OpenCV/ROS style (image_width, image_height, camera_matrix, distortion_coefficients)
    board.yaml         checkerboard: inner-corner grid, square size, physical outline (metres)
    NNN.png | NNN.jpg  one image per pose
    NNN.csv            one scan per pose: header ``bearing_rad,range_m`` or ``x,y`` (lidar frame, metres)
    scans.csv          alternative to the per-pose CSVs: one file keyed by a ``pose`` column
    background.csv     optional: a scan without the board (same columns)
    windows.yaml       optional: per-pose manual bearing window, overrides the automatic segment search
    ground_truth.yaml  optional: written by ``simulate.dataset``; never read by extraction

``load_dataset`` fails as a whole (``DatasetError``) only when the shared files are bad (folder, camera.yaml,
board.yaml, background.csv, windows.yaml); a bad image or scan makes that pose's ``error`` a ``DatasetError``
naming the file and line, and the other poses go on.
"""

from __future__ import annotations

import csv
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from calib_core.data.observations import check_simple_polygon
from calib_core.errors import LidarcamError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
RESERVED_STEMS = {"camera", "board", "background", "scans", "windows", "ground_truth"}


class DatasetError(LidarcamError, ValueError):
    """Bad dataset input; ``str(err)`` reads ``"ds/003.csv: line 7: expected 2 numbers, got 'a,b,c'"``.

    Attributes: ``file`` (path as given), ``line`` (1-based, or None), ``pose`` (pose name, or None), ``message``.
    """

    def __init__(self, message: str, *, file=None, line: int | None = None, pose: str | None = None) -> None:
        self.message = message
        self.file = None if file is None else str(file)
        self.line = line
        self.pose = pose
        parts = [p for p in (self.file, None if line is None else f"line {line}") if p]
        super().__init__(": ".join(parts + [message]))


# --------------------------------------------------------------------------------------------------- dataclasses
@dataclass(frozen=True, eq=False)
class CameraModel:
    """Pinhole camera with OpenCV distortion.

    Attributes: ``width``, ``height`` (pixels); ``K`` 3x3 camera matrix; ``dist`` (D,) OpenCV distortion
    coefficients (k1, k2, p1, p2[, k3, ...]); may be empty.
    """

    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray


@dataclass(frozen=True, eq=False)
class BoardSpec:
    """Checkerboard geometry, board frame: origin at the first inner corner, x along a row of ``cols`` corners,
    y along a column of ``rows`` corners, z = x cross y (the board plane is z = 0); metres.

    Attributes:
        cols, rows: inner corners per row / per column (OpenCV's ``patternSize = (cols, rows)``).
        square: side of one square (m).
        outline: (V,2) physical outline of the board in the board frame (m).
        origin_square_dark: colour of the square spanning x in [0, square], y in [0, square] (True dark, False
            light); used to undo a 180-degree reversal of the corner order (possible only when cols + rows is
            odd). None: keep the detector's order (``findChessboardCornersSB`` starts next to a light outer square
            on an odd x even board, i.e. a light origin square).
    """

    cols: int
    rows: int
    square: float
    outline: np.ndarray
    origin_square_dark: bool | None = None

    @property
    def corners(self) -> np.ndarray:
        """(cols*rows, 3) inner corners in the board frame, row-major (x fastest), as OpenCV orders them."""
        j, i = np.mgrid[0:self.rows, 0:self.cols]
        return np.column_stack([i.ravel() * self.square, j.ravel() * self.square, np.zeros(i.size)])

    @property
    def diagonal(self) -> float:
        """Longest distance between two outline vertices (m): no chord of the board is longer."""
        d = self.outline[:, None, :] - self.outline[None, :, :]
        return float(np.sqrt((d ** 2).sum(-1)).max())

    @property
    def centre(self) -> np.ndarray:
        """Mean of the outline vertices in the board frame (m), (2,)."""
        return self.outline.mean(axis=0)

    @property
    def reversible(self) -> bool:
        """True when a 180-degree turn maps the corner grid onto itself with the same colours (cols+rows even)."""
        return (self.cols + self.rows) % 2 == 0


@dataclass(frozen=True, eq=False)
class Scan:
    """One lidar scan, ordered along the sweep (by bearing, starting after the largest angular gap).

    Attributes: ``bearing`` (K,) radians in (-pi, pi]; ``range`` (K,) metres; ``points`` (K,2) lidar-frame x, y;
    ``n_dropped``: beams without a return (range NaN, inf or <= 0) left out.
    """

    bearing: np.ndarray
    range: np.ndarray
    points: np.ndarray
    n_dropped: int = 0

    def __len__(self) -> int:
        return len(self.range)


@dataclass(frozen=True, eq=False)
class Pose:
    """One board pose of the dataset: an image path and a scan, or the error that makes it unusable.

    Attributes: ``name`` (file stem, e.g. ``"003"``); ``image_path`` (or None); ``scan`` (or None);
    ``window`` (bearing_min, bearing_max) radians from windows.yaml, or None; ``error``: a DatasetError when
    the image or scan is missing or bad (the pose is then skipped by extraction), else None; ``corners``: the
    checkerboard detector's corners (N,2 pixels) when found already (extraction then skips the detection;
    an empty array: the detector found no board).
    """

    name: str
    image_path: Path | None
    scan: Scan | None
    window: tuple[float, float] | None = None
    error: DatasetError | None = None
    corners: np.ndarray | None = None

    def read_image(self) -> np.ndarray:
        """The image as 8-bit grayscale (H, W)."""
        import cv2

        img = cv2.imread(str(self.image_path), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise DatasetError("cannot read image", file=self.image_path, pose=self.name)
        return img


@dataclass(frozen=True, eq=False)
class Dataset:
    """A loaded dataset folder. ``poses`` are sorted by name (numerically when all names are digits)."""

    root: Path
    camera: CameraModel
    board: BoardSpec
    poses: tuple[Pose, ...]
    background: Scan | None = None
    ground_truth: dict = field(default_factory=dict)

    def pose(self, name: str) -> Pose:
        for p in self.poses:
            if p.name == name:
                return p
        raise KeyError(name)


# --------------------------------------------------------------------------------------------------- YAML helpers
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


def _matrix(value, name: str, path: Path, shape: tuple[int | None, ...]) -> np.ndarray:
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


def load_camera(path) -> CameraModel:
    """Read camera.yaml: ``image_width``, ``image_height``, ``camera_matrix`` (3x3), ``distortion_coefficients``."""
    path = Path(path)
    return camera_from_dict(read_yaml(path), path)


def camera_from_dict(data: dict, path: Path) -> CameraModel:
    """A CameraModel from camera.yaml's keys (already parsed); errors name ``path``."""
    try:
        w, h = int(_require(data, "image_width", path)), int(_require(data, "image_height", path))
    except (TypeError, ValueError):
        raise DatasetError("image_width and image_height must be integers", file=path) from None
    if w <= 0 or h <= 0:
        raise DatasetError(f"image size must be positive, got {w}x{h}", file=path)
    K = _matrix(_require(data, "camera_matrix", path), "camera_matrix", path, (3, 3))
    if not (K[0, 0] > 0 and K[1, 1] > 0 and np.allclose(K[2], [0, 0, 1]) and K[1, 0] == 0):
        raise DatasetError("'camera_matrix' must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0",
                           file=path)
    dist = _matrix(data.get("distortion_coefficients", []), "distortion_coefficients", path, (None,))
    if dist.size not in (0, 4, 5, 8, 12, 14):
        raise DatasetError(f"'distortion_coefficients': OpenCV takes 4, 5, 8, 12 or 14, got {dist.size}", file=path)
    K.setflags(write=False)
    dist.setflags(write=False)
    return CameraModel(w, h, K, dist)


def load_board(path) -> BoardSpec:
    """Read board.yaml: ``cols``, ``rows`` (inner corners), ``square_m``, ``outline_m`` [[x, y], ...] and the
    optional ``origin_square`` (``dark`` | ``light``; absent: keep the detector's order). Without ``outline_m``
    the outline is the squares' extent: one square beyond the outer inner corners on every side."""
    path = Path(path)
    return board_from_dict(read_yaml(path), path)


def board_from_dict(data: dict, path: Path) -> BoardSpec:
    """A BoardSpec from board.yaml's keys (already parsed); errors name ``path``."""
    try:
        cols, rows = int(_require(data, "cols", path)), int(_require(data, "rows", path))
        square = float(_require(data, "square_m", path))
    except (TypeError, ValueError):
        raise DatasetError("cols, rows must be integers and square_m a number", file=path) from None
    if cols < 2 or rows < 2:
        raise DatasetError(f"needs at least 2x2 inner corners, got {cols}x{rows}", file=path)
    if not (square > 0 and math.isfinite(square)):
        raise DatasetError(f"square_m must be positive, got {square}", file=path)
    if "outline_m" in data:
        outline = _matrix(data["outline_m"], "outline_m", path, (None, 2))
    else:
        x0, y0, x1, y1 = -square, -square, cols * square, rows * square
        outline = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    why = check_simple_polygon(outline)
    if why:
        raise DatasetError(f"'outline_m' {why}", file=path)
    colour = data.get("origin_square")
    if colour is not None and str(colour).lower() not in ("dark", "light", "black", "white"):
        raise DatasetError(f"'origin_square' must be dark or light, got {colour!r}", file=path)
    outline.setflags(write=False)
    dark = None if colour is None else str(colour).lower() in ("dark", "black")
    return BoardSpec(cols, rows, square, outline, dark)


# --------------------------------------------------------------------------------------------------- scans
def make_scan(bearing=None, rng=None, points=None) -> Scan:
    """A Scan from bearings + ranges or from x, y points; drops no-return beams and orders along the sweep."""
    if points is not None:
        points = np.asarray(points, float).reshape(-1, 2)
        rng = np.hypot(points[:, 0], points[:, 1])
        bearing = np.arctan2(points[:, 1], points[:, 0])
    bearing = np.asarray(bearing, float).ravel()
    rng = np.asarray(rng, float).ravel()
    good = np.isfinite(rng) & np.isfinite(bearing) & (rng > 0)
    bearing, rng = np.arctan2(np.sin(bearing[good]), np.cos(bearing[good])), rng[good]
    order = np.argsort(bearing, kind="stable")
    bearing, rng = bearing[order], rng[order]
    if len(bearing) > 1:  # start after the largest angular gap, so a 360-degree sweep stays contiguous
        gaps = np.diff(np.concatenate([bearing, bearing[:1] + 2 * np.pi]))
        start = (int(np.argmax(gaps)) + 1) % len(bearing)
        bearing, rng = np.roll(bearing, -start), np.roll(rng, -start)
    pts = np.column_stack([rng * np.cos(bearing), rng * np.sin(bearing)])
    for a in (bearing, rng, pts):
        a.setflags(write=False)
    return Scan(bearing, rng, pts, int((~good).sum()))


_COLUMN_SETS = (("bearing_rad", "range_m"), ("x", "y"))


def _scan_columns(header: list[str], path: Path, keyed: bool) -> tuple[dict[str, int], tuple[str, str]]:
    names = [h.strip().lower() for h in header]
    idx = {n: i for i, n in enumerate(names)}
    for cols in _COLUMN_SETS:
        if all(c in idx for c in cols) and (not keyed or "pose" in idx):
            return idx, cols
    want = " or ".join(",".join((("pose",) if keyed else ()) + c) for c in _COLUMN_SETS)
    raise DatasetError(f"header must name the columns {want}; got {','.join(header)!r}", file=path, line=1)


def _parse_row(row: list[str], idx: dict[str, int], cols: tuple[str, str], path: Path, line: int,
               pose: str | None) -> tuple[float, float]:
    if len(row) != len(idx):
        raise DatasetError(f"expected {len(idx)} fields, got {len(row)}: {','.join(row)!r}", file=path, line=line,
                           pose=pose)
    try:
        a, b = float(row[idx[cols[0]]]), float(row[idx[cols[1]]])
    except ValueError:
        raise DatasetError(f"not a number in {','.join(row)!r}", file=path, line=line, pose=pose) from None
    return a, b


def _to_scan(values: list[tuple[float, float]], cols: tuple[str, str]) -> Scan:
    v = np.asarray(values, float).reshape(-1, 2)
    if cols == ("x", "y"):
        ok = np.all(np.isfinite(v), axis=1) & (np.hypot(v[:, 0], v[:, 1]) > 0)
        s = make_scan(points=v[ok])
        return Scan(s.bearing, s.range, s.points, int((~ok).sum()))
    return make_scan(bearing=v[:, 0], rng=v[:, 1])


def _rows(path: Path):
    try:
        with path.open(newline="") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise DatasetError(f"cannot read ({exc.strerror})", file=path) from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise DatasetError(f"not a text CSV file ({exc})", file=path) from None
    return [(n, r) for n, r in enumerate(rows, start=1) if r and not r[0].lstrip().startswith("#")]


def read_scan_csv(path, pose: str | None = None) -> Scan:
    """One scan from a CSV with header ``bearing_rad,range_m`` or ``x,y`` (extra columns allowed, e.g. intensity).

    Empty lines and lines starting with ``#`` are skipped. ``nan``/``inf``/``0`` ranges are no-returns (dropped);
    a row that does not parse raises DatasetError naming the file and line.
    """
    path = Path(path)
    rows = _rows(path)
    if not rows:
        raise DatasetError("empty file (needs a header and one row per beam)", file=path, pose=pose)
    (_, header), body = rows[0], rows[1:]
    idx, cols = _scan_columns(header, path, keyed=False)
    values = [_parse_row(r, idx, cols, path, n, pose) for n, r in body]
    if not values:
        raise DatasetError("no beams after the header", file=path, pose=pose)
    return _to_scan(values, cols)


def _same_pose(a: str, b: str) -> bool:
    return a == b or (a.isdigit() and b.isdigit() and int(a) == int(b))


def read_keyed_scans(path) -> tuple[dict[str, Scan], dict[str, DatasetError]]:
    """``scans.csv``: scans keyed by a ``pose`` column. Returns (scans by pose, errors by pose); a bad row
    spoils only its own pose."""
    path = Path(path)
    rows = _rows(path)
    if not rows:
        raise DatasetError("empty file", file=path)
    (_, header), body = rows[0], rows[1:]
    idx, cols = _scan_columns(header, path, keyed=True)
    values: dict[str, list] = {}
    errors: dict[str, DatasetError] = {}
    for n, r in body:
        pose = r[idx["pose"]].strip() if len(r) > idx["pose"] else None
        if not pose:
            raise DatasetError("row without a pose", file=path, line=n)
        try:
            values.setdefault(pose, []).append(_parse_row(r, idx, cols, path, n, pose))
        except DatasetError as err:
            errors.setdefault(pose, err)
    scans = {p: _to_scan(v, cols) for p, v in values.items() if p not in errors}
    return scans, errors


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


# --------------------------------------------------------------------------------------------------- the folder
def _sort_key(name: str):
    return (0, int(name), name) if name.isdigit() else (1, 0, name)


def _image_size(path: Path) -> tuple[int, int] | None:
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    return None if img is None else (img.shape[1], img.shape[0])


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
    T = _matrix(value, "T_lidar_cam", path, (4, 4))
    if not np.allclose(T[3], [0, 0, 0, 1]) or abs(np.linalg.det(T[:3, :3]) - 1) > 1e-4:
        raise DatasetError("'T_lidar_cam': not a rigid transform (last row 0 0 0 1, rotation of determinant 1)",
                           file=path)
    return {**gt, "T_lidar_cam": T}


def load_dataset(root) -> Dataset:
    """Load a dataset folder (layout in the module docstring and docs/dataset.md).

    Raises DatasetError when the folder, camera.yaml, board.yaml, background.csv, windows.yaml or the header of
    scans.csv is bad. Per-pose problems (missing/unreadable image, image size differing from camera.yaml, missing
    scan, a CSV row that does not parse) are recorded in that pose's ``error``.
    """
    root = Path(root)
    if not root.is_dir():
        raise DatasetError("not a dataset folder (does not exist or is not a directory)", file=root)
    camera = load_camera(root / "camera.yaml")
    board = load_board(root / "board.yaml")
    windows = load_windows(root / "windows.yaml") if (root / "windows.yaml").exists() else {}
    background = read_scan_csv(root / "background.csv") if (root / "background.csv").exists() else None
    ground_truth = load_ground_truth(root / "ground_truth.yaml") if (root / "ground_truth.yaml").exists() else {}

    images: dict[str, Path] = {}
    csvs: dict[str, Path] = {}
    for p in sorted(root.iterdir()):
        if not p.is_file() or p.stem in RESERVED_STEMS:
            continue
        if p.suffix.lower() in IMAGE_SUFFIXES:
            if p.stem in images:
                raise DatasetError(f"two images for pose {p.stem!r} ({images[p.stem].name}, {p.name})", file=root)
            images[p.stem] = p
        elif p.suffix.lower() == ".csv":
            csvs[p.stem] = p
    keyed: dict[str, Scan] = {}
    keyed_err: dict[str, DatasetError] = {}
    keyed_path = root / "scans.csv"
    if keyed_path.exists():
        keyed, keyed_err = read_keyed_scans(keyed_path)

    def keyed_name(name):
        return next((k for k in list(keyed) + list(keyed_err) if _same_pose(k, name)), None)

    names = set(images) | set(csvs)
    names |= {k for k in list(keyed) + list(keyed_err) if not any(_same_pose(k, n) for n in names)}
    poses = []
    for name in sorted(names, key=_sort_key):
        error = None
        scan = None
        image_path = images.get(name)
        try:
            if image_path is None:
                raise DatasetError(f"image missing for pose {name!r} (expected {name}.png or {name}.jpg)",
                                   file=root / f"{name}.png", pose=name)
            size = _image_size(image_path)
            if size is None:
                raise DatasetError("cannot read image (missing, empty or not an image)", file=image_path, pose=name)
            if size != (camera.width, camera.height):
                raise DatasetError(f"image is {size[0]}x{size[1]} but camera.yaml says "
                                   f"{camera.width}x{camera.height}", file=image_path, pose=name)
            if name in csvs:
                if keyed_name(name) is not None:
                    raise DatasetError(f"pose {name!r} has a scan both here and in scans.csv", file=csvs[name],
                                       pose=name)
                scan = read_scan_csv(csvs[name], pose=name)
            else:
                k = keyed_name(name)
                if k is None:
                    raise DatasetError(f"no scan for pose {name!r} (expected {name}.csv or rows in scans.csv)",
                                       file=root / f"{name}.csv", pose=name)
                if k in keyed_err:
                    raise keyed_err[k]
                scan = keyed[k]
        except DatasetError as err:
            error = err if err.pose is not None else DatasetError(err.message, file=err.file, line=err.line,
                                                                  pose=name)
            scan = None
        window = next((w for k, w in windows.items() if _same_pose(k, name)), None)
        poses.append(Pose(name, image_path, scan, window, error))
    unknown = [k for k in windows if not any(_same_pose(k, p.name) for p in poses)]
    if unknown:
        raise DatasetError(f"windows for unknown poses {unknown}", file=root / "windows.yaml")
    return Dataset(root, camera, board, tuple(poses), background, ground_truth)
