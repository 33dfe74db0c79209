"""Hints the command line adds to a failed or thin extraction: a board size off by a unit factor shows as every
pose's board at a distance the scans never reach."""

from __future__ import annotations

import numpy as np

RATIO_OK = (1 / 3, 3.0)
"""The images' board distance over the scans' 10th-percentile range (the board is most often the nearest thing in
front) that a right square size gives: 0.65-1.0 on the demo's dataset, rig offsets and clutter included."""


def square_hint(dataset, diags) -> str | None:
    """One line naming board.yaml's ``square_m`` as the likely cause when at least half the poses were skipped and
    the images put the board several times nearer or farther than the scans' returns; None otherwise."""
    skipped = [d for d in diags if not d.used and np.isfinite(d.cam_distance_m)]
    if len(skipped) < max(1, len(diags) / 2):
        return None
    ranges = [np.percentile(p.scan.range, 10) for p in dataset.poses if len(p.scan)]
    if not ranges:
        return None
    ratio = float(np.median([d.cam_distance_m for d in skipped]) / np.median(ranges))
    if RATIO_OK[0] <= ratio <= RATIO_OK[1]:
        return None
    square, k = dataset.board.square, round(float(np.log10(ratio)))
    if k != 0 and abs(np.log10(ratio) - k) < 0.3:  # a unit factor: mm or cm read as m, or the reverse
        fits = f"{square:g} m {'/' if k > 0 else 'x'} {10 ** abs(k):g} = {square / 10 ** k:g} m would match"
    else:
        fits = f"about {square / ratio:.2g} m would match"
    return (f"hint: the images put the board {ratio:.3g}x as far as the scans' near returns on {len(skipped)} "
            f"skipped poses: is board.yaml's square_m ({square:g} m) in metres and right? {fits}")
