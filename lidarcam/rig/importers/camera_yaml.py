"""Camera intrinsics from the files calibration tools write: ``lidarcam.rig.dataset.camera_files`` reads every
form (OpenCV keys as YAML or XML, ROS ``camera_info``, Kalibr camchain, MATLAB text); this name is kept for the
importers."""

from __future__ import annotations

from ..dataset import CameraModel
from ..dataset.camera_files import read_camera


def read_camera_file(path, cam: str | None = None, size: tuple[int, int] | None = None) -> CameraModel:
    """``read_camera``: the camera of a camera file in any form (``cam``: a Kalibr camchain's camera, default
    ``cam0``; ``size`` (width, height): the image size where the file has none); DatasetError naming the file and
    key."""
    return read_camera(path, cam, size)
