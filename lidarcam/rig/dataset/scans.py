"""Lidar scans of a dataset: a ``Scan`` from bearings and ranges or points, per-pose CSV files and the keyed
``scans.csv``; a row that does not parse raises DatasetError naming the file and line."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .model import DatasetError, Scan


def make_scan(bearing=None, rng=None, points=None) -> Scan:
    """A Scan from bearings + ranges or from x, y points; drops no-return beams and orders along the sweep."""
    if points is not None:
        points = np.asarray(points, float).reshape(-1, 2)
        rng = np.hypot(points[:, 0], points[:, 1])
        bearing = np.arctan2(points[:, 1], points[:, 0])
    bearing = np.asarray(bearing, float).ravel()
    rng = np.asarray(rng, float).ravel()
    good = np.isfinite(rng) & np.isfinite(bearing) & (rng > 0)
    bearing, rng = np.arctan2(np.sin(bearing[good]), np.cos(bearing[good])), rng[good]
    order = np.argsort(bearing, kind="stable")
    bearing, rng = bearing[order], rng[order]
    if len(bearing) > 1:  # start after the largest angular gap, so a 360-degree sweep stays contiguous
        gaps = np.diff(np.concatenate([bearing, bearing[:1] + 2 * np.pi]))
        start = (int(np.argmax(gaps)) + 1) % len(bearing)
        bearing, rng = np.roll(bearing, -start), np.roll(rng, -start)
    pts = np.column_stack([rng * np.cos(bearing), rng * np.sin(bearing)])
    for a in (bearing, rng, pts):
        a.setflags(write=False)
    return Scan(bearing, rng, pts, int((~good).sum()))


_COLUMN_SETS = (("bearing_rad", "range_m"), ("x", "y"))


def _scan_columns(header: list[str], path: Path, keyed: bool) -> tuple[dict[str, int], tuple[str, str]]:
    names = [h.strip().lower() for h in header]
    idx = {n: i for i, n in enumerate(names)}
    for cols in _COLUMN_SETS:
        if all(c in idx for c in cols) and (not keyed or "pose" in idx):
            return idx, cols
    want = " or ".join(",".join((("pose",) if keyed else ()) + c) for c in _COLUMN_SETS)
    raise DatasetError(f"header must name the columns {want}; got {','.join(header)!r}", file=path, line=1)


def _parse_row(row: list[str], idx: dict[str, int], cols: tuple[str, str], path: Path, line: int,
               pose: str | None) -> tuple[float, float]:
    if len(row) != len(idx):
        raise DatasetError(f"expected {len(idx)} fields, got {len(row)}: {','.join(row)!r}", file=path, line=line,
                           pose=pose)
    try:
        a, b = float(row[idx[cols[0]]]), float(row[idx[cols[1]]])
    except ValueError:
        raise DatasetError(f"not a number in {','.join(row)!r}", file=path, line=line, pose=pose) from None
    return a, b


def _to_scan(values: list[tuple[float, float]], cols: tuple[str, str]) -> Scan:
    v = np.asarray(values, float).reshape(-1, 2)
    if cols == ("x", "y"):
        ok = np.all(np.isfinite(v), axis=1) & (np.hypot(v[:, 0], v[:, 1]) > 0)
        s = make_scan(points=v[ok])
        return Scan(s.bearing, s.range, s.points, int((~ok).sum()))
    return make_scan(bearing=v[:, 0], rng=v[:, 1])


def csv_rows(path: Path) -> list[tuple[int, list[str]]]:
    """The (1-based line number, fields) of a CSV file's rows, blank and ``#`` comment lines left out;
    DatasetError naming the file when it cannot be read as text."""
    try:
        with path.open(newline="") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise DatasetError(f"cannot read ({exc.strerror})", file=path) from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise DatasetError(f"not a text CSV file ({exc})", file=path) from None
    return [(n, r) for n, r in enumerate(rows, start=1) if r and not r[0].lstrip().startswith("#")]


def read_scan_csv(path, pose: str | None = None) -> Scan:
    """One scan from a CSV with header ``bearing_rad,range_m`` or ``x,y`` (extra columns allowed, e.g. intensity).

    Empty lines and lines starting with ``#`` are skipped. ``nan``/``inf``/``0`` ranges are no-returns (dropped);
    a row that does not parse raises DatasetError naming the file and line.
    """
    path = Path(path)
    rows = csv_rows(path)
    if not rows:
        raise DatasetError("empty file (needs a header and one row per beam)", file=path, pose=pose)
    (_, header), body = rows[0], rows[1:]
    idx, cols = _scan_columns(header, path, keyed=False)
    values = [_parse_row(r, idx, cols, path, n, pose) for n, r in body]
    if not values:
        raise DatasetError("no beams after the header", file=path, pose=pose)
    return _to_scan(values, cols)


def same_pose(a: str, b: str) -> bool:
    """Two pose names of one pose: equal, or both digits of one number (``3`` and ``003``)."""
    return a == b or (a.isdigit() and b.isdigit() and int(a) == int(b))


def read_keyed_scans(path) -> tuple[dict[str, Scan], dict[str, DatasetError]]:
    """``scans.csv``: scans keyed by a ``pose`` column. Returns (scans by pose, errors by pose); a bad row
    spoils only its own pose."""
    path = Path(path)
    rows = csv_rows(path)
    if not rows:
        raise DatasetError("empty file", file=path)
    (_, header), body = rows[0], rows[1:]
    idx, cols = _scan_columns(header, path, keyed=True)
    values: dict[str, list] = {}
    errors: dict[str, DatasetError] = {}
    for n, r in body:
        pose = r[idx["pose"]].strip() if len(r) > idx["pose"] else None
        if not pose:
            raise DatasetError("row without a pose", file=path, line=n)
        try:
            values.setdefault(pose, []).append(_parse_row(r, idx, cols, path, n, pose))
        except DatasetError as err:
            errors.setdefault(pose, err)
    scans = {p: _to_scan(v, cols) for p, v in values.items() if p not in errors}
    return scans, errors
