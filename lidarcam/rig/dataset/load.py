"""``load_dataset``: a dataset folder (layout in ``lidarcam.rig.dataset``'s docstring and docs/dataset.md) as a
``Dataset``."""

from __future__ import annotations

from pathlib import Path

from .boards import load_board
from .camera_files import load_camera
from .direction import check_scan_direction, load_lidar, mirror_scan, mirror_window
from .model import Dataset, DatasetError, Pose, Scan
from .scans import read_keyed_scans, read_scan_csv, same_pose
from .yaml_files import load_ground_truth, load_windows

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
RESERVED_STEMS = {"camera", "board", "background", "scans", "windows", "ground_truth", "lidar"}


def _sort_key(name: str):
    return (0, int(name), name) if name.isdigit() else (1, 0, name)


def _image_size(path: Path) -> tuple[int, int] | None:
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    return None if img is None else (img.shape[1], img.shape[0])


def _pose_files(root: Path) -> tuple[dict[str, Path], dict[str, Path]]:
    """The folder's images and per-pose CSVs by stem (the reserved files left out); two images of one pose fail."""
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
    return images, csvs


def _check_image(name: str, image_path: Path | None, root: Path, camera) -> None:
    """DatasetError when pose ``name`` has no image, an unreadable one, or one of another size than camera.yaml's."""
    if image_path is None:
        raise DatasetError(f"image missing for pose {name!r} (expected {name}.png or {name}.jpg)",
                           file=root / f"{name}.png", pose=name)
    size = _image_size(image_path)
    if size is None:
        raise DatasetError("cannot read image (missing, empty or not an image)", file=image_path, pose=name)
    if size != (camera.width, camera.height):
        raise DatasetError(f"image is {size[0]}x{size[1]} but camera.yaml says "
                           f"{camera.width}x{camera.height}", file=image_path, pose=name)


def _pose_scan(name: str, root: Path, csvs: dict[str, Path], keyed: dict[str, Scan],
               keyed_err: dict[str, DatasetError]) -> Scan:
    """Pose ``name``'s scan: its own CSV or its rows of scans.csv (not both); DatasetError when none or bad."""
    k = next((k for k in list(keyed) + list(keyed_err) if same_pose(k, name)), None)
    if name in csvs:
        if k is not None:
            raise DatasetError(f"pose {name!r} has a scan both here and in scans.csv", file=csvs[name], pose=name)
        return read_scan_csv(csvs[name], pose=name)
    if k is None:
        raise DatasetError(f"no scan for pose {name!r} (expected {name}.csv or rows in scans.csv)",
                           file=root / f"{name}.csv", pose=name)
    if k in keyed_err:
        raise keyed_err[k]
    return keyed[k]


def _direction(root: Path, given: str | None) -> tuple[str, str]:
    """(scan direction, its source): ``given`` when not None, else lidar.yaml's ``scan_direction``, else ccw."""
    if given is not None:
        return check_scan_direction(given), "given"
    declared = load_lidar(root / "lidar.yaml").get("scan_direction") if (root / "lidar.yaml").exists() else None
    return (declared, "lidar.yaml") if declared else ("ccw", "default")


def load_dataset(root, scan_direction: str | None = None) -> Dataset:
    """Load a dataset folder (layout in the package docstring and docs/dataset.md).

    ``scan_direction`` (``cw`` or ``ccw``) overrides lidar.yaml's; with ``cw`` every scan, the background and the
    windows are read mirrored (``lidarcam.rig.dataset.direction``).

    Raises DatasetError when the folder, camera.yaml, board.yaml, background.csv, windows.yaml or the header of
    scans.csv is bad. Per-pose problems (missing/unreadable image, image size differing from camera.yaml, missing
    scan, a CSV row that does not parse) are recorded in that pose's ``error``.
    """
    root = Path(root)
    if not root.is_dir():
        raise DatasetError("not a dataset folder (does not exist or is not a directory)", file=root)
    direction, direction_source = _direction(root, scan_direction)
    camera = load_camera(root / "camera.yaml")
    board = load_board(root / "board.yaml")
    windows = load_windows(root / "windows.yaml") if (root / "windows.yaml").exists() else {}
    background = read_scan_csv(root / "background.csv") if (root / "background.csv").exists() else None
    ground_truth = load_ground_truth(root / "ground_truth.yaml") if (root / "ground_truth.yaml").exists() else {}
    images, csvs = _pose_files(root)
    keyed: dict[str, Scan] = {}
    keyed_err: dict[str, DatasetError] = {}
    if (root / "scans.csv").exists():
        keyed, keyed_err = read_keyed_scans(root / "scans.csv")
    names = set(images) | set(csvs)
    names |= {k for k in list(keyed) + list(keyed_err) if not any(same_pose(k, n) for n in names)}
    poses = []
    for name in sorted(names, key=_sort_key):
        error, scan = None, None
        try:
            _check_image(name, images.get(name), root, camera)
            scan = _pose_scan(name, root, csvs, keyed, keyed_err)
        except DatasetError as err:
            error = err if err.pose is not None else DatasetError(err.message, file=err.file, line=err.line,
                                                                  pose=name)
        window = next((w for k, w in windows.items() if same_pose(k, name)), None)
        poses.append(Pose(name, images.get(name), scan, window, error))
    unknown = [k for k in windows if not any(same_pose(k, p.name) for p in poses)]
    if unknown:
        raise DatasetError(f"windows for unknown poses {unknown}", file=root / "windows.yaml")
    if direction == "cw":
        poses = [Pose(p.name, p.image_path, None if p.scan is None else mirror_scan(p.scan),
                      None if p.window is None else mirror_window(p.window), p.error, p.corners) for p in poses]
        background = None if background is None else mirror_scan(background)
    return Dataset(root, camera, board, tuple(poses), background, ground_truth, direction, direction_source)
