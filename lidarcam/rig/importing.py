"""Assembling the project's inputs from the formats calibration data comes in: ``lidarcam import`` and
``make real-data`` both go through these functions, so they use the same boards.

- images + scans (RADLOCC laser log, a folder of PCD scans, a folder of range-only logs) -> a dataset folder
  (docs/dataset.md: ``camera.yaml``, ``board.yaml``, ``NNN.png`` + ``NNN.csv``) for ``lidarcam extract``;
- board poses + segmented scan points (a Bouguet ``Calib_Results.mat`` with its detected corners and intrinsics,
  or a CSV of board poses) -> ``lidarcam.observations/1`` directly.

A source without the physical board's outline gives the printed pattern's (one square beyond the inner corners)
as a lower bound (``outline_kind`` ``lower_bound``). Metres and radians.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calib_core.data.camera import Camera
from calib_core.data.observations import BoardObservation, Observations, check_outline_kind
from calib_core.errors import ObservationError

from .dataset import IMAGE_SUFFIXES, BoardSpec, CameraModel, Dataset, DatasetError, Pose, Scan, csv_rows
from .importers.bouguet import grid_outline, read_bouguet
from .importers.camera_yaml import read_camera_file
from .importers.pcd import read_pcd_scan
from .importers.radlocc import read_radlocc_laser
from .importers.ranges import read_range_log
from .importers.segmented import read_segmented_points


@dataclass(frozen=True)
class SourcePose:
    """One pose of an image + scan source: ``name``, ``image`` (path), ``scan``."""

    name: str
    image: Path
    scan: Scan


def pattern_board(cols: int, rows: int, square_m: float) -> BoardSpec:
    """A checkerboard whose physical outline is not known: the printed pattern's outline (a lower bound)."""
    grid = BoardSpec(cols, rows, square_m, np.zeros((3, 2))).corners
    return BoardSpec(cols, rows, square_m, grid_outline(grid, square_m))


def sorted_files(folder, suffixes: tuple[str, ...]) -> list[Path]:
    """Files of ``folder`` with one of ``suffixes`` (lower case), in sorted name order; DatasetError when none."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DatasetError("not a folder", file=folder)
    out = sorted(p for p in folder.iterdir() if p.suffix.lower() in suffixes)
    if not out:
        raise DatasetError(f"no {'/'.join(suffixes)} files", file=folder)
    return out


def pair_in_order(images: list[Path], scans: list[Scan]) -> list[SourcePose]:
    """The i-th image with the i-th scan (both in sorted file order), poses named 000, 001, ..."""
    if len(images) != len(scans):
        raise DatasetError(f"{len(images)} images but {len(scans)} scans: cannot pair them in order",
                           file=images[0].parent if images else None)
    return [SourcePose(f"{i:03d}", im, sc) for i, (im, sc) in enumerate(zip(images, scans, strict=True))]


def radlocc_poses(laser, images, lines: range | None, image_name: str) -> list[SourcePose]:
    """RADLOCC laser lines paired with images by line number: line n <-> ``image_name.format(n=n)`` in ``images``;
    poses named by the line number (a line without its image, or the reverse, is left out)."""
    scans = read_radlocc_laser(laser, lines)
    out = []
    for s in scans:
        img = Path(images) / image_name.format(n=s.line)
        if img.exists():
            out.append(SourcePose(str(s.line), img, s.scan))
    if not out:
        raise DatasetError(f"no laser line has its image {image_name!r}", file=images)
    return out


def pcd_poses(lasers, images) -> list[SourcePose]:
    """The i-th image of ``images`` with the i-th PCD scan of ``lasers`` (sorted names)."""
    return pair_in_order(sorted_files(images, IMAGE_SUFFIXES),
                         [read_pcd_scan(p) for p in sorted_files(lasers, (".pcd",))])


def range_log_poses(scans, images, start_rad: float, step_rad: float, unit: str, suffix: str = ".log"
                    ) -> list[SourcePose]:
    """The i-th image of ``images`` with the i-th range-only log of ``scans`` (sorted names)."""
    logs = sorted_files(scans, (suffix.lower(),))
    return pair_in_order(sorted_files(images, IMAGE_SUFFIXES), [read_range_log(p, start_rad, step_rad, unit)
                                                                for p in logs])


def image_size(path: Path) -> tuple[int, int]:
    """(width, height) of an image file."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise DatasetError("cannot read image", file=path)
    return int(img.shape[1]), int(img.shape[0])


def source_camera(camera_file, intrinsics, dist, size: tuple[int, int]) -> CameraModel:
    """The camera of a source: a camera file (ROS / OpenCV / Kalibr / MATLAB text; ``size`` where the file has
    none) or ``intrinsics`` (fx, fy, cx, cy; pixels) and ``dist`` (OpenCV order)."""
    if camera_file is not None:
        return read_camera_file(camera_file, size=size)
    if intrinsics is None:
        raise DatasetError("no camera: give a camera file or the intrinsics fx,fy,cx,cy")
    fx, fy, cx, cy = intrinsics
    return CameraModel(size[0], size[1], np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]]),
                       np.asarray(dist if dist is not None else [], float))


def board_yaml(board: BoardSpec) -> str:
    """board.yaml text (docs/dataset.md) of a board: grid, square and outline."""
    outline = "\n".join(f"  - [{x!r}, {y!r}]" for x, y in board.outline.tolist())
    return (f"cols: {board.cols}\nrows: {board.rows}\nsquare_m: {board.square!r}\noutline_m:\n{outline}\n")


def write_dataset_folder(out, poses: list[SourcePose], camera: CameraModel, board: BoardSpec,
                         scan_direction: str | None = None, why: str = "") -> Path:
    """Write the dataset folder (docs/dataset.md) of ``poses``: ``camera.yaml``, ``board.yaml``, per pose its image
    (copied, its suffix kept) and ``<name>.csv`` (``bearing_rad,range_m``, as the source counts them), and
    ``lidar.yaml`` when a ``scan_direction`` is declared (``why``: where the declaration comes from; an earlier
    lidar.yaml is removed when none is). Returns the folder."""
    from .dataset import camera_yaml, lidar_yaml

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "camera.yaml").write_text(camera_yaml(camera, f"the imported camera ({camera.name})"))
    (out / "board.yaml").write_text(board_yaml(board))
    if scan_direction is not None:
        (out / "lidar.yaml").write_text(lidar_yaml(scan_direction, why))
    elif (out / "lidar.yaml").exists():
        (out / "lidar.yaml").unlink()
    for p in poses:
        shutil.copyfile(p.image, out / f"{p.name}{p.image.suffix.lower()}")
        np.savetxt(out / f"{p.name}.csv", np.column_stack([p.scan.bearing, p.scan.range]), delimiter=",",
                   header="bearing_rad,range_m", comments="", fmt="%.9g")
    return out


def as_dataset(poses: list[SourcePose], camera: CameraModel, board: BoardSpec, root,
               scan_direction: str | None = None) -> Dataset:
    """The ``Dataset`` that ``write_dataset_folder`` then ``load_dataset`` give, without writing (the importers
    name poses in ``load_dataset``'s order: line numbers ascending, or 000, 001, ...); ``cw`` scans mirrored."""
    from .dataset import mirror_scan

    cw = scan_direction == "cw"
    return Dataset(Path(root), camera, board, tuple(Pose(p.name, p.image, mirror_scan(p.scan) if cw else p.scan)
                                                    for p in poses),
                   scan_direction=scan_direction or "ccw",
                   scan_direction_source="default" if scan_direction is None else "lidar.yaml")


def mirror_observations(obs: Observations, source: str) -> Observations:
    """Observations whose scan points are read mirrored (``y -> -y``: a clockwise lidar), the declaration recorded
    in ``meta`` (``scan_direction`` ``cw``, ``scan_direction_source`` ``source``)."""
    from dataclasses import replace

    boards = tuple(replace(b, scan=_by_bearing(b.scan * np.array([1.0, -1.0]))) for b in obs.boards)
    return replace(obs, boards=boards, meta={**obs.meta, "scan_direction": "cw", "scan_direction_source": source})


def _by_bearing(points: np.ndarray) -> np.ndarray:
    return points[np.argsort(np.arctan2(points[:, 1], points[:, 0]), kind="stable")]


def _observations(boards, names, camera: Camera | None, source: str, skipped: dict) -> Observations:
    if not boards:
        raise DatasetError(f"no pose has both a board pose and scan points ({source})")
    return Observations(tuple(boards), None, {"source": source, "poses": names, "skipped": skipped}, camera)


def observations_from_bouguet(mat, points, outline_kind: str = "lower_bound", corners: bool = True) -> Observations:
    """Board poses, detected corners and intrinsics of a Bouguet ``Calib_Results.mat`` with the segmented scan
    points of a CSV (``pose,x_m,y_m``, pose = the image index k): one board per pose that has both; the outline is
    the printed pattern's (``outline_kind`` ``lower_bound`` unless told). With ``corners`` the boards carry the
    corners and the observations the camera, so the joint model runs."""
    check_outline_kind(outline_kind)
    calib = read_bouguet(mat)
    pts = read_segmented_points(points)
    square = calib.square_m or float(np.median(np.diff(np.unique(np.round(calib.views[0].grid_m[:, 0], 6)))))
    outline = None if outline_kind == "none" else grid_outline(calib.views[0].grid_m, square)
    c = calib.camera
    camera = Camera(c.K, c.dist, c.width, c.height, c.std_intrinsics) if corners else None
    boards, names, skipped = [], [], {}
    for v in calib.views:
        p = pts.get(str(v.index))
        if p is None:
            skipped[str(v.index)] = "no segmented scan points for this image"
            continue
        px, pb = (v.corners_px, v.grid_m) if corners and len(v.corners_px) else (None, None)
        boards.append(BoardObservation(v.T_cam_board, outline, _by_bearing(p), px, pb, outline_kind=outline_kind))
        names.append(str(v.index))
    return _observations(boards, names, camera, f"{Path(mat).name} + {Path(points).name}", skipped)


POSE_COLUMNS = tuple(f"R_cam_board_{i}{j}" for i in range(3) for j in range(3)) + tuple(
    f"t_cam_board_{a}_mm" for a in "xyz")
"""Columns of a board-pose CSV (besides ``pose``): the rotation row-major and the translation in millimetres,
``X_cam = R X_board + t``."""


def read_board_poses(path) -> dict[str, np.ndarray]:
    """Pose name -> 4x4 ``T_cam_board`` (metres) from a CSV with ``pose`` and ``POSE_COLUMNS``; DatasetError naming
    the file, line and field."""
    path = Path(path)
    rows = csv_rows(path)
    if not rows:
        raise DatasetError("empty file", file=path)
    (_, header), body = rows[0], rows[1:]
    names = [h.strip() for h in header]
    missing = [c for c in ("pose", *POSE_COLUMNS) if c not in names]
    if missing:
        raise DatasetError(f"header lacks column(s) {','.join(missing)}", file=path, line=1)
    out = {}
    for n, r in body:
        if len(r) != len(names):
            raise DatasetError(f"expected {len(names)} fields, got {len(r)}", file=path, line=n)
        try:
            v = np.array([float(r[names.index(c)]) for c in POSE_COLUMNS])
        except ValueError:
            raise DatasetError("a pose field is not a number", file=path, line=n) from None
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = v[:9].reshape(3, 3), v[9:] / 1000.0
        out[r[names.index("pose")].strip()] = T
    return out


def observations_from_segmented(points, poses, board: BoardSpec | None, outline_kind: str = "lower_bound"
                                ) -> Observations:
    """Segmented scan points (``pose,x_m,y_m``) with board poses (``read_board_poses``): one board per pose in
    both. ``board``: the pattern (its outline read as ``outline_kind``); None only with ``outline_kind`` none."""
    check_outline_kind(outline_kind)
    if board is None and outline_kind != "none":
        raise ObservationError("a board (grid and square) is needed unless the outline kind is 'none'",
                               field="outline_kind")
    pts, T = read_segmented_points(points), read_board_poses(poses)
    outline = None if outline_kind == "none" else board.outline
    boards, names, skipped = [], [], {}
    for name, Tcb in T.items():
        if name not in pts:
            skipped[name] = "no segmented scan points for this pose"
            continue
        boards.append(BoardObservation(Tcb, outline, _by_bearing(pts[name]), outline_kind=outline_kind))
        names.append(name)
    return _observations(boards, names, None, f"{Path(poses).name} + {Path(points).name}", skipped)
