"""The distance of 2D points outside a simple polygon (a board outline, in its board frame), and its gradient:
the outline term of the residuals (``data.residuals.outside_outlines``). Metres in the board frame's (x, y).
"""

from __future__ import annotations

import functools

import numpy as np


def outside_outline(xy: np.ndarray, outline: np.ndarray, gradient: bool | str = False):
    """Distance (metres) of 2D points ``xy`` (...,2) outside the simple polygon ``outline`` (V,2); 0 inside. With
    ``gradient`` also (...,2) its gradient in ``xy``: the unit vector from the nearest point of the outline
    (``"later"``: a function of no arguments giving it).
    (The work runs edge by edge along the first axis, the points along the others: short reductions over the
    edges are then elementwise.)"""
    ax, ay, abx, aby, inv_len2, by, slope = _edges(np.ascontiguousarray(outline, float).tobytes(), len(outline),
                                                   xy.ndim - 1)
    x, y = xy[..., 0], xy[..., 1]
    wx, wy = x - ax, y - ay                                                     # (V,...) from each edge's start
    s = ((wx * abx + wy * aby) * inv_len2).clip(0.0, 1.0)
    ox, oy = wx - s * abx, wy - s * aby                                         # from the nearest point of each edge
    d2 = ox**2 + oy**2
    dist = np.sqrt(d2.min(axis=0))
    crosses = (ay > y) != (by > y)                                              # even-odd rule
    inside = np.logical_xor.reduce(crosses & (x < ax + wy * slope), axis=0)
    out = np.where(inside, 0.0, dist)
    if not gradient:
        return out
    g = functools.partial(_outline_gradient, ox, oy, d2, dist, inside)
    return out, (g if gradient == "later" else g())


def _outline_gradient(ox: np.ndarray, oy: np.ndarray, d2: np.ndarray, dist: np.ndarray,
                      inside: np.ndarray) -> np.ndarray:
    """``outside_outline``'s gradient (...,2) from the offsets (V,...) of the points from each edge's nearest point,
    their squares' sum, the distances to the outline and the inside mask (...)."""
    k = d2.argmin(axis=0).ravel() * dist.size + np.arange(dist.size)       # flat index of the nearest edge
    nearest = np.empty(dist.shape + (2,))
    flat = nearest.reshape(-1, 2)                                               # a view: each point's (x, y)
    flat[:, 0], flat[:, 1] = ox.ravel()[k], oy.ravel()[k]
    return np.where((inside | (dist == 0))[..., None], 0.0, nearest / np.where(dist > 0, dist, 1.0)[..., None])


@functools.lru_cache(maxsize=256)
def _edges(outline: bytes, V: int, ndim: int = 0) -> tuple[np.ndarray, ...]:
    """The edges ``a_k -> b_k`` of an outline (V,2) given as bytes: ``a_x, a_y``, ``b - a``, ``1 / |b - a|^2`` (0 for a
    zero-length edge, whose nearest point is then ``a_k``), ``b_y`` and the edge's ``dx/dy`` (0 where it is
    horizontal: such an edge is never crossed); each (V,) followed by ``ndim`` unit axes (to broadcast against
    points of ``ndim`` axes), kept per outline and ``ndim``."""
    a = np.frombuffer(outline, float).reshape(V, 2)
    b = np.roll(a, -1, axis=0)
    ab = b - a
    len2 = np.sum(ab**2, axis=1)
    out = (a[:, 0].copy(), a[:, 1].copy(), ab[:, 0].copy(), ab[:, 1].copy(),
           np.divide(1.0, len2, out=np.zeros(V), where=len2 > 0), b[:, 1].copy(),
           np.divide(ab[:, 0], ab[:, 1], out=np.zeros(V), where=ab[:, 1] != 0))
    out = tuple(v.reshape((V,) + (1,) * ndim) for v in out)
    for v in out:
        v.setflags(write=False)
    return out
