"""Hand-segmented board points per pose: a CSV ``pose,x_m,y_m`` (lidar frame, scan plane z = 0, metres).

Extra columns are ignored; ``#`` lines are comments. Poses keep the order of their first row; each pose's points
keep the file's order.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..dataset import DatasetError, csv_rows

COLUMNS = ("pose", "x_m", "y_m")


def read_segmented_points(path) -> dict[str, np.ndarray]:
    """Pose name -> (K,2) board points (metres); DatasetError naming the file, line and field when a row is bad."""
    path = Path(path)
    rows = csv_rows(path)
    if not rows:
        raise DatasetError("empty file (needs a header pose,x_m,y_m)", file=path)
    (_, header), body = rows[0], rows[1:]
    names = [h.strip().lower() for h in header]
    missing = [c for c in COLUMNS if c not in names]
    if missing:
        raise DatasetError(f"header lacks column(s) {','.join(missing)}; got {','.join(header)!r}", file=path, line=1)
    ip, ix, iy = (names.index(c) for c in COLUMNS)
    out: dict[str, list] = {}
    for n, r in body:
        if len(r) != len(names):
            raise DatasetError(f"expected {len(names)} fields, got {len(r)}", file=path, line=n)
        pose = r[ip].strip()
        for col, i in (("x_m", ix), ("y_m", iy)):
            try:
                v = float(r[i])
            except ValueError:
                raise DatasetError(f"field {col}: not a number: {r[i]!r}", file=path, line=n, pose=pose) from None
            if not np.isfinite(v):
                raise DatasetError(f"field {col}: not finite", file=path, line=n, pose=pose)
        out.setdefault(pose, []).append((float(r[ix]), float(r[iy])))
    if not out:
        raise DatasetError("no points after the header", file=path)
    return {k: np.asarray(v, float) for k, v in out.items()}
