"""The simulated pinhole camera: intrinsics, the checkerboard, rendering, corner detection and board poses.

Frames: ``{C}`` camera (z optical axis, y down); ``{W}`` board (plane z = 0, z pointing away from the camera
side that sees the pattern). Pixels follow OpenCV: pixel (i, j) has its centre at integer coordinates
(x = column j, y = row i), so the image centre is ((W-1)/2, (H-1)/2). Units: metres, pixels.

The checkerboard: ``squares_x`` x ``squares_y`` squares of side ``square_m``, centred on the square board of
side ``size_m`` (its lower-left pattern corner at ``((size_m - squares_x square_m)/2, (size_m - squares_y
square_m)/2)`` in the board frame). The square touching that pattern corner is white: with an odd x even
grid, ``cv2.findChessboardCornersSB`` then lists the inner corners in the same order as
``checkerboard_corners`` (row by row along board y, x fastest, starting next to the board origin); with the
opposite colouring it lists them reversed (checked for 7x6, 9x6, 6x7, 8x5 squares).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from calib_core.geometry.transforms import make_T

WHITE, BLACK, BACKGROUND = 230.0, 25.0, 110.0  # grey levels of the board, its black squares, the world


UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-10)
"""Undistortion's iterations and tolerance (OpenCV's default of 5 iterations is too few for strong distortion)."""


def undistort_points(px: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """(N,2) pixels ``px`` undistorted (OpenCV's model, coefficients ``dist``) into the pinhole ``K``'s pixels, with
    ``UNDISTORT_CRITERIA``: ``cv2.undistortPointsIter`` in OpenCV 4 (whose ``undistortPoints`` takes no criteria),
    ``cv2.undistortPoints(criteria=)`` in OpenCV 5. The same fallback as ``lidarcam.rig.detect.undistort_points``
    (simulate and lidarcam.rig may not import each other: tests/test_layers.py)."""
    pts = np.asarray(px, np.float64).reshape(-1, 1, 2)
    if hasattr(cv2, "undistortPointsIter"):
        return cv2.undistortPointsIter(pts, K, dist, None, K, UNDISTORT_CRITERIA).reshape(-1, 2)
    return cv2.undistortPoints(pts, K, dist, P=K, criteria=UNDISTORT_CRITERIA).reshape(-1, 2)


class CameraError(RuntimeError):
    """The simulated camera could not produce a board pose (no detection, PnP failure)."""


@dataclass(frozen=True)
class BoardSpec:
    """A square board of side ``size_m`` with a centred checkerboard of ``squares_x`` x ``squares_y``
    squares of side ``square_m`` (metres)."""

    size_m: float = 1.0
    squares_x: int = 7
    squares_y: int = 6
    square_m: float = 0.12

    @classmethod
    def of(cls, spec) -> BoardSpec:
        """A BoardSpec from a BoardSpec or anything with SimOptions' board fields."""
        if isinstance(spec, BoardSpec):
            return spec
        return cls(spec.board_size_m, spec.board_squares_x, spec.board_squares_y, spec.checker_square_m)

    @property
    def pattern_origin(self) -> np.ndarray:
        """Board-frame xy (metres) of the pattern's outer corner next to the board origin."""
        return np.array([(self.size_m - self.squares_x * self.square_m) / 2.0,
                         (self.size_m - self.squares_y * self.square_m) / 2.0])

    @property
    def pattern_size(self) -> tuple[int, int]:
        """Inner-corner grid as OpenCV wants it: (columns along board x, rows along board y)."""
        return (self.squares_x - 1, self.squares_y - 1)

    def outline(self) -> np.ndarray:
        """The board outline (4,2) ``[[0,0],[c,0],[c,c],[0,c]]`` in metres."""
        c = self.size_m
        return np.array([[0.0, 0.0], [c, 0.0], [c, c], [0.0, c]])


def camera_matrix(focal_px: float, width: int, height: int) -> np.ndarray:
    """Pinhole K (3x3), square pixels, principal point at the image centre ((W-1)/2, (H-1)/2)."""
    return np.array([[focal_px, 0.0, (width - 1) / 2.0], [0.0, focal_px, (height - 1) / 2.0], [0.0, 0.0, 1.0]])


def checkerboard_corners(spec) -> np.ndarray:
    """Inner corners (N,3) of the checkerboard in the board frame (z = 0), metres, row by row, x fastest.

    ``spec``: a BoardSpec or SimOptions. N = (squares_x - 1)(squares_y - 1).
    """
    b = BoardSpec.of(spec)
    ox, oy = b.pattern_origin
    i, j = np.meshgrid(np.arange(1, b.squares_x), np.arange(1, b.squares_y))  # j rows (y), i columns (x)
    return np.column_stack([ox + i.ravel() * b.square_m, oy + j.ravel() * b.square_m, np.zeros(i.size)])


def project(K: np.ndarray, T_cam_board: np.ndarray, P_board: np.ndarray) -> np.ndarray:
    """Pixel coordinates (N,2) of board-frame points (N,3) seen with pose ``T_cam_board``; no distortion."""
    P = np.asarray(P_board, float) @ T_cam_board[:3, :3].T + T_cam_board[:3, 3]
    uvw = P @ np.asarray(K, float).T
    return uvw[:, :2] / uvw[:, 2:3]


def board_homography(K: np.ndarray, T_cam_board: np.ndarray) -> np.ndarray:
    """Homography (3x3) from board-plane xy (metres) to pixels: ``K [r1 r2 t]``."""
    return np.asarray(K, float) @ np.column_stack([T_cam_board[:3, 0], T_cam_board[:3, 1], T_cam_board[:3, 3]])


def _parity_cover(edges: np.ndarray, origin: float, square: float, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Per interval ``[edges[i], edges[i+1])`` along one board axis (metres): the fraction of it on the pattern's
    odd-index squares and on its even-index squares (``count`` squares of side ``square`` from ``origin``)."""
    def covered(x: np.ndarray, parity: int) -> np.ndarray:   # length of [origin, x] on squares of that parity
        t = np.clip((x - origin) / square, 0.0, count)
        k = np.floor(t)
        full = np.ceil(k / 2) if parity == 0 else np.floor(k / 2)
        return (full + np.where((k % 2 == parity) & (k < count), t - k, 0.0)) * square

    w = np.diff(edges)
    return ((covered(edges[1:], 1) - covered(edges[:-1], 1)) / w,
            (covered(edges[1:], 0) - covered(edges[:-1], 0)) / w)


def board_texture(spec, px_per_m: float) -> tuple[np.ndarray, float]:
    """The board's appearance as a float32 image: texel (row v, column u) covers board xy
    ``[u, u+1) x [v, v+1)`` divided by ``px_per_m``; returns (texture, px_per_m actually used).

    Each texel is the exact area average of the pattern over it (box-filtered): a square's edge that falls inside a
    texel gives it the grey of its dark share, so the edges (and the corners) sit where they are on the board, not
    moved to the nearest texel boundary (up to half a texel, the same shift for every corner of one grid line)."""
    b = BoardSpec.of(spec)
    n = int(np.ceil(b.size_m * px_per_m))
    ppm = n / b.size_m
    edges = np.arange(n + 1) / ppm
    ox, oy = b.pattern_origin
    odd_x, even_x = _parity_cover(edges, ox, b.square_m, b.squares_x)
    odd_y, even_y = _parity_cover(edges, oy, b.square_m, b.squares_y)
    dark = odd_y[:, None] * even_x[None, :] + even_y[:, None] * odd_x[None, :]   # (ix + iy) odd
    return (WHITE + (BLACK - WHITE) * dark).astype(np.float32), ppm


def render_board_image(K: np.ndarray, T_cam_board: np.ndarray, spec, width: int, height: int,
                       supersample: int = 4, texel_px: float = 0.5, texture=None) -> np.ndarray:
    """Grey uint8 image (height, width) of the board seen with pose ``T_cam_board`` on a uniform background.

    ``spec``: a BoardSpec or SimOptions. Rendered with ``cv2.warpPerspective`` of the board texture at
    ``supersample`` x the resolution, then averaged down (INTER_AREA); texels are at most ``texel_px``
    supersampled pixels wide. Pixel-centre conventions are matched exactly: texel u has its centre at board
    x = (u + 0.5)/ppm, and supersampled pixel xs at image x = (xs + 0.5)/s - 0.5, so the rendered corners
    sit where ``project`` puts them. The board must lie in front of the camera. ``texture``: a function of the
    texels per metre needed returning (texture, texels per metre) of another pattern (``simulate.patterns``).
    """
    b = BoardSpec.of(spec)
    s = int(supersample)
    H = board_homography(K, T_cam_board)
    # the finest texture the board needs: the largest pixel-per-metre scale over its outline (x supersample)
    corners = np.column_stack([b.outline(), np.ones(4)]) @ H.T
    if np.any(corners[:, 2] <= 0):
        raise CameraError("render_board_image: board not in front of the camera")
    f = max(K[0, 0], K[1, 1])
    ppm_needed = f * s / np.min(corners[:, 2]) / texel_px
    tex, ppm = (texture or (lambda q: board_texture(b, q)))(min(ppm_needed, 20000.0))
    A = np.array([[1.0 / ppm, 0.0, 0.5 / ppm], [0.0, 1.0 / ppm, 0.5 / ppm], [0.0, 0.0, 1.0]])  # texel -> board
    S = np.array([[s, 0.0, (s - 1) / 2.0], [0.0, s, (s - 1) / 2.0], [0.0, 0.0, 1.0]])        # image -> supersampled
    M = S @ H @ A
    big = cv2.warpPerspective(tex, M, (width * s, height * s), flags=cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_CONSTANT, borderValue=BACKGROUND)
    img = cv2.resize(big, (width, height), interpolation=cv2.INTER_AREA) if s > 1 else big
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def detect_corners(image: np.ndarray, spec) -> np.ndarray | None:
    """Inner corners (N,2) in pixels found by ``cv2.findChessboardCornersSB``, in ``checkerboard_corners``
    order, or None when the board is not found."""
    b = BoardSpec.of(spec)
    found, pts = cv2.findChessboardCornersSB(image, b.pattern_size, flags=cv2.CALIB_CB_ACCURACY)
    if not found:
        return None
    return pts.reshape(-1, 2).astype(float)


def pose_from_corners(K: np.ndarray, corners_board: np.ndarray, corners_px: np.ndarray, dist=None) -> np.ndarray:
    """``T_cam_board`` (4x4) from board-frame points (N,3) on z = 0 and their pixels (N,2): solvePnP IPPE with
    camera matrix ``K`` and OpenCV distortion ``dist`` (None: none)."""
    d = None if dist is None else np.asarray(dist, np.float64)
    ok, rvec, tvec = cv2.solvePnP(np.asarray(corners_board, np.float64), np.asarray(corners_px, np.float64),
                                  np.asarray(K, np.float64), d, flags=cv2.SOLVEPNP_IPPE)
    if not ok:
        raise CameraError("solvePnP (IPPE) failed")
    return make_T(cv2.Rodrigues(rvec)[0], tvec.ravel())


def observe_board_pose(K: np.ndarray, T_cam_board: np.ndarray, spec, mode: str, width: int, height: int,
                       rng: np.random.Generator, pixel_noise_px: float = 0.0, image_noise_std: float = 0.0,
                       supersample: int = 4) -> np.ndarray:
    """The camera's estimate of ``T_cam_board`` (4x4) under ``mode`` (``observe_board`` without the corners)."""
    return observe_board(K, T_cam_board, spec, mode, width, height, rng, pixel_noise_px, image_noise_std,
                         supersample)[0]


def observe_board(K: np.ndarray, T_cam_board: np.ndarray, spec, mode: str, width: int, height: int,
                  rng: np.random.Generator, pixel_noise_px: float = 0.0, image_noise_std: float = 0.0,
                  supersample: int = 4) -> tuple[np.ndarray, np.ndarray | None]:
    """The camera's estimate of ``T_cam_board`` (4x4) under ``mode`` and the image corners (N,2) it came from
    (in ``checkerboard_corners`` order; None in ``exact`` mode):

    ``exact``: the true pose; ``pixel``: true inner corners + N(0, ``pixel_noise_px``) per coordinate, then
    IPPE; ``image``: render, add N(0, ``image_noise_std``) grey-level noise, detect, IPPE.
    Raises CameraError when the checkerboard is not detected.
    """
    T_cam_board = np.asarray(T_cam_board, float)
    if mode == "exact":
        return T_cam_board.copy(), None
    P = checkerboard_corners(spec)
    if mode == "pixel":
        uv = project(K, T_cam_board, P) + rng.normal(0.0, pixel_noise_px, (len(P), 2))
    elif mode == "image":
        img = render_board_image(K, T_cam_board, spec, width, height, supersample)
        if image_noise_std > 0:
            img = np.clip(np.rint(img + rng.normal(0.0, image_noise_std, img.shape)), 0, 255).astype(np.uint8)
        uv = detect_corners(img, spec)
        if uv is None:
            raise CameraError("checkerboard not detected in the rendered image")
    else:
        raise ValueError(f"unknown pose mode {mode!r} (exact|pixel|image)")
    return pose_from_corners(K, P, uv), uv
