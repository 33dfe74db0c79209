"""The board's pose through any lens: ``lidarcam.rig.detect`` finds the corners and puts them in canonical order,
``calib_core.data.cameras.pose.pose_from_corners`` fits ``T_cam_board`` through the camera's model (rays, then the
pixel reprojection error). For pinhole + OpenCV distortion this is ``detect_board`` itself; for the other models
(``pinhole-equidistant``, ``omni-radtan``, ``ds``, ``eucm``) the detector's order decisions are made on the
pinhole of the same K (they depend on the corners' pixels and the board's facing, not on the distortion) and the
pose and reprojection RMS (pixels) are then those of the real lens. Frames: camera ``{C}``, board ``{W}``;
metres, pixels."""

from __future__ import annotations

import numpy as np

from calib_core.data.cameras.pose import pose_from_corners
from calib_core.errors import ObservationError

from .dataset import BoardSpec, CameraModel
from .detect import BoardDetection, detect_board
from .extract_options import ExtractionError


def detect_board_lens(gray: np.ndarray, camera: CameraModel, board: BoardSpec, flags: int | None = None,
                      corners: np.ndarray | None = None) -> BoardDetection:
    """``detect_board`` through ``camera``'s own model (module docstring); ExtractionError when the board is not
    found or its corners give no pose through the lens."""
    if camera.is_opencv_pinhole or board.identified:   # an identified board's pose is fitted through the lens there
        return detect_board(gray, camera, board, flags, corners)
    stand_in = CameraModel(camera.width, camera.height, camera.K, np.zeros(0))
    det = detect_board(gray, stand_in, board, flags, corners)
    lens = camera.core()
    try:
        T = pose_from_corners(lens, board.corners, det.corners)
    except ObservationError as err:
        raise ExtractionError(f"no board pose through the {lens.name} lens: {err}") from None
    if T[:3, 2] @ T[:3, 3] < 0:
        raise ExtractionError(f"the board's pose through the {lens.name} lens faces away from the camera")
    P = board.corners @ T[:3, :3].T + T[:3, 3]
    rms = float(np.sqrt(np.mean(np.sum((lens.project(P) - det.corners) ** 2, axis=1))))
    return BoardDetection(T, det.corners, rms)
