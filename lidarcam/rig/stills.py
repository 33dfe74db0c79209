"""Still-frame picking: which frames of a calibration recording become board poses, and why.

A recording is mostly motion and near-duplicates. The picking runs in stages, each a pure function here:
``still_runs`` finds runs of frames whose thumbnail barely changes (cheap, every frame); the centre of each run
is the run's candidate (the others are its near-duplicates); a candidate is still when its board's corners,
detected in it and tracked into both neighbouring frames (``track_corners``), move less than ``still_px``
(``corner_motion``) and its scan segment stays put (``scan_segment_shift``); ``too_close`` drops a pose within
``min_angle_deg`` and ``min_move_m`` of one already kept; ``spread_order`` chooses up to ``max_poses`` that
spread the board normals (``calib_core.refine.uncertainty.normal_spread_deg``).
Pixels, metres, degrees at the option edges; radians and metres inside.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calib_core.data.observations import BoardObservation, Observations
from calib_core.refine.uncertainty import normal_spread_deg


@dataclass(frozen=True)
class PickOptions:
    """Thresholds of the picking and the time sync.

    Attributes:
        max_poses: at most this many poses are kept (chosen to spread the board normals).
        still_px: a candidate's corners may move at most this much (RMS over corners, pixels) to each neighbour.
        quiet_grey: a frame is quiet when its thumbnail changes by at most this (99.9th percentile of the absolute
            grey-level differences, ``timesync.image_motion``) from the previous and to the next frame;
            0 = automatic (3 x the 5th percentile of the changes + 0.2).
        min_run: fewest consecutive quiet frames that make a still run.
        scan_still_m: the board segment of the paired scan and of the scans a quarter of the run before and after
            may differ by at most this median range change (metres); 0 = automatic (``median_shift_tolerance``:
            4 standard deviations of the median of the differences at the extraction's range noise) ...
        scan_still_beams: ... and their segment ends by at most this many beams.
        min_angle_deg, min_move_m: a pose is a duplicate of a kept one when both its rotation differs by less than
            ``min_angle_deg`` and its board centre moved less than ``min_move_m``.
        sync_tol_s: pairing tolerance (s); None = ``timesync.DEFAULT_TOL_FRACTION`` x the scan period.
        time_offset_s: scan clock minus image clock (s), applied before pairing.
        estimate_offset: estimate the offset from the moving board instead (``timesync.estimate_offset``).
        max_offset_s: half-width of the window searched for the offset.
        thumb_width: width of the thumbnails the quiet test compares (pixels).
    """

    max_poses: int = 20
    still_px: float = 0.5
    quiet_grey: float = 0.0
    min_run: int = 3
    scan_still_m: float = 0.0
    scan_still_beams: int = 2
    min_angle_deg: float = 5.0
    min_move_m: float = 0.10
    sync_tol_s: float | None = None
    time_offset_s: float = 0.0
    estimate_offset: bool = False
    max_offset_s: float = 0.5
    thumb_width: int = 160


def quiet_threshold(motion: np.ndarray) -> float:
    """Automatic quiet threshold (grey levels): 3 x the 5th percentile of the frame changes, + 0.2. The quietest
    frames of a calibration recording are still ones, so this sits just above the image noise."""
    m = np.asarray(motion, float)
    m = m[np.isfinite(m)]
    return 3.0 * float(np.percentile(m, 5)) + 0.2 if len(m) else math.inf


def still_runs(motion: np.ndarray, threshold: float, min_run: int) -> list[tuple[int, int]]:
    """Half-open frame ranges ``[a, b)`` of at least ``min_run`` consecutive quiet frames: frame ``i`` is quiet
    when ``motion[i]`` (change from frame i-1) and ``motion[i+1]`` (change to frame i+1) are both at most
    ``threshold``; the first and last frames are never quiet (a neighbour is missing)."""
    m = np.asarray(motion, float)
    n = len(m)
    quiet = np.zeros(n, bool)
    if n >= 3:
        q = np.nan_to_num(m, nan=np.inf) <= threshold
        quiet[1:-1] = q[1:-1] & q[2:]
    edges = np.diff(np.concatenate([[0], quiet.astype(np.int8), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(a), int(b)) for a, b in zip(starts, ends, strict=True) if b - a >= max(1, min_run)]


def run_tries(run: tuple[int, int]) -> list[int]:
    """Frames of a still run ``[a, b)`` tried in turn as its candidate: the centre, then the quarter points (a run
    can hold a slow move between two rests; one of them is then still)."""
    a, b = run
    out = []
    for c in ((a + b - 1) // 2, a + (b - a) // 4, a + (3 * (b - a)) // 4):
        if a <= c < b and c not in out:
            out.append(c)
    return out


def corner_motion(corners: np.ndarray, neighbours: list[np.ndarray | None]) -> float:
    """RMS corner displacement (pixels) from ``corners`` (N,2) to a neighbour's corners, the largest over the
    neighbours (inf when a neighbour's board was not found). RMS, not max: a moving board moves every corner,
    while detector jitter moves single corners by a few tenths of a pixel."""
    out = 0.0
    for c in neighbours:
        if c is None or c.shape != corners.shape:
            return math.inf
        out = max(out, float(np.sqrt(np.mean(np.sum((c - corners) ** 2, axis=1)))))
    return out


def track_corners(gray: np.ndarray, corners: np.ndarray, other: np.ndarray) -> np.ndarray | None:
    """Where the corners (N,2) of ``gray`` are in the frame ``other`` (pyramidal Lucas-Kanade,
    ``cv2.calcOpticalFlowPyrLK``, sub-pixel); None when a corner is lost."""
    import cv2

    p0 = np.ascontiguousarray(corners, np.float32).reshape(-1, 1, 2)
    p1, status, _ = cv2.calcOpticalFlowPyrLK(gray, other, p0, None, winSize=(15, 15), maxLevel=3,
                                             criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-3))
    if p1 is None or not np.all(status):
        return None
    return p1.reshape(-1, 2).astype(float)


def median_shift_tolerance(range_sigma_m: float, n_beams: int) -> float:
    """4 standard deviations (metres) of the median of ``n_beams`` differences of two ranges with Gaussian noise
    ``range_sigma_m``: ``4 sqrt(pi/2) sqrt(2) sigma / sqrt(n)``."""
    return 4.0 * math.sqrt(math.pi) * range_sigma_m / math.sqrt(max(n_beams, 1))


def scan_segment_shift(bearing_step: float, seg_a: tuple[np.ndarray, np.ndarray],
                       seg_b: tuple[np.ndarray, np.ndarray]) -> tuple[float, float, int]:
    """How far a board segment moved between two scans: (|median range change| over the bearings both segments
    cover, metres; largest shift of a segment end, in beams; number of shared beams). Each segment is
    (bearing (K,), range (K,)) sorted by bearing; (NaN, inf, 0) when they share no bearing."""
    (ba, ra), (bb, rb) = seg_a, seg_b
    lo, hi = max(ba[0], bb[0]), min(ba[-1], bb[-1])
    ends = max(abs(ba[0] - bb[0]), abs(ba[-1] - bb[-1])) / abs(bearing_step)
    if hi < lo:
        return math.nan, math.inf, 0
    grid = ba[(ba >= lo) & (ba <= hi)]
    d = np.interp(grid, bb, rb) - np.interp(grid, ba, ra)
    return abs(float(np.median(d))), float(ends), len(grid)


def pose_difference(Ta: np.ndarray, Tb: np.ndarray, centre_board: np.ndarray) -> tuple[float, float]:
    """(rotation angle between two board poses, degrees; distance between the board centres, metres)."""
    R = Ta[:3, :3].T @ Tb[:3, :3]
    ang = math.degrees(math.acos(float(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0))))
    c = np.array([*centre_board, 0.0, 1.0])
    return ang, float(np.linalg.norm((Ta @ c)[:3] - (Tb @ c)[:3]))


def too_close(T: np.ndarray, kept: list[tuple[int, np.ndarray]], centre_board: np.ndarray, opts: PickOptions
              ) -> tuple[int, float, float] | None:
    """(frame, degrees, metres) of the first kept pose ``T`` duplicates (module docstring), else None."""
    for frame, Tk in kept:
        ang, move = pose_difference(T, Tk, centre_board)
        if ang < opts.min_angle_deg and move < opts.min_move_m:
            return frame, ang, move
    return None


def spread_order(boards: list[BoardObservation], quality: np.ndarray, max_poses: int) -> tuple[list[int], float]:
    """Greedy choice of up to ``max_poses`` boards spreading the normals: first the best ``quality`` (lower is
    better), then each time the board that most raises ``normal_spread_deg`` of the chosen set (ties: the
    largest smallest angle to a chosen normal). Returns (chosen indices in choice order, final spread, degrees)."""
    n = len(boards)
    if n == 0 or max_poses <= 0:
        return [], 0.0
    normals = np.array([b.T_cam_board[:3, 2] for b in boards])
    chosen = [int(np.argmin(quality))]
    while len(chosen) < min(max_poses, n):
        rest = [i for i in range(n) if i not in chosen]
        best, key = rest[0], (-math.inf, -math.inf)
        for i in rest:
            spread = normal_spread_deg(Observations(tuple(boards[j] for j in chosen + [i])))
            gap = float(np.degrees(np.arccos(np.clip(normals[chosen] @ normals[i], -1, 1))).min())
            k = (round(spread, 6), gap)
            if k > key:
                best, key = i, k
        chosen.append(best)
    return chosen, normal_spread_deg(Observations(tuple(boards[j] for j in chosen)))
