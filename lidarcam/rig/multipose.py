"""What the poses of one rig tell about each other: near-duplicate captures and the static background.

- ``duplicate_groups``: poses whose camera views of the board agree (rotation within ``max_deg`` and translation
  within ``max_m``) are the same board pose captured more than once; they form one group, counted once.
- ``static_masks``: with no ``background.csv``, what stays put across the poses is background. A scan point is
  static when, in at least ``min_frac`` of the other pose groups, a scan has a return at the same bearing (within
  1.5 beam steps) and range (within ``tol_m``). The board moves from pose to pose, so its points are not static;
  a wall, a post or the rig's own structure is.
"""

from __future__ import annotations

import math

import numpy as np

from .dataset import Scan


def duplicate_groups(T_cam_boards: list[np.ndarray | None], max_deg: float = 1.0, max_m: float = 0.01) -> list[int]:
    """Group index per pose (poses without a board pose get their own group); groups numbered in pose order.

    Two poses join when their ``T_cam_board`` differ by less than ``max_deg`` in rotation and ``max_m`` in
    translation (single linkage along the pose order, as captures of one pose are consecutive or not)."""
    n = len(T_cam_boards)
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i in range(n):
        for j in range(i + 1, n):
            A, B = T_cam_boards[i], T_cam_boards[j]
            if A is None or B is None:
                continue
            c = (np.trace(A[:3, :3].T @ B[:3, :3]) - 1) / 2
            if math.degrees(math.acos(min(1.0, max(-1.0, c)))) < max_deg and \
                    np.linalg.norm(A[:3, 3] - B[:3, 3]) < max_m:
                parent[root(j)] = root(i)
    roots = [root(i) for i in range(n)]
    first = {r: k for k, r in enumerate(dict.fromkeys(roots))}
    return [first[r] for r in roots]


def _matches(scan: Scan, other: Scan, tol_m: float) -> np.ndarray:
    """True for points of ``scan`` with a return of ``other`` at the same bearing (1.5 steps) within ``tol_m``."""
    if len(other) < 2 or len(scan) == 0:
        return np.zeros(len(scan), bool)
    order = np.argsort(other.bearing)
    bb, br = other.bearing[order], other.range[order]
    step = float(np.median(np.diff(bb)))
    j = np.searchsorted(bb, scan.bearing)
    hit = np.zeros(len(scan), bool)
    for k in (-2, -1, 0, 1):  # the two beams on either side
        jj = np.clip(j + k, 0, len(bb) - 1)
        hit |= (np.abs(bb[jj] - scan.bearing) <= 1.5 * step) & (np.abs(br[jj] - scan.range) <= tol_m)
    return hit


def static_masks(scans: list[Scan | None], groups: list[int] | None = None, tol_m: float = 0.03,
                 min_frac: float = 0.75, min_groups: int = 2) -> list[np.ndarray | None]:
    """Per scan, True for its static points (see the module docstring); None for a missing scan. With fewer than
    ``min_groups + 1`` groups nothing is static (too few poses to tell)."""
    groups = list(range(len(scans))) if groups is None else list(groups)
    G = len({g for g, s in zip(groups, scans, strict=True) if s is not None})
    out: list[np.ndarray | None] = []
    need = max(min_groups, math.ceil(min_frac * (G - 1)))
    for i, s in enumerate(scans):
        if s is None:
            out.append(None)
            continue
        if G - 1 < need:
            out.append(np.zeros(len(s), bool))
            continue
        hits: dict[int, np.ndarray] = {}
        for j, o in enumerate(scans):
            if o is None or groups[j] == groups[i]:
                continue
            m = _matches(s, o, tol_m)
            hits[groups[j]] = hits[groups[j]] | m if groups[j] in hits else m
        count = np.sum(list(hits.values()), axis=0) if hits else np.zeros(len(s))
        out.append(count >= need)
    return out
