"""Real-rig dataset folders: camera.yaml, board.yaml, per-pose images and scans (see docs/dataset.md).

Layout of a dataset folder::

    camera.yaml        intrinsics: OpenCV keys, a ROS camera_info or a Kalibr camchain (``camera_files``)
    board.yaml         the board: a checkerboard, a Kalibr target (AprilGrid, checkerboard) or a ChArUco board
    NNN.png | NNN.jpg  one image per pose
    NNN.csv            one scan per pose: header ``bearing_rad,range_m`` or ``x,y`` (lidar frame, metres)
    scans.csv          alternative to the per-pose CSVs: one file keyed by a ``pose`` column
    background.csv     optional: a scan without the board (same columns)
    windows.yaml       optional: per-pose manual bearing window, overrides the automatic segment search
    lidar.yaml         optional: ``scan_direction: cw | ccw`` (default ccw; cw: the scans are read mirrored)
    ground_truth.yaml  optional: written by ``simulate.dataset``; never read by extraction

``load_dataset`` fails as a whole (``DatasetError``) only when the shared files are bad (folder, camera.yaml,
board.yaml, background.csv, windows.yaml); a bad image or scan makes that pose's ``error`` a ``DatasetError``
naming the file and line, and the other poses go on.
"""

from .boards import board_from_dict, load_board
from .camera_files import camera_formats, camera_yaml, load_camera, read_camera
from .direction import SCAN_DIRECTIONS, check_scan_direction, lidar_yaml, load_lidar, mirror_scan
from .load import IMAGE_SUFFIXES, RESERVED_STEMS, load_dataset
from .model import BOARD_KINDS, BoardSpec, CameraModel, Dataset, DatasetError, Pose, Scan
from .scans import csv_rows, make_scan, read_keyed_scans, read_scan_csv, same_pose
from .yaml_files import (
    camera_from_dict,
    load_ground_truth,
    load_windows,
    matrix_field,
    read_yaml,
)

__all__ = [
    "BOARD_KINDS", "IMAGE_SUFFIXES", "RESERVED_STEMS", "SCAN_DIRECTIONS", "BoardSpec", "CameraModel", "Dataset",
    "DatasetError", "Pose", "Scan", "board_from_dict", "camera_formats", "camera_from_dict", "camera_yaml",
    "check_scan_direction", "csv_rows", "lidar_yaml", "load_board", "load_camera", "load_dataset", "load_ground_truth",
    "load_lidar", "load_windows", "make_scan", "matrix_field", "mirror_scan", "read_camera", "read_keyed_scans",
    "read_scan_csv", "read_yaml", "same_pose",
]
