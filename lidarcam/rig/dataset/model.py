"""The dataset's data model: camera, board, scan, pose, dataset (frozen dataclasses), and its error type."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib_core.errors import LidarcamError
from calib_core.geometry.patterns import aprilgrid_corners, aprilgrid_extent, charuco_corners


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


@dataclass(frozen=True, eq=False)
class CameraModel:
    """The dataset's camera as its file states it (``lidarcam.rig.dataset.camera_files``): a pinhole with OpenCV
    distortion, or (``model``) any ``calib_core.data.cameras`` model.

    Attributes: ``width``, ``height`` (pixels); ``K`` 3x3 camera matrix; ``dist`` (D,) distortion coefficients
    (pinhole: OpenCV's k1, k2, p1, p2[, k3, ...]; another model: its own, e.g. k1..k4 of ``pinhole-equidistant``);
    may be empty; ``std_intrinsics`` the optional 1-sigma of the intrinsics in ``calib_core``'s order (fx, fy, cx,
    cy in pixels, the model's parameters, then ``dist``; OpenCV's ``stdDeviationsIntrinsics`` for the pinhole), None
    when the source states none; ``model``: the ``calib_core.data.cameras`` model when the file names one other than
    the pinhole with OpenCV distortion (``K`` then holds its fx, fy, cx, cy and ``dist`` its distortion), else None;
    ``note``: what the reader chose for the user (the camera of a several-camera camchain), else empty.
    """

    width: int
    height: int
    K: np.ndarray
    dist: np.ndarray
    std_intrinsics: np.ndarray | None = None
    model: object | None = None
    note: str = ""

    @property
    def lens(self):
        """The camera as a ``calib_core.data.cameras`` model: ``model`` when the file names one other than the
        pinhole with OpenCV distortion, else None (the OpenCV pinhole path: ``K`` and ``dist``)."""
        return self.model

    @property
    def is_opencv_pinhole(self) -> bool:
        """True for pinhole + OpenCV distortion, the model ``cv2.projectPoints`` and ``cv2.undistortPoints`` take."""
        return self.model is None

    @property
    def name(self) -> str:
        """The model's one-word name (``pinhole-radtan``, ``pinhole-equidistant``, ``omni-radtan``, ``ds``,
        ``eucm``)."""
        return "pinhole-radtan" if self.model is None else self.model.name

    @property
    def camera_model(self) -> str:
        """Kalibr's ``camera_model`` (``pinhole``, ``omni``, ``ds``, ``eucm``)."""
        return "pinhole" if self.model is None else self.model.camera_model

    @property
    def distortion_model(self) -> str:
        """Kalibr's ``distortion_model`` (``radtan``, ``equidistant``, ``none``)."""
        return "radtan" if self.model is None else self.model.distortion_model

    @property
    def params(self) -> tuple[float, ...]:
        """The model's own parameters (its ``param_names``: xi; xi, alpha; alpha, beta), unitless."""
        return () if self.model is None else tuple(float(v) for v in self.model.params)

    @classmethod
    def from_core(cls, camera) -> CameraModel:
        """The CameraModel of a ``calib_core`` camera (no 1-sigma)."""
        from calib_core.data.camera import Camera

        model = None if isinstance(camera, Camera) else camera
        return cls(camera.width, camera.height, camera.K, camera.dist, None, model)

    def core(self):
        """The ``calib_core`` camera: ``model``, or ``calib_core.data.camera.Camera`` of ``K``, ``dist`` and
        ``std_intrinsics``; ``ObservationError`` naming the field it refuses."""
        if self.model is not None:
            return self.model
        from calib_core.data.camera import Camera

        return Camera(self.K, self.dist, self.width, self.height, self.std_intrinsics)


BOARD_KINDS = ("checkerboard", "charuco", "aprilgrid")
"""The board kinds of board.yaml (``lidarcam.rig.dataset.boards`` reads their file forms)."""


@dataclass(frozen=True, eq=False)
class BoardSpec:
    """A calibration board's geometry in its frame (the pattern on the plane z = 0, z = x cross y pointing away from
    the side that carries the pattern); metres.

    Kinds (``kind``):

    - ``checkerboard``: origin at the first inner corner, x along a row of ``cols`` corners, y along a column of
      ``rows`` corners; ``square`` the pitch along x (``square_y`` along y when it differs: Kalibr's
      ``colSpacingMeters`` / ``rowSpacingMeters``). Its corners have no identity: the whole grid is found or none.
    - ``charuco``: OpenCV's ChArUco board of ``squares_x`` x ``squares_y`` squares (``cols`` = squares_x - 1,
      ``rows`` = squares_y - 1 inner corners) of side ``square`` with markers of side ``marker`` from the predefined
      ``dictionary`` (``legacy_pattern``: OpenCV's pattern before 4.6.0); OpenCV's board frame: origin at the
      pattern's outer corner next to corner 0, x along the first row of squares, y down the columns. Corner ``k``
      is ChArUco corner id ``k``.
    - ``aprilgrid``: Kalibr's AprilGrid of ``cols`` x ``rows`` tag36h11 tags of side ``square`` (2-bit black border)
      ``spacing`` apart (``tagSpacing * tagSize``), a black square of side ``spacing`` at every gap crossing; origin at
      the outer corner of the top-left tag as printed (tag 0 is printed bottom-left, ids grow along a row, then
      upwards), x to the right, y down. Corner ``4 id + k`` is tag ``id``'s corner ``k`` (0 top-left, 1 top-right,
      2 bottom-right, 3 bottom-left as printed).

    Attributes:
        cols, rows: inner corners per row / per column (checkerboard, charuco) or tags (aprilgrid).
        square: pitch along x (checkerboard), square side (charuco) or tag side (aprilgrid), metres.
        outline: (V,2) physical outline of the board in the board frame (m); board.yaml's ``outline_m``, else the
            pattern's extent (a lower bound).
        origin_square_dark: checkerboard only: colour of the square spanning x in [0, square], y in [0, square]
            (True dark, False light); used to undo a 180-degree reversal of the corner order (possible only when
            cols + rows is odd). None: keep the detector's order (``findChessboardCornersSB`` starts next to a light
            outer square on an odd x even board, i.e. a light origin square).
        kind: one of ``BOARD_KINDS``.
        square_y: checkerboard pitch along y when it differs from ``square`` (None: square).
        marker: charuco marker side (m).
        spacing: aprilgrid gap between tags (m).
        dictionary: charuco: OpenCV's predefined dictionary name (``DICT_5X5_100``); aprilgrid: ``DICT_APRILTAG_36h11``.
        legacy_pattern: charuco: OpenCV's pattern before 4.6.0 (``CharucoBoard.setLegacyPattern``).
        source: the board.yaml form it was read from (``lidarcam``, ``kalibr`` or ``charuco``), for messages.
    """

    cols: int
    rows: int
    square: float
    outline: np.ndarray
    origin_square_dark: bool | None = None
    kind: str = "checkerboard"
    square_y: float | None = None
    marker: float = 0.0
    spacing: float = 0.0
    dictionary: str = ""
    legacy_pattern: bool = False
    source: str = "lidarcam"

    @property
    def identified(self) -> bool:
        """True when each detected corner carries its identity (charuco, aprilgrid): part of the board may be seen."""
        return self.kind != "checkerboard"

    @property
    def pitch_y(self) -> float:
        """Checkerboard pitch along y (m)."""
        return self.square if self.square_y is None else self.square_y

    @property
    def corners(self) -> np.ndarray:
        """(N,3) corners in the board frame, by identity: the checkerboard's and ChArUco's inner corners row-major
        (x fastest, as OpenCV orders them), an AprilGrid's 4 per tag (``4 id + k``)."""
        if self.kind == "aprilgrid":
            return aprilgrid_corners(self.cols, self.rows, self.square, self.spacing)
        if self.kind == "charuco":
            return charuco_corners(self.cols + 1, self.rows + 1, self.square)
        j, i = np.mgrid[0:self.rows, 0:self.cols]
        return np.column_stack([i.ravel() * self.square, j.ravel() * self.pitch_y, np.zeros(i.size)])

    @property
    def pattern_extent(self) -> np.ndarray:
        """(4,2) rectangle of the printed pattern in the board frame (m): one square beyond the outer inner corners
        (checkerboard), the squares (charuco), the tags with their corner squares (aprilgrid)."""
        if self.kind == "checkerboard":
            x0, y0, x1, y1 = -self.square, -self.pitch_y, self.cols * self.square, self.rows * self.pitch_y
        elif self.kind == "charuco":
            x0, y0, x1, y1 = 0.0, 0.0, (self.cols + 1) * self.square, (self.rows + 1) * self.square
        else:
            return aprilgrid_extent(self.cols, self.rows, self.square, self.spacing)
        return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])

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

    def describe(self) -> str:
        """The board in words: ``checkerboard with 6x5 inner corners``, ``ChArUco 7x5 squares (DICT_5X5_100)``."""
        if self.kind == "charuco":
            return f"ChArUco board of {self.cols + 1}x{self.rows + 1} squares ({self.dictionary})"
        if self.kind == "aprilgrid":
            return f"AprilGrid of {self.cols}x{self.rows} tag36h11 tags"
        return f"checkerboard with {self.cols}x{self.rows} inner corners"


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
    """A loaded dataset folder. ``poses`` are sorted by name (numerically when all names are digits).

    ``scan_direction``: which way the scan files count their bearings (``ccw`` or ``cw``; the scans here are
    already read counter-clockwise, ``lidarcam.rig.dataset.direction``); ``scan_direction_source``: ``default`` (nothing
    declared), ``lidar.yaml`` or ``given`` (by the caller, e.g. ``--scan-direction``)."""

    root: Path
    camera: CameraModel
    board: BoardSpec
    poses: tuple[Pose, ...]
    background: Scan | None = None
    ground_truth: dict = field(default_factory=dict)
    scan_direction: str = "ccw"
    scan_direction_source: str = "default"

    def pose(self, name: str) -> Pose:
        for p in self.poses:
            if p.name == name:
                return p
        raise KeyError(name)
