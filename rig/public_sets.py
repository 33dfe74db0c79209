"""Loaders of the three public 2D-lidar + camera data sets in ``../shared/real-data/`` (each folder's SOURCE.md
gives the repository, licence, sensors, board and formats). Each returns the project's data model plus what
the loader knows about the set (published result, board, intrinsics source); nothing is copied anywhere.

- ``rplidar-a1-tx2-edenshin``: Bouguet ``Calib_Results.mat`` + hand-segmented points -> ``Observations``
  (19 poses), with the published RADLOCC extrinsic as ``T_lidar_cam``.
- ``hokuyo-usbcam-kazmierczak``: images ``RGB31..61`` + RADLOCC laser lines 31..61 -> ``Dataset`` (intrinsics
  refitted from the images: the author's are rough).
- ``turtlebot3-acfr-wall-examples``: 5 images + 5 ASCII PCD scans -> ``Dataset`` (intrinsics as hard-coded
  upstream; boards vertical on the floor, so only the planar part of the extrinsic is determined).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib_core.data.observations import BoardObservation, Observations

from .dataset import BoardSpec, CameraModel, Dataset, DatasetError, Pose
from .importers.bouguet import grid_outline, read_bouguet
from .importers.camera_yaml import read_camera_file
from .importers.pcd import read_pcd_scan
from .importers.radlocc import T_lidar_cam_from_radlocc, read_radlocc_laser
from .importers.segmented import read_segmented_points

EDENSHIN, KAZMIERCZAK, ACFR = "rplidar-a1-tx2-edenshin", "hokuyo-usbcam-kazmierczak", "turtlebot3-acfr-wall-examples"

# EdenShin/2D-Lidar_Camera_Calibration calibration/transform_test.py (RADLOCC convention, DELTA in mm)
EDENSHIN_PHI = [[0.9995, 0.0165, -0.0268], [0.0154, -0.9990, -0.0421], [-0.0275, 0.0417, -0.9988]]
EDENSHIN_DELTA_MM = [-27.3456, -24.4341, -100.7541]
# ACFR-RPG/camera_2d_lidar_calibration cam_lidar_2d_icp.py lines 85-86 (OpenCV model)
ACFR_K = [[519.26845842, 0.0, 331.11197675], [0.0, 518.89359517, 229.43433605], [0.0, 0.0, 1.0]]
ACFR_DIST = [0.11418155, 0.19343114, -0.00268067, 0.00371577, -1.09539701]


@dataclass
class RealSet:
    """One public data set as loaded: ``name``, ``folder``, ``board``, and either ``observations`` (already
    segmented) or ``dataset`` (images + raw scans to extract from); ``camera``; ``published`` T_lidar_cam or
    None; ``notes`` (what the loader assumed, one line each)."""

    name: str
    folder: Path
    board: BoardSpec
    camera: CameraModel
    observations: Observations | None = None
    dataset: Dataset | None = None
    published: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    extra: dict = field(default_factory=dict)


def _need(folder: Path, *names: str) -> None:
    for n in names:
        if not (folder / n).exists():
            raise DatasetError(f"missing {n} (see SOURCE.md)", file=folder)


def load_edenshin(folder) -> RealSet:
    """Observations of the 19 poses: planes from the .mat, points from ``derived_laser_board_points.csv``."""
    folder = Path(folder)
    _need(folder, "Calib_Results.mat", "derived_laser_board_points.csv")
    calib = read_bouguet(folder / "Calib_Results.mat")
    pts = read_segmented_points(folder / "derived_laser_board_points.csv")
    square = calib.square_m or 0.023
    outline = grid_outline(calib.views[0].grid_m, square)
    boards, names = [], []
    for v in calib.views:
        p = pts.get(str(v.index))
        if p is None:
            continue
        order = np.argsort(np.arctan2(p[:, 1], p[:, 0]))
        boards.append(BoardObservation(v.T_cam_board, outline, p[order]))
        names.append(str(v.index))
    cols = len(np.unique(np.round(calib.views[0].grid_m[:, 0], 6)))
    rows = len(np.unique(np.round(calib.views[0].grid_m[:, 1], 6)))
    board = BoardSpec(cols, rows, square, outline)
    obs = Observations(tuple(boards), None, {"source": f"{folder.name}: Calib_Results.mat + hand-segmented points",
                                              "poses": names, "skipped": {}})
    published = T_lidar_cam_from_radlocc(EDENSHIN_PHI, EDENSHIN_DELTA_MM)
    return RealSet(EDENSHIN, folder, board, calib.camera, observations=obs, published=published,
                   notes=[f"intrinsics and {len(calib.views)} board poses from Calib_Results.mat (Bouguet, Tc in mm)",
                          f"{sum(len(b.scan) for b in boards)} hand-segmented board points in {len(boards)} poses",
                          "board outline unknown: the printed pattern's (one square beyond the inner corners)"],
                   extra={"bouguet": calib})


def load_kazmierczak(folder, first: int = 31, last: int = 61, camera: CameraModel | None = None) -> RealSet:
    """Images ``RGB<first..last>.png`` paired with RADLOCC laser lines ``first..last`` (line n = image n).

    ``camera``: intrinsics to use; default the author's OpenCV file (rough: refit with ``rig.intrinsics``)."""
    folder = Path(folder)
    _need(folder, "laser.txt", "images")
    scans = {s.line: s.scan for s in read_radlocc_laser(folder / "laser.txt", range(first, last + 1))}
    author = folder / "author_calib_xml" / "out_camera_data.xml"
    camera = camera or read_camera_file(author)
    board = BoardSpec(9, 6, 0.09, grid_outline(BoardSpec(9, 6, 0.09, np.zeros((3, 2))).corners, 0.09))
    poses = []
    for n in range(first, last + 1):
        img = folder / "images" / f"RGB{n}.png"
        err = None if img.exists() and n in scans else DatasetError("image or laser line missing", file=img)
        poses.append(Pose(str(n), img if img.exists() else None, scans.get(n), error=err))
    ds = Dataset(folder, camera, board, tuple(poses))
    return RealSet(KAZMIERCZAK, folder, board, camera, dataset=ds,
                   notes=[f"images RGB{first}..RGB{last} with RADLOCC laser lines {first}..{last} (line n = image n)",
                          "board 9 x 6 inner corners, 90 mm squares; outline unknown (pattern's used)"])


def load_acfr(folder, square_m: float = 0.019) -> RealSet:
    """The 5 image / PCD pairs (i-th file of each folder, sorted), 8 x 11 inner corners, ``square_m``."""
    folder = Path(folder)
    _need(folder, "images", "lasers")
    images = sorted(p for p in (folder / "images").iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
    lasers = sorted((folder / "lasers").glob("*.pcd"))
    if len(images) != len(lasers):
        raise DatasetError(f"{len(images)} images but {len(lasers)} scans", file=folder)
    camera = CameraModel(640, 480, np.array(ACFR_K), np.array(ACFR_DIST))
    board = BoardSpec(8, 11, square_m, grid_outline(BoardSpec(8, 11, square_m, np.zeros((3, 2))).corners, square_m))
    poses = tuple(Pose(f"{i:02d}", img, read_pcd_scan(las)) for i, (img, las) in enumerate(zip(images, lasers,
                                                                                               strict=True)))
    ds = Dataset(folder, camera, board, poses)
    return RealSet(ACFR, folder, board, camera, dataset=ds,
                   notes=["pairs: i-th image with i-th PCD scan in sorted order",
                          "intrinsics as hard-coded upstream (cam_lidar_2d_icp.py)",
                          f"board 8 x 11 inner corners, {1000 * square_m:.0f} mm squares; the printed sheet sits on a "
                          "larger white board whose outline is not stated"])
