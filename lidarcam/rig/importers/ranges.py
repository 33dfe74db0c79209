"""Range-only scan logs: one scan per file, one range per line (e.g. the Hokuyo logs of Pless & Zhang's
camera-laser toolbox: 721 integer millimetres over 0-180 deg). Beam ``i`` (0-based) has bearing
``start + i * step`` counter-clockwise from the lidar x axis; a range of 0 (or inf, nan, negative) is no return.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..dataset import DatasetError, Scan, make_scan
from .radlocc import data_lines

UNITS_M = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
"""Range units accepted, in metres."""


def read_range_log(path, start_rad: float, step_rad: float, unit: str = "mm") -> Scan:
    """The scan of one range log; DatasetError naming the file and line when a line is not one number."""
    path = Path(path)
    if unit not in UNITS_M:
        raise DatasetError(f"range unit {unit!r} is not one of {', '.join(UNITS_M)}", file=path)
    if not (math.isfinite(step_rad) and step_rad != 0):
        raise DatasetError(f"bearing step {step_rad!r} must be a non-zero number", file=path)
    values = []
    for k, s in data_lines(path):
        try:
            values.append(float(s))
        except ValueError:
            raise DatasetError(f"not one range: {s[:40]!r}", file=path, line=k) from None
    if len(values) < 2:
        raise DatasetError(f"{len(values)} ranges, fewer than 2", file=path)
    r = np.asarray(values) * UNITS_M[unit]
    return make_scan(bearing=start_rad + step_rad * np.arange(len(r)), rng=r)
