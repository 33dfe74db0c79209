"""Which way a lidar counts its bearings: ``lidar.yaml``'s optional ``scan_direction`` (docs/dataset.md).

The project's lidar frame is right-handed with z up, so bearings grow counter-clockwise seen from above (``ccw``,
ROS's REP 103). A lidar whose driver counts them clockwise (``cw``) writes every scan mirrored; its scans are read
with each bearing negated (``y -> -y``), and so are ``background.csv`` and the windows of ``windows.yaml`` (their
bearings are the scan files', as the sensor counts them). A 2D scan cannot tell a mirrored scan from a lidar mounted
upside down: the direction is declared, never guessed.
"""

from __future__ import annotations

from pathlib import Path

from ..extract_options import SCAN_DIRECTIONS
from .model import DatasetError, Scan
from .scans import make_scan
from .yaml_files import read_yaml

SCAN_DIRECTION_NAMES = {"ccw": "counter-clockwise", "cw": "clockwise"}
__all__ = ["SCAN_DIRECTIONS", "SCAN_DIRECTION_NAMES", "check_scan_direction", "lidar_yaml", "load_lidar",
           "mirror_scan", "mirror_window"]


def check_scan_direction(value, file=None) -> str:
    """``value`` as ``ccw`` or ``cw`` (also ``counterclockwise`` / ``clockwise``, any case); DatasetError naming
    the file and field otherwise."""
    text = str(value).strip().lower().replace("-", "").replace("_", "").replace(" ", "")
    aliases = {"ccw": "ccw", "counterclockwise": "ccw", "anticlockwise": "ccw", "cw": "cw", "clockwise": "cw"}
    if isinstance(value, bool) or text not in aliases:
        raise DatasetError(f"'scan_direction' must be cw or ccw, got {value!r}", file=file)
    return aliases[text]


def load_lidar(path) -> dict:
    """lidar.yaml as ``{"scan_direction": "cw" | "ccw"}`` (the key optional: absent, nothing is declared)."""
    path = Path(path)
    data = read_yaml(path)
    unknown = sorted(set(data) - {"scan_direction"})
    if unknown:
        raise DatasetError(f"unknown keys {unknown} (lidar.yaml knows scan_direction)", file=path)
    return {"scan_direction": check_scan_direction(data["scan_direction"], path)} if "scan_direction" in data else {}


def lidar_yaml(direction: str, why: str = "") -> str:
    """lidar.yaml text declaring ``direction`` (``why``: a comment saying where the declaration comes from)."""
    direction = check_scan_direction(direction)
    head = f"# {why}\n" if why else ""
    return f"{head}scan_direction: {direction}  # {SCAN_DIRECTION_NAMES[direction]}\n"


def mirror_scan(scan: Scan) -> Scan:
    """The scan with every bearing negated (``y -> -y``), ordered along the sweep again; ``n_dropped`` kept."""
    s = make_scan(bearing=-scan.bearing, rng=scan.range)
    return Scan(s.bearing, s.range, s.points, scan.n_dropped)


def mirror_window(window: tuple[float, float]) -> tuple[float, float]:
    """A bearing window (radians) of a mirrored scan."""
    return -window[1], -window[0]
