"""PCD point clouds (PCL's format, v0.5-0.7) holding one 2D lidar scan.

Header lines ``FIELDS``, ``SIZE``, ``TYPE``, ``COUNT``, ``WIDTH``, ``HEIGHT``, ``POINTS``, ``DATA`` (``ascii`` or
``binary``; ``binary_compressed`` is refused). The fields ``x`` and ``y`` (lidar frame, metres) are read; ``z``, when
present, must be near 0 (a 2D scan). A point at the origin or with a NaN coordinate is no return.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..dataset import DatasetError, Scan, make_scan

_HEADER_KEYS = ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA")
_DTYPES = {("F", 4): "<f4", ("F", 8): "<f8", ("I", 1): "<i1", ("I", 2): "<i2", ("I", 4): "<i4", ("I", 8): "<i8",
           ("U", 1): "<u1", ("U", 2): "<u2", ("U", 4): "<u4", ("U", 8): "<u8"}


def _header(raw: bytes, path: Path) -> tuple[dict[str, list[str]], int]:
    """Header keys -> tokens, and the byte offset where the data starts."""
    head: dict[str, list[str]] = {}
    pos = 0
    line_no = 0
    while pos < len(raw):
        end = raw.find(b"\n", pos)
        end = len(raw) if end < 0 else end
        line_no += 1
        text = raw[pos:end].decode("ascii", "replace").strip()
        pos = end + 1
        if not text or text.startswith("#"):
            continue
        key, *vals = text.split()
        if key.upper() not in _HEADER_KEYS:
            raise DatasetError(f"unknown PCD header key {key!r}", file=path, line=line_no)
        head[key.upper()] = vals
        if key.upper() == "DATA":
            return head, pos
    raise DatasetError("PCD header has no DATA line", file=path)


def read_pcd_points(path) -> dict[str, np.ndarray]:
    """Every field of a PCD file as a float array (fields with COUNT > 1 as (N, COUNT))."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DatasetError(f"cannot read ({exc.strerror})", file=path) from None
    head, start = _header(raw, path)
    for key in ("FIELDS", "DATA"):
        if not head.get(key):
            raise DatasetError(f"PCD header: missing {key}", file=path)
    fields = head["FIELDS"]
    counts = [int(c) for c in head.get("COUNT", ["1"] * len(fields))]
    try:
        n = int(head["POINTS"][0]) if "POINTS" in head else int(head["WIDTH"][0]) * int(head.get("HEIGHT", ["1"])[0])
    except (KeyError, ValueError, IndexError):
        raise DatasetError("PCD header: POINTS (or WIDTH x HEIGHT) is not an integer", file=path) from None
    if len(counts) != len(fields):
        raise DatasetError(f"PCD header: {len(fields)} FIELDS but {len(counts)} COUNT values", file=path)
    mode = head["DATA"][0].lower()
    if mode == "ascii":
        rows = [r.split() for r in raw[start:].decode("ascii", "replace").splitlines() if r.strip()]
        width = sum(counts)
        bad = next((k for k, r in enumerate(rows) if len(r) != width), None)
        if bad is not None:
            raise DatasetError(f"data row {bad + 1} has {len(rows[bad])} values, FIELDS/COUNT say {width}",
                               file=path)
        try:
            table = np.array(rows, dtype=float).reshape(-1, width)
        except ValueError:
            raise DatasetError("PCD data: a value is not a number", file=path) from None
    elif mode == "binary":
        sizes, types = head.get("SIZE", []), head.get("TYPE", [])
        try:
            dt = np.dtype([(f"f{k}", _DTYPES[(t.upper(), int(s))], (c,)) for k, (t, s, c)
                           in enumerate(zip(types, sizes, counts, strict=True))])
        except (KeyError, ValueError):
            raise DatasetError(f"PCD header: unsupported SIZE/TYPE {sizes}/{types}", file=path) from None
        if len(raw) - start < n * dt.itemsize:
            raise DatasetError(f"PCD data: {len(raw) - start} bytes, {n} points need {n * dt.itemsize}", file=path)
        rec = np.frombuffer(raw[start:start + n * dt.itemsize], dtype=dt)
        table = np.column_stack([rec[f"f{k}"].astype(float) for k in range(len(fields))])
    else:
        raise DatasetError(f"PCD DATA {mode!r} is not supported (ascii or binary)", file=path)
    if len(table) != n:
        raise DatasetError(f"PCD data: {len(table)} points, header says {n}", file=path)
    out, col = {}, 0
    for f, c in zip(fields, counts, strict=True):
        out[f] = table[:, col] if c == 1 else table[:, col:col + c]
        col += c
    return out


def read_pcd_scan(path, max_abs_z_m: float = 0.01) -> Scan:
    """A 2D scan from a PCD file (fields x, y, optional z near 0); origin / NaN points are no returns."""
    path = Path(path)
    f = read_pcd_points(path)
    for key in ("x", "y"):
        if key not in f:
            raise DatasetError(f"PCD has no field {key!r} (fields: {' '.join(f)})", file=path)
    xy = np.column_stack([f["x"], f["y"]])
    if "z" in f:
        z = f["z"][np.isfinite(f["z"])]
        if z.size and np.abs(z).max() > max_abs_z_m:
            raise DatasetError(f"field z: up to {np.abs(z).max():.3f} m, not a 2D scan (|z| <= {max_abs_z_m} m)",
                               file=path)
    ok = np.all(np.isfinite(xy), axis=1) & (np.hypot(xy[:, 0], xy[:, 1]) > 1e-6)
    s = make_scan(points=xy[ok])
    return Scan(s.bearing, s.range, s.points, int((~ok).sum()))
