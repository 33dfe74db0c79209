"""Plane polygons (a board's outline, board-frame metres): whether one is simple, with positive area."""

from __future__ import annotations

import numpy as np


def _segments_cross(p1, p2, q1, q2) -> bool:
    """True when closed segments p1p2 and q1q2 intersect (2D)."""
    def orient(a, b, c):
        return np.sign((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))

    def on_seg(a, b, c):
        return min(a[0], b[0]) <= c[0] <= max(a[0], b[0]) and min(a[1], b[1]) <= c[1] <= max(a[1], b[1])

    o1, o2, o3, o4 = orient(p1, p2, q1), orient(p1, p2, q2), orient(q1, q2, p1), orient(q1, q2, p2)
    if o1 != o2 and o3 != o4:
        return True
    return bool((o1 == 0 and on_seg(p1, p2, q1)) or (o2 == 0 and on_seg(p1, p2, q2))
                or (o3 == 0 and on_seg(q1, q2, p1)) or (o4 == 0 and on_seg(q1, q2, p2)))


def check_simple_polygon(outline: np.ndarray) -> str | None:
    """Why ``outline`` (V,2) is not a simple polygon with positive area, or None when it is."""
    V = len(outline)
    if V < 3:
        return f"needs at least 3 vertices, got {V}"
    x, y = outline[:, 0], outline[:, 1]
    area = 0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    if abs(area) < 1e-12:
        return "has zero area"
    for i in range(V):
        for j in range(i + 1, V):
            adjacent = j == i + 1 or (i == 0 and j == V - 1)  # adjacent edges share a vertex
            if not adjacent and _segments_cross(outline[i], outline[(i + 1) % V], outline[j], outline[(j + 1) % V]):
                return f"is not a simple polygon (edges {i} and {j} cross)"
    return None
