"""Where the corners of the identified boards lie in their board frame (metres; the pattern on the plane z = 0, x to
the right and y down as printed, z away from the printed side): OpenCV's ChArUco board and Kalibr's AprilGrid.
Corners are listed by identity: the index of a row is the corner's identity (``lidarcam.rig.dataset.model.BoardSpec``
names the frames and identities)."""

from __future__ import annotations

import numpy as np


def charuco_corners(squares_x: int, squares_y: int, square: float) -> np.ndarray:
    """((squares_x - 1)(squares_y - 1), 3) inner corners of a ChArUco board of ``squares_x`` x ``squares_y``
    squares of side ``square``, row-major (corner id = row index), origin at the pattern's outer corner next to
    corner 0 (OpenCV's ``CharucoBoard.getChessboardCorners``)."""
    j, i = np.mgrid[1:squares_y, 1:squares_x]
    return np.column_stack([i.ravel() * square, j.ravel() * square, np.zeros(i.size)])


def aprilgrid_corners(tag_cols: int, tag_rows: int, tag_size: float, spacing: float) -> np.ndarray:
    """(4 tag_cols tag_rows, 3) tag corners of Kalibr's AprilGrid (tags of side ``tag_size``, ``spacing`` metres
    apart): row ``4 id + k`` is tag ``id``'s corner ``k`` (0 top-left, 1 top-right, 2 bottom-right, 3 bottom-left as
    printed, OpenCV's marker corner order). Tag 0 is printed bottom-left, the ids growing along a row, then upwards;
    origin at the outer top-left corner of the top-left tag."""
    pitch = tag_size + spacing
    ids = np.arange(tag_cols * tag_rows)
    x0 = (ids % tag_cols) * pitch
    y0 = (tag_rows - 1 - ids // tag_cols) * pitch
    x = (x0[:, None] + np.array([0.0, 1.0, 1.0, 0.0]) * tag_size).ravel()
    y = (y0[:, None] + np.array([0.0, 0.0, 1.0, 1.0]) * tag_size).ravel()
    return np.column_stack([x, y, np.zeros(x.size)])


def aprilgrid_extent(tag_cols: int, tag_rows: int, tag_size: float, spacing: float) -> np.ndarray:
    """(4,2) rectangle of the printed AprilGrid (its tags and the black squares around them), board frame, metres."""
    pitch = tag_size + spacing
    x1, y1 = tag_cols * pitch, tag_rows * pitch
    return np.array([[-spacing, -spacing], [x1, -spacing], [x1, y1], [-spacing, y1]])
