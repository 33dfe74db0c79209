"""The identified boards the simulator renders: OpenCV's ChArUco board and Kalibr's AprilGrid (tag36h11 with a 2-bit
black border, a black square at every gap crossing), centred on the simulator's square board of side ``size_m``.

``Pattern`` holds a board's layout; ``pattern_texture`` its appearance as a texture for
``simulate.lens_render.render_board_lens``: every black rectangle (a square, a run of a marker's black cells) is
rasterised by its exact area over each texel, so the corners sit where ``Pattern.corners`` puts them (no rounding to
texels). Layout (which squares carry which marker) comes from ``cv2.aruco`` (``CharucoBoard``,
``generateImageMarker``). Frames: the pattern's own board frame (``calib_core.geometry.patterns``: x right, y down as
printed) sits at ``offset(size_m)`` in the simulator's board frame (outline ``[0, size_m]^2``); metres.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from calib_core.geometry.patterns import aprilgrid_corners, aprilgrid_extent, charuco_corners

from .camera import BLACK, WHITE

PATTERN_KINDS = ("charuco", "aprilgrid")
PATTERN_MAX_PPM = 4096.0
"""Finest texture of a pattern, texels per metre (a 1 m board: 16 M texels); nearer boards are rendered from it."""


@dataclass(frozen=True)
class Pattern:
    """An identified board's layout.

    Attributes:
        kind: ``charuco`` or ``aprilgrid``.
        cols, rows: squares (charuco: ``squares_x``, ``squares_y``) or tags (aprilgrid: ``tagCols``, ``tagRows``).
        square: square side (charuco) or tag side (aprilgrid), metres.
        marker: charuco marker side (m).
        spacing_ratio: aprilgrid gap as a fraction of the tag side (Kalibr's ``tagSpacing``).
        dictionary: charuco's OpenCV predefined dictionary name.
        legacy: charuco's pattern before OpenCV 4.6.0.
    """

    kind: str = "charuco"
    cols: int = 7
    rows: int = 5
    square: float = 0.12
    marker: float = 0.09
    spacing_ratio: float = 0.3
    dictionary: str = "DICT_5X5_100"
    legacy: bool = False

    def __post_init__(self) -> None:
        if self.kind not in PATTERN_KINDS:
            raise ValueError(f"Pattern: kind must be one of {', '.join(PATTERN_KINDS)}, got {self.kind!r}")

    @property
    def spacing(self) -> float:
        """AprilGrid gap between tags (m)."""
        return self.spacing_ratio * self.square

    def extent(self) -> np.ndarray:
        """(4,2) rectangle of the printed pattern in its board frame (m)."""
        if self.kind == "charuco":
            w, h = self.cols * self.square, self.rows * self.square
            return np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]])
        return aprilgrid_extent(self.cols, self.rows, self.square, self.spacing)

    def corners(self) -> np.ndarray:
        """(N,3) corners in the pattern's board frame, by identity (``calib_core.geometry.patterns``)."""
        if self.kind == "charuco":
            return charuco_corners(self.cols, self.rows, self.square)
        return aprilgrid_corners(self.cols, self.rows, self.square, self.spacing)

    def offset(self, size_m: float) -> np.ndarray:
        """Where the pattern's board frame origin lies on the simulator's board of side ``size_m`` (pattern centred);
        ValueError when the pattern does not fit."""
        e = self.extent()
        span = e.max(axis=0) - e.min(axis=0)
        if np.any(span > size_m + 1e-12):
            raise ValueError(f"Pattern: a {span[0]:.3f} x {span[1]:.3f} m pattern does not fit on a {size_m} m board")
        return (size_m - span) / 2.0 - e.min(axis=0)

    def board_yaml(self, outline_m: np.ndarray | None = None) -> str:
        """board.yaml text of the pattern (ChArUco's form, or Kalibr's AprilGrid target YAML), with ``outline_m``
        (pattern frame) when given."""
        if self.kind == "charuco":
            text = ("# ChArUco board (OpenCV): squares, their side and the markers' side in metres\n"
                    f"type: charuco\nsquares_x: {self.cols}\nsquares_y: {self.rows}\nsquare_m: {self.square!r}\n"
                    f"marker_m: {self.marker!r}\ndictionary: {self.dictionary}\n"
                    + ("legacy_pattern: true\n" if self.legacy else ""))
        else:
            text = ("# Kalibr AprilGrid target (tag36h11): tags, tag side in metres, gap as a fraction of it\n"
                    f"target_type: 'aprilgrid'\ntagCols: {self.cols}\ntagRows: {self.rows}\n"
                    f"tagSize: {self.square!r}\ntagSpacing: {self.spacing_ratio!r}\n")
        if outline_m is not None:
            text += "# the board's outline in the board frame (metres)\noutline_m:\n" + "\n".join(
                f"  - [{float(x)!r}, {float(y)!r}]" for x, y in np.asarray(outline_m))
            text += "\n"
        return text

    def dark_rects(self) -> np.ndarray:
        """(M,4) black rectangles ``x0, y0, x1, y1`` of the printed pattern in its board frame (m)."""
        return _dark_rects(self)


def _runs(cells: np.ndarray) -> list[tuple[int, int, int]]:
    """Runs ``(row, c0, c1)`` of the True cells of each row of ``cells``."""
    out = []
    for r, row in enumerate(cells):
        d = np.diff(np.concatenate([[0], row.astype(np.int8), [0]]))
        out += [(r, int(a), int(b)) for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True)]
    return out


def _marker_rects(dictionary, marker_id: int, border_bits: int, x0: float, y0: float, side: float) -> list:
    """The black rectangles of one marker whose outer corner is ``(x0, y0)``, side ``side`` metres."""
    n = dictionary.markerSize + 2 * border_bits
    cells = cv2.aruco.generateImageMarker(dictionary, int(marker_id), n, borderBits=border_bits) < 128
    c = side / n
    return [(x0 + a * c, y0 + r * c, x0 + b * c, y0 + (r + 1) * c) for r, a, b in _runs(cells)]


@lru_cache(maxsize=8)
def _dark_rects(p: Pattern) -> np.ndarray:
    rects = []
    if p.kind == "charuco":
        d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, p.dictionary))
        board = cv2.aruco.CharucoBoard((p.cols, p.rows), p.square, p.marker, d)
        board.setLegacyPattern(p.legacy)
        white = set()
        for mid, q in zip(board.getIds().ravel(), board.getObjPoints(), strict=True):
            q = np.asarray(q).reshape(4, 3)
            lo = q[:, :2].min(axis=0)
            centre = q[:, :2].mean(axis=0)
            white.add((int(centre[0] // p.square), int(centre[1] // p.square)))
            rects += _marker_rects(d, int(mid), 1, lo[0], lo[1], p.marker)
        rects += [(i * p.square, j * p.square, (i + 1) * p.square, (j + 1) * p.square)
                  for j in range(p.rows) for i in range(p.cols) if (i, j) not in white]
    else:
        d = cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_APRILTAG_36h11)
        tl = aprilgrid_corners(p.cols, p.rows, p.square, p.spacing)[::4]
        for mid, (x0, y0, _) in enumerate(tl):
            rects += _marker_rects(d, mid, 2, x0, y0, p.square)
        pitch, s = p.square + p.spacing, p.spacing
        rects += [(i * pitch - s, j * pitch - s, i * pitch, j * pitch)
                  for j in range(p.rows + 1) for i in range(p.cols + 1)]
    out = np.array(rects, float)
    out.setflags(write=False)
    return out


def _cover(lo: float, hi: float, ppm: float) -> tuple[int, np.ndarray]:
    """First texel and the share (0..1) of each texel from it covered by ``[lo, hi)`` (metres) at ``ppm``."""
    a, b = lo * ppm, hi * ppm
    i0, i1 = int(np.floor(a)), int(np.ceil(b))
    u = np.arange(i0, i1)
    return i0, np.clip(np.minimum(b, u + 1) - np.maximum(a, u), 0.0, 1.0)


@lru_cache(maxsize=4)
def pattern_texture(pattern: Pattern, size_m: float, ppm: float) -> tuple[np.ndarray, float]:
    """(texture float32, texels per metre) of the simulator's board of side ``size_m`` carrying ``pattern``
    (centred): texel (v, u) covers board xy ``[u, u+1) x [v, v+1)`` / ppm, grey ``WHITE`` with each black
    rectangle's exact area share of ``BLACK``."""
    n = int(np.ceil(size_m * ppm))
    ppm = n / size_m
    dark = np.zeros((n, n), np.float32)
    off = pattern.offset(size_m)
    for x0, y0, x1, y1 in pattern.dark_rects() + np.r_[off, off]:
        u0, cx = _cover(x0, x1, ppm)
        v0, cy = _cover(y0, y1, ppm)
        if u0 < 0 or v0 < 0 or u0 + len(cx) > n or v0 + len(cy) > n:
            raise ValueError("pattern_texture: the pattern leaves the board")
        dark[v0:v0 + len(cy), u0:u0 + len(cx)] += np.outer(cy, cx).astype(np.float32)
    np.clip(dark, 0.0, 1.0, out=dark)
    tex = (WHITE + (BLACK - WHITE) * dark).astype(np.float32)
    tex.setflags(write=False)
    return tex, ppm


def texture_source(pattern: Pattern, size_m: float):
    """``texture(ppm) -> (texture, ppm)`` for the renderers (``simulate.camera.render_board_image``'s ``texture``):
    ``pattern_texture`` at the power of 2 at or above ``ppm`` (at most ``PATTERN_MAX_PPM``), so that a few textures
    serve a whole dataset (cached)."""
    def texture(ppm: float):
        level = 2.0 ** np.ceil(np.log2(max(ppm, 128.0)))
        return pattern_texture(pattern, size_m, float(min(level, PATTERN_MAX_PPM)))

    return texture
