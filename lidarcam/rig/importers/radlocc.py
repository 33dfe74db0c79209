"""RADLOCC laser text and RADLOCC results.

The laser log has one scan per line::

    timestamp StartAngleRad AngleIncrementRad EndAngleRad RangeUnitType N r_1 r_2 ... r_N

separated by spaces and/or commas (``2.47, 2.48, inf``). ``inf`` / ``nan`` / ``0`` / a non-positive range is no
return. ``RangeUnitType`` gives the unit of the ranges: 1 mm, 2 cm, 3 m (RADLOCC's own convention). Bearings
are ``StartAngle + i * AngleIncrement`` counter-clockwise from the lidar x axis (a negative increment is a
clockwise sweep). Lines whose header does not parse are errors unless the caller restricts ``lines``.

RADLOCC writes laser points as ``[y; 0; x]`` and its result as ``Lpts = PHI (Cpts - DELTA)`` (DELTA in mm, the
camera-frame position of the lidar origin). ``T_lidar_cam_from_radlocc`` converts that to the project's
``T_lidar_cam`` for lidar points ``[x, y, 0]``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..dataset import DatasetError, Scan, make_scan

UNIT_TO_M = {1: 1e-3, 2: 1e-2, 3: 1.0}
_SPLIT = re.compile(r"[,\s]+")
# RADLOCC laser point [y; 0; x] from the project's lidar point [x, y, z] (a proper rotation: z -> the middle row)
RADLOCC_FROM_LIDAR = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])


@dataclass(frozen=True, eq=False)
class RadloccScan:
    """One line of a RADLOCC laser log: ``line`` (1-based), ``timestamp`` (as written), ``scan``."""

    line: int
    timestamp: float
    scan: Scan


def parse_radlocc_line(text: str, path, line: int) -> RadloccScan:
    """One laser line -> RadloccScan; DatasetError naming the file, line and field when it does not parse."""
    tok = [t for t in _SPLIT.split(text.strip()) if t]
    names = ("timestamp", "StartAngleRad", "AngleIncrementRad", "EndAngleRad", "RangeUnitType", "N")
    if len(tok) < len(names):
        raise DatasetError(f"RADLOCC header needs {len(names)} fields ({' '.join(names)}), got {len(tok)}",
                           file=path, line=line)
    head = []
    for name, t in zip(names, tok, strict=False):
        try:
            head.append(float(t))
        except ValueError:
            raise DatasetError(f"field {name}: not a number: {t!r}", file=path, line=line) from None
    stamp, start, inc, end, unit, n = head
    if unit not in UNIT_TO_M:
        raise DatasetError(f"field RangeUnitType: {tok[4]!r} is not 1 (mm), 2 (cm) or 3 (m)", file=path, line=line)
    if n != int(n) or n < 1:
        raise DatasetError(f"field N: {tok[5]!r} is not a positive integer", file=path, line=line)
    n = int(n)
    ranges = tok[len(names):]
    if len(ranges) != n:
        raise DatasetError(f"field N says {n} ranges, the line holds {len(ranges)}", file=path, line=line)
    if not (math.isfinite(inc) and inc != 0):
        raise DatasetError(f"field AngleIncrementRad: {tok[2]!r} must be a non-zero number", file=path, line=line)
    if abs(start + (n - 1) * inc - end) > 1.5 * abs(inc):  # ROS drivers are often one beam off
        raise DatasetError(f"field EndAngleRad: {end} but StartAngleRad + (N-1) * AngleIncrementRad = "
                           f"{start + (n - 1) * inc:.6f}", file=path, line=line)
    try:
        r = np.array(ranges, dtype=float) * UNIT_TO_M[int(unit)]
    except ValueError:
        bad = next(t for t in ranges if not _is_number(t))
        raise DatasetError(f"range {ranges.index(bad) + 1}: not a number: {bad!r}", file=path, line=line) from None
    return RadloccScan(line, stamp, make_scan(bearing=start + inc * np.arange(n), rng=r))


def _is_number(t: str) -> bool:
    try:
        float(t)
    except ValueError:
        return False
    return True


def data_lines(path: Path) -> list[tuple[int, str]]:
    """(1-based line number, text) of the non-empty lines of a text file that are not ``#`` comments; DatasetError
    naming the file when it cannot be read as text."""
    try:
        text = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"cannot read as text ({exc})", file=path) from None
    return [(k, s) for k, s in enumerate(text, start=1) if s.strip() and not s.lstrip().startswith("#")]


def read_radlocc_laser(path, lines: range | None = None) -> list[RadloccScan]:
    """The scans of a RADLOCC laser log, one per non-empty line (``lines``: 1-based line numbers to read, e.g.
    ``range(1, 62)`` to ignore trailing lines of another format)."""
    path = Path(path)
    out = []
    for k, s in data_lines(path):
        if lines is not None and k not in lines:
            continue
        out.append(parse_radlocc_line(s, path, k))
    if not out:
        raise DatasetError("no laser lines", file=path)
    return out


def T_lidar_cam_from_radlocc(PHI, DELTA_mm) -> np.ndarray:
    """RADLOCC's ``Lpts = PHI (Cpts - DELTA)`` (laser points written ``[y; 0; x]``, DELTA in mm) -> ``T_lidar_cam``
    (4x4, metres) for lidar points ``[x, y, 0]``. PHI is projected onto SO(3) (results are often printed to
    four decimals)."""
    from scipy.spatial.transform import Rotation

    PHI = np.asarray(PHI, float).reshape(3, 3)
    R_rad_cam = Rotation.from_matrix(PHI).as_matrix()  # nearest rotation (orthonormalises)
    R = RADLOCC_FROM_LIDAR.T @ R_rad_cam  # lidar <- radlocc <- camera
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = -R @ (np.asarray(DELTA_mm, float).ravel() / 1000.0)
    return T
