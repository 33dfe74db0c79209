"""board.yaml in its three forms, recognised by their keys (docs/dataset.md):

- the project's checkerboard: ``cols``, ``rows`` (inner corners), ``square_m``, optional ``outline_m`` and
  ``origin_square`` (``type: checkerboard`` may be stated);
- a Kalibr target YAML: ``target_type: 'aprilgrid'`` (``tagCols``, ``tagRows``, ``tagSize``, ``tagSpacing``: the gap
  as a fraction of ``tagSize``) or ``target_type: 'checkerboard'`` (``targetCols``, ``targetRows`` inner corners,
  ``rowSpacingMeters``, ``colSpacingMeters``);
- ChArUco: ``type: charuco``, ``squares_x``, ``squares_y``, ``square_m``, ``marker_m``, ``dictionary`` (an OpenCV
  predefined name such as ``DICT_5X5_100``), optional ``legacy_pattern``.

Every form takes the optional ``outline_m`` (the physical board's outline in the board frame, metres); without it
the pattern's extent is the outline (a lower bound of the board). A key a form does not know, a missing key or a bad
value is a ``DatasetError`` naming the file and the key. Board frames: ``lidarcam.rig.dataset.model.BoardSpec``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from calib_core.geometry.polygon import check_simple_polygon

from .model import BOARD_KINDS, BoardSpec, DatasetError
from .yaml_files import matrix_field, read_yaml

APRILGRID_DICTIONARY = "DICT_APRILTAG_36h11"
"""The OpenCV dictionary of Kalibr's AprilGrid tags (tag36h11, 587 codes)."""
APRILGRID_BORDER_BITS = 2
"""Black border of Kalibr's printed tags, in code bits (OpenCV's ``markerBorderBits``; AprilTag's own is 1)."""

FORMS = {
    "checkerboard": ("the project's checkerboard", {"cols", "rows", "square_m"},
                     {"type", "outline_m", "origin_square"}),
    "kalibr-aprilgrid": ("a Kalibr AprilGrid target", {"target_type", "tagCols", "tagRows", "tagSize", "tagSpacing"},
                         {"outline_m"}),
    "kalibr-checkerboard": ("a Kalibr checkerboard target", {"target_type", "targetCols", "targetRows",
                                                             "rowSpacingMeters", "colSpacingMeters"},
                            {"outline_m", "origin_square"}),
    "charuco": ("a ChArUco board", {"type", "squares_x", "squares_y", "square_m", "marker_m", "dictionary"},
                {"outline_m", "legacy_pattern"}),
}
"""Each board.yaml form: (what it is in words, required keys, optional keys)."""
FORM_SELECTORS = {"checkerboard": "", "kalibr-aprilgrid": "target_type: aprilgrid",
                  "kalibr-checkerboard": "target_type: checkerboard", "charuco": "type: charuco"}
"""The key and value that select each form (the checkerboard: none, or ``type: checkerboard``)."""


def load_board(path) -> BoardSpec:
    """Read board.yaml in any of its forms (module docstring) as a BoardSpec."""
    path = Path(path)
    return board_from_dict(read_yaml(path), path)


def board_form(data: dict, path: Path) -> str:
    """Which form of ``FORMS`` the keys of ``data`` are; DatasetError naming the file otherwise."""
    if "target_type" in data:
        t = str(data["target_type"]).strip().lower()
        if t not in ("aprilgrid", "checkerboard"):
            raise DatasetError(f"'target_type' must be aprilgrid or checkerboard (Kalibr's targets), got "
                               f"{data['target_type']!r}", file=path)
        return f"kalibr-{t}"
    kind = str(data.get("type", "checkerboard")).strip().lower()
    if kind not in ("checkerboard", "charuco"):
        raise DatasetError(f"'type' must be checkerboard or charuco (an AprilGrid is Kalibr's target_type: aprilgrid),"
                           f" got {data['type']!r}", file=path)
    return kind


def _check_keys(data: dict, form: str, path: Path) -> None:
    what, need, optional = FORMS[form]
    known = need | optional
    for key in data:
        if key not in known:
            raise DatasetError(f"unknown key {key!r} for {what} (its keys: {', '.join(sorted(known, key=str.lower))})",
                               file=path)
    for key in sorted(need):
        if key not in data:
            raise DatasetError(f"missing key {key!r} for {what}", file=path)


def _int(data: dict, key: str, path: Path, least: int) -> int:
    v = data[key]
    if isinstance(v, bool) or not isinstance(v, int) or v < least:
        raise DatasetError(f"{key!r} must be an integer >= {least}, got {v!r}", file=path)
    return v


def _length(data: dict, key: str, path: Path) -> float:
    v = data[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
        raise DatasetError(f"{key!r} must be a positive number (metres), got {v!r}", file=path)
    return float(v)


def _origin_colour(data: dict, path: Path) -> bool | None:
    colour = data.get("origin_square")
    if colour is not None and str(colour).lower() not in ("dark", "light", "black", "white"):
        raise DatasetError(f"'origin_square' must be dark or light, got {colour!r}", file=path)
    return None if colour is None else str(colour).lower() in ("dark", "black")


def _dictionary(name, n_markers: int, path: Path) -> str:
    """``name`` checked as an OpenCV predefined dictionary holding at least ``n_markers`` markers."""
    import cv2

    value = getattr(cv2.aruco, str(name), None) if str(name).startswith("DICT_") else None
    if not isinstance(value, int):
        known = sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_"))
        raise DatasetError(f"'dictionary' {name!r} is not an OpenCV predefined dictionary (e.g. "
                           f"{', '.join(known[:4])}, ...)", file=path)
    size = len(cv2.aruco.getPredefinedDictionary(value).bytesList)
    if size < n_markers:
        raise DatasetError(f"'dictionary' {name} holds {size} markers, the board needs {n_markers}", file=path)
    return str(name)


def board_from_dict(data: dict, path: Path) -> BoardSpec:
    """A BoardSpec from board.yaml's keys (already parsed) in any form; errors name ``path`` and the key."""
    form = board_form(data, path)
    _check_keys(data, form, path)
    if form == "checkerboard":
        spec = BoardSpec(_int(data, "cols", path, 2), _int(data, "rows", path, 2), _length(data, "square_m", path),
                         np.zeros((0, 2)), _origin_colour(data, path))
    elif form == "kalibr-checkerboard":
        sx, sy = _length(data, "colSpacingMeters", path), _length(data, "rowSpacingMeters", path)
        spec = BoardSpec(_int(data, "targetCols", path, 2), _int(data, "targetRows", path, 2), sx, np.zeros((0, 2)),
                         _origin_colour(data, path), square_y=None if sy == sx else sy, source="kalibr")
    elif form == "kalibr-aprilgrid":
        cols, rows = _int(data, "tagCols", path, 1), _int(data, "tagRows", path, 1)
        size, ratio = _length(data, "tagSize", path), _length(data, "tagSpacing", path)
        if cols * rows < 2:
            raise DatasetError(f"an AprilGrid needs at least 2 tags, got {cols}x{rows}", file=path)
        spec = BoardSpec(cols, rows, size, np.zeros((0, 2)), kind="aprilgrid", spacing=ratio * size,
                         dictionary=_dictionary(APRILGRID_DICTIONARY, cols * rows, path), source="kalibr")
    else:
        nx, ny = _int(data, "squares_x", path, 2), _int(data, "squares_y", path, 2)
        square, marker = _length(data, "square_m", path), _length(data, "marker_m", path)
        if marker >= square:
            raise DatasetError(f"'marker_m' ({marker:g}) must be smaller than 'square_m' ({square:g})", file=path)
        legacy = data.get("legacy_pattern", False)
        if not isinstance(legacy, bool):
            raise DatasetError(f"'legacy_pattern' must be true or false, got {legacy!r}", file=path)
        spec = BoardSpec(nx - 1, ny - 1, square, np.zeros((0, 2)), kind="charuco", marker=marker,
                         dictionary=_dictionary(data["dictionary"], (nx * ny) // 2, path), legacy_pattern=legacy,
                         source="charuco")
    assert spec.kind in BOARD_KINDS
    outline = matrix_field(data["outline_m"], "outline_m", path, (None, 2)) if "outline_m" in data \
        else spec.pattern_extent
    why = check_simple_polygon(outline)
    if why:
        raise DatasetError(f"'outline_m' {why}", file=path)
    outline.setflags(write=False)
    from dataclasses import replace

    return replace(spec, outline=outline)
