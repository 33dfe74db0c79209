"""The likelihood terms of a lower-bound outline (``outline_kind`` ``lower_bound``: the printed pattern on a board
at least as large), read by the selection score, the consensus and the polish alike.

The physical edge lies at or beyond the printed outline, so the lidar's segment on the board, mapped into the
board frame, covers the chord its line cuts through the outline (``data.chords``). Two one-sided terms, per board:

* **chord coverage**: each of the two shortfalls ``f`` (metres) of the segment against the chord is half-normal
  with scale ``CHORD_SIGMA_M`` (the scan's last point on the board lies up to one beam spacing inside the edge,
  plus the range noise), mixed with a flat component for a segment that is only part of the crossing (hand
  segmentation, points trimmed at the ends): its cost ``min(0.5 (f / sigma)^2, CHORD_CAP)``. Zero when the segment
  covers the chord: a segment running past the printed outline is what a margin looks like, no evidence against.
* **margin**: the board's margin beyond the printed outline is unknown but not unbounded: each scan end outside
  the outline lies on the physical edge, beside the printed edge it is paired with; its point-line error against
  that edge (the paper's, eq. 8-12: small for a margin perpendicular to the edge, large for an end run past the
  printed corner along it) is half-normal with scale ``MARGIN_SIGMA_M``, a soft prior on the margin, mixed with a
  flat component for an end beyond the printed corner: its cost ``min(0.5 (e / sigma)^2, MARGIN_CAP)``.

Why one-sided: a lower bound says where the edge cannot be (inside the outline), not where it is; the two-sided
point-line error of the paper (the ends on the outline's edges) reads the printed outline as the edge, which on a
real board is a few centimetres off. Residuals are in units of their scales (their squares halved are the costs);
Jacobians by the chain rule through the board frame (``residuals.board_frame_rows``), each crossing's edge and
each end's nearest outline edge held fixed (piecewise constant).
"""

from __future__ import annotations

import numpy as np

from ..data.observations import Observations
from .chords import chord_shortfalls, endpoints_2d, lower_bound_boards, lower_bound_groups
from .residuals import board_frame_rows, outside_outline, point_line_errors, scan_endpoints

CHORD_SIGMA_M = 0.03
"""Scale (metres) of a scan segment's shortfall against its lower-bound outline's chord (the beam spacing at the
board edges, 0.25 deg at 5 m is 22 mm, and the range noise)."""
CHORD_CAP = 1.0
"""Cost cap of one shortfall (half a squared number of ``CHORD_SIGMA_M``; 1.0 is reached at 1.4 scales, 42 mm):
beyond, the segment is read as part of the crossing only (the flat component of the mixture), which is no evidence
for or against a candidate. On the hand-segmented rig of EdenShin the segments fall 65 mm short of the pattern's
chord at the all-board answer (median)."""
MARGIN_SIGMA_M = 0.05
"""Scale (metres) of the margin term: each scan end outside its lower-bound outline lies on the physical edge, a
margin beyond the printed edge it is paired with, and its error is the paper's point-line error against that edge
(the sum of its distances to the edge's two corners less the edge's length L). A margin h perpendicular to the edge
gives about 2 h^2 / L, an overshoot a along it past the printed corner 2 a: the scale is reached at a 0.12 m margin
on a 0.6 m edge (a printed sheet on a backing board a decimetre larger per side) or 0.06 m on a letter sheet's
0.16 m edge, but 25 mm past the pattern's corner along the edge (about the beam spacing at the board edges). The
ends of EdenShin's, Kazmierczak's and Nowicki's segments lie 0-210 mm outside their patterns at the all-board
answers, every one beside an edge, none beyond a corner."""

MARGIN_CAP = 2.0
"""Cost cap of one end's margin term (half a squared number of ``MARGIN_SIGMA_M``; reached at 2 scales): the flat
component of a mixture for an end beyond the printed corner, where it meets the margins of two sides. An end lies
there when the scan passes within a margin m of the board's top or bottom: about 2 m / (H + 2 m) of the crossings
of a board of height H, 14% for a 5 cm margin on a 0.6 m board, a cost of -log(0.14) = 2.0. Without the cap, a
board whose margins surround the pattern (every side) would pull the answer towards the pattern's corners."""


def chord_residuals(obs: Observations, candidates: np.ndarray, sigma_m: float = CHORD_SIGMA_M,
                    cap: float = CHORD_CAP, frames: tuple | None = None, gradient: bool = False):
    """(M, 2 n) capped chord residuals ``min(f / sigma_m, sqrt(2 cap))`` of the n lower-bound boards (board order,
    two ends each) per candidate (M,4,4); with ``gradient`` also (M, 2n, 2, 2): d r / d (x, y) of each end in the
    board frame (0 where the cap holds)."""
    lb = lower_bound_boards(obs)
    C = np.asarray(candidates, float).reshape(-1, 4, 4)
    if not len(lb):
        return (np.zeros((len(C), 0)), np.zeros((len(C), 0, 2, 2))) if gradient else np.zeros((len(C), 0))
    top = np.sqrt(2.0 * cap)
    if not gradient:
        return np.minimum(chord_shortfalls(obs, C, frames=frames)[:, lb] / sigma_m, top).reshape(len(C), -1)
    f, g = chord_shortfalls(obs, C, gradient=True, frames=frames)
    r = f[:, lb] / sigma_m
    g = np.where((r < top)[..., None, None], g[:, lb] / sigma_m, 0.0)
    return np.minimum(r, top).reshape(len(C), -1), g.reshape(len(C), -1, 2, 2)


def margin_residuals(obs: Observations, candidates: np.ndarray, sigma_m: float = MARGIN_SIGMA_M,
                     frames: tuple | None = None, gradient: bool = False, cap: float = MARGIN_CAP):
    """(M, 2 n) each scan end's margin error over ``sigma_m``, boards in order: outside its lower-bound outline, the
    point-line error against the printed edge it is paired with (``residuals.point_line_errors``: the sum of its
    distances to the edge's two corners less the edge's length, ``MARGIN_SIGMA_M`` says why); 0 inside. With
    ``gradient`` also (M, 2n, 3): its gradient in the end's board-frame (x, y, z)."""
    lb = lower_bound_boards(obs)
    C = np.asarray(candidates, float).reshape(-1, 4, 4)
    if not len(lb):
        return (np.zeros((len(C), 0)), np.zeros((len(C), 0, 3))) if gradient else np.zeros((len(C), 0))
    P = endpoints_2d(obs, C, frames)                                          # (M,N,2,2)
    outside = np.zeros(P.shape[:3], bool)
    for idx, outline in lower_bound_groups(obs):
        outside[:, idx] = outside_outline(P[:, idx], outline) > 0
    e, g = point_line_errors(obs, C, gradient=True, frames=frames)           # (M,N,2), (M,N,2,3)
    r = np.where(outside, e, 0.0)[:, lb] / sigma_m
    top = np.sqrt(2.0 * cap)
    if not gradient:
        return np.minimum(r, top).reshape(len(C), -1)
    g = np.where((outside[:, lb] & (r < top))[..., None], g[:, lb] / sigma_m, 0.0)
    return np.minimum(r, top).reshape(len(C), -1), g.reshape(len(C), -1, 3)


def lower_bound_rows(obs: Observations, T: np.ndarray, frames: tuple, chord_sigma_m: float = CHORD_SIGMA_M,
                     cap: float = CHORD_CAP, margin_sigma_m: float = MARGIN_SIGMA_M):
    """At one (4,4) ``T_lidar_cam``: (chord residuals (2n,), their Jacobian (2n,6), margin residuals (2n,), theirs
    (2n,6)) in ``x = (w, dt)`` (``data.residuals``' left perturbation); ``frames``: ``board_frames(obs, T[None])``."""
    lb = lower_bound_boards(obs)
    if not len(lb):
        return np.zeros(0), np.zeros((0, 6)), np.zeros(0), np.zeros((0, 6))
    rc, gc = chord_residuals(obs, T[None], chord_sigma_m, cap, frames, gradient=True)
    rm, gm = margin_residuals(obs, T[None], margin_sigma_m, frames, gradient=True)
    ends = scan_endpoints(obs)[lb].reshape(-1, 3)                             # (2n,3): board i's two ends
    board = np.repeat(lb, 2)
    Jc = sum(board_frame_rows(obs, T, np.repeat(scan_endpoints(obs)[lb][:, j], 2, axis=0), board, gc[0][:, j],
                              frames) for j in (0, 1))
    Jm = board_frame_rows(obs, T, ends, board, gm[0], frames)
    return rc[0], Jc, rm[0], Jm
