"""Scan side of the extraction: the board's points in one 2D scan (lidar frame, metres, radians).

No-returns dropped, optional background subtraction, breakpoint clustering (adaptive threshold of Borges & Aldon
2004), split-and-merge into line segments, and the segment that agrees with the camera's view of the board is kept
(hard gates: ranges within the camera-to-board distances +- ``max_offset_m``, length at most the board's diagonal, no
arc; ranking: distance to the board centre and the expected chord)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calib_core.data.lines import tls_line
from calib_core.geometry.transforms import transform_points

from .dataset import BoardSpec, Scan
from .extract_options import AmbiguousSegment, ExtractionError, ExtractOptions, PoseDiagnostics


def breakpoints(scan: Scan, range_sigma_m: float = 0.02, lambda_deg: float = 10.0) -> np.ndarray:
    """Indices i where the sweep breaks between point i and i+1 (Borges & Aldon's adaptive threshold:
    ``r_i sin(dtheta) / sin(lambda - dtheta) + 3 sigma``)."""
    if len(scan) < 2:
        return np.zeros(0, int)
    P, r = scan.points, scan.range
    gap = np.linalg.norm(np.diff(P, axis=0), axis=1)
    dth = np.abs(np.angle(np.exp(1j * np.diff(scan.bearing))))
    lam = math.radians(lambda_deg)
    with np.errstate(divide="ignore", invalid="ignore"):
        thresh = np.where(dth < lam, r[:-1] * np.sin(dth) / np.sin(lam - dth), 0.0) + 3.0 * range_sigma_m
    return np.flatnonzero(gap > thresh)


def _chord_split(P: np.ndarray, tol: float, min_points: int) -> list[tuple[int, int]]:
    """Recursive split (iterative end-point fit) of the run ``P``; half-open index ranges relative to P."""
    out, stack = [], [(0, len(P))]
    while stack:
        i0, i1 = stack.pop()
        n = i1 - i0
        if n < 3:
            out.append((i0, i1))
            continue
        k = max(1, min(3, n // 6))
        a, b = P[i0:i0 + k].mean(axis=0), P[i1 - k:i1].mean(axis=0)
        u = b - a
        L = np.linalg.norm(u)
        Q = P[i0:i1]
        if L < 1e-9:
            d = np.linalg.norm(Q - a, axis=1)
        else:
            d = np.abs((Q - a) @ np.array([-u[1], u[0]]) / L)
        j = int(np.argmax(d[1:-1])) + 1
        if d[j] > tol:
            stack += [(i0 + j + 1, i1), (i0, i0 + j + 1)] if j < n // 2 else [(i0 + j, i1), (i0, i0 + j)]
        else:
            out.append((i0, i1))
    return sorted(out)


def _merge(P: np.ndarray, segs: list[tuple[int, int]], tol: float) -> list[tuple[int, int]]:
    segs = list(segs)
    merged = True
    while merged and len(segs) > 1:
        merged = False
        best, best_err = None, tol
        for k in range(len(segs) - 1):
            i0, i1 = segs[k][0], segs[k + 1][1]
            err = float(np.max(np.abs(tls_line(P[i0:i1])[2])))
            if err <= best_err:
                best, best_err = k, err
        if best is not None:
            segs[best:best + 2] = [(segs[best][0], segs[best + 1][1])]
            merged = True
    return segs


def split_and_merge(scan: Scan, keep: np.ndarray | None = None, opts: ExtractOptions | None = None
                    ) -> list[tuple[int, int]]:
    """Line segments of a scan as half-open index ranges ``(i0, i1)`` into the scan (only points with ``keep``).

    Breakpoints (range jumps, dropped points) split the sweep into runs; each run is split where a point lies
    further than ``opts.split_tol`` from the chord of its ends, and neighbouring pieces are merged back while
    their union fits one line within the same tolerance. Segments shorter than ``opts.min_points`` are dropped.
    """
    opts = opts or ExtractOptions()
    keep = np.ones(len(scan), bool) if keep is None else np.asarray(keep, bool)
    idx = np.flatnonzero(keep)
    if len(idx) < opts.min_points:
        return []
    sub = Scan(scan.bearing[idx], scan.range[idx], scan.points[idx])
    cuts = breakpoints(sub, opts.range_sigma_m, opts.breakpoint_lambda_deg)
    # a removed point in between also breaks the run
    cuts = np.union1d(cuts, np.flatnonzero(np.diff(idx) > 1))
    bounds = np.concatenate([[0], cuts + 1, [len(idx)]])
    segs = []
    for s0, s1 in zip(bounds[:-1], bounds[1:], strict=True):
        if s1 - s0 < opts.min_points:
            continue
        P = sub.points[s0:s1]
        pieces = _merge(P, _chord_split(P, opts.split_tol, opts.min_points), opts.split_tol)
        segs += [(int(idx[s0 + a]), int(idx[s0 + b - 1]) + 1) for a, b in pieces if b - a >= opts.min_points]
    return segs


def background_mask(scan: Scan, background: Scan, tol_m: float = 0.1) -> np.ndarray:
    """True for points of ``scan`` that are background: not at least ``tol_m`` nearer than the background beam at
    the same bearing (nearest background beam within 1.5 median beam steps; points without one are kept)."""
    if len(background) == 0 or len(scan) == 0:
        return np.zeros(len(scan), bool)
    order = np.argsort(background.bearing)
    bb, br = background.bearing[order], background.range[order]
    step = np.median(np.abs(np.diff(bb))) if len(bb) > 1 else math.inf
    j = np.clip(np.searchsorted(bb, scan.bearing), 1, max(len(bb) - 1, 1))
    left, right = np.clip(j - 1, 0, len(bb) - 1), np.clip(j, 0, len(bb) - 1)
    pick = np.where(np.abs(scan.bearing - bb[left]) <= np.abs(scan.bearing - bb[right]), left, right)
    near = np.abs(scan.bearing - bb[pick]) <= 1.5 * step
    return near & (scan.range > br[pick] - tol_m)


def _polygon_chord(outline: np.ndarray, c: np.ndarray, u: np.ndarray) -> float:
    """Length of the intersection of the line ``c + s u`` (board frame 2D) with the convex hull of ``outline``."""
    s_vals = []
    V = len(outline)
    for k in range(V):
        a, b = outline[k], outline[(k + 1) % V]
        e = b - a
        M = np.array([[u[0], -e[0]], [u[1], -e[1]]])
        if abs(np.linalg.det(M)) < 1e-12:
            continue
        s, t = np.linalg.solve(M, a - c)
        if -1e-9 <= t <= 1 + 1e-9:
            s_vals.append(s)
    return float(max(s_vals) - min(s_vals)) if len(s_vals) >= 2 else 0.0


def expected_chord(T_cam_board: np.ndarray, board: BoardSpec, plane_normal_cam=(0.0, 1.0, 0.0)) -> float:
    """Chord of the board through its centre along the board plane's intersection with a plane of normal
    ``plane_normal_cam`` (camera frame), metres; NaN when the two planes are parallel."""
    n_b = T_cam_board[:3, 2]
    d = np.cross(n_b, np.asarray(plane_normal_cam, float))
    if np.linalg.norm(d) < 1e-6:
        return math.nan
    u = T_cam_board[:3, :3].T @ (d / np.linalg.norm(d))
    return _polygon_chord(board.outline, board.centre, u[:2] / np.linalg.norm(u[:2]))


def board_distance_range(T_cam_board: np.ndarray, board: BoardSpec) -> tuple[float, float]:
    """(nearest, farthest) distance from the camera centre to the board (its plane and outline vertices), metres."""
    V = transform_points(T_cam_board, np.column_stack([board.outline, np.zeros(len(board.outline))]))
    far = float(np.linalg.norm(V, axis=1).max())
    plane = abs(float(T_cam_board[:3, 2] @ T_cam_board[:3, 3]))
    return min(plane, float(np.linalg.norm(V, axis=1).min())), far


@dataclass
class _Segment:
    i0: int
    i1: int
    length: float
    range_mid: float
    rms: float
    score: float = math.inf


def curvature_statistic(P: np.ndarray, range_sigma_m: float) -> float:
    """How much better a parabola than a straight line fits the (K,2) points, in chi-square(1) units of the range
    noise across the line (``sigma |nu . beam|``); about chi-square(1) for a straight segment."""
    if len(P) < 4:
        return 0.0
    c, u, res, _ = tls_line(P)
    nu = np.array([-u[1], u[0]])
    s = (P - c) @ u
    A = np.column_stack([np.ones_like(s), s, s**2])
    coef, *_ = np.linalg.lstsq(A, res, rcond=None)
    gain = float(res @ res - np.sum((res - A @ coef) ** 2))
    beams = P / np.linalg.norm(P, axis=1, keepdims=True)
    sigma_p = range_sigma_m * max(float(np.sqrt(np.mean((beams @ nu) ** 2))), 0.05)
    return gain / sigma_p**2


def describe_segment(scan: Scan, idx: np.ndarray) -> tuple[float, float, float]:
    P = scan.points[idx]
    c, u, res, _ = tls_line(P)
    s = (P - c) @ u
    return float(s.max() - s.min()), float(np.linalg.norm(c)), float(np.sqrt(np.mean(res ** 2)))


def find_board_segment(scan: Scan, T_cam_board: np.ndarray, board: BoardSpec, opts: ExtractOptions | None = None,
                       background: Scan | None = None, diag: PoseDiagnostics | None = None,
                       static: np.ndarray | None = None) -> np.ndarray:
    """Indices of the scan points on the board (ordered along the sweep); raises ExtractionError when no segment
    agrees with the camera's view of the board. ``static``: mask of points that stay put across poses (dropped)."""
    opts = opts or ExtractOptions()
    diag = diag if diag is not None else PoseDiagnostics("")
    keep = np.ones(len(scan), bool)
    if background is not None:
        bg = background_mask(scan, background, opts.background_tol_m)
        keep &= ~bg
        diag.n_background = int(bg.sum())
    if static is not None:
        keep &= ~static
        diag.n_background += int(static.sum())
    segs = split_and_merge(scan, keep, opts)
    diag.n_segments = len(segs)
    if not segs:
        raise ExtractionError("no line segment in the scan" + (" after background subtraction" if background
                                                               is not None else ""))
    near, far = board_distance_range(T_cam_board, board)
    lo, hi = near - opts.max_offset_m, far + opts.max_offset_m
    ext = board.outline.max(axis=0) - board.outline.min(axis=0)
    min_len, max_len = opts.min_length_frac * float(ext.min()), board.diagonal + opts.length_slack_m
    if not opts.outline_known:
        max_len = max(max_len, opts.max_board_m)
    chord = expected_chord(T_cam_board, board, opts.scan_plane_normal_cam) if opts.chord_weight > 0 else math.nan
    centre_dist = float(np.linalg.norm(transform_points(T_cam_board, [[*board.centre, 0.0]])[0]))
    cands, rejected = [], []
    for i0, i1 in segs:
        idx = np.arange(i0, i1)
        length, rmid, rms = describe_segment(scan, idx)
        r = scan.range[idx]
        inside = np.mean((r >= lo) & (r <= hi))
        why = None
        if inside < 0.9:
            why = f"range {r.min():.2f}-{r.max():.2f} m outside {lo:.2f}-{hi:.2f} m"
        elif length > max_len:
            why = f"length {length:.2f} m > diagonal {board.diagonal:.2f} m"
        elif length < min_len:
            why = f"length {length:.2f} m < {min_len:.2f} m"
        elif (curv := curvature_statistic(scan.points[idx], opts.range_sigma_m)) > opts.max_curvature_chi2:
            why = (f"not straight within the noise (curvature statistic {curv:.3g} > {opts.max_curvature_chi2:g}): "
                   "an arc (a pillar, a curved object), not a board")
        if why:
            rejected.append(why)
            continue
        score = abs(rmid - centre_dist) / max(board.diagonal / 2, 1e-3)
        if math.isfinite(chord) and chord > 0:
            miss = length - chord if opts.outline_known else max(0.0, chord - length)
            score += opts.chord_weight * abs(miss) / chord
        score += rms / opts.split_tol
        cands.append(_Segment(i0, i1, length, rmid, rms, score))
    diag.n_candidates = len(cands)
    if not cands:
        raise ExtractionError(f"no scan segment matches the board at {near:.2f}-{far:.2f} m "
                              f"({len(segs)} segments; refused: {'; '.join(rejected) if rejected else '-'})")
    cands.sort(key=lambda s: s.score)
    best = cands[0]
    if len(cands) > 1 and cands[1].score - best.score < opts.ambiguity_margin:
        two = ", ".join(f"{math.degrees(scan.bearing[c.i0]):.1f}..{math.degrees(scan.bearing[c.i1 - 1]):.1f} deg "
                        f"(score {c.score:.2f})" for c in cands[:2])
        if opts.skip_ambiguous:
            raise AmbiguousSegment(f"ambiguous: {len(cands)} segments fit the board about equally: {two}",
                                   [(c.i0, c.i1) for c in cands if c.score - best.score < opts.ambiguity_margin])
        diag.notes.append(f"ambiguous: {len(cands)} segments fit the board about equally: {two}")
    return np.arange(best.i0, best.i1)
