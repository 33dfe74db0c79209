"""The lidar axes of the degeneracy analysis (``checks.degeneracy``) and how its messages name them: the axis
names and their words, the ``calibrate(..., fixed=...)`` key of each, a direction as a combination of axes, and
what a refused set's profile likelihood says of each axis. One home for these words, so that the refusal's
reason and its readers (``experiments.summary.tables.refused_axes``) agree.

Axes and units as ``checks.degeneracy``: rotations (radians) about the lidar's x, y, z axes, translations along
them in units of the typical range ``scale_m``; degrees and millimetres only in the words.
"""

from __future__ import annotations

import numpy as np

AXES = ("roll", "pitch", "yaw", "x", "y", "z")
AXIS_WORDS = {"roll": "roll (rotation about the lidar x axis)", "pitch": "pitch (about the lidar y axis)",
              "yaw": "yaw (about the lidar z axis)", "x": "x (translation along the lidar x axis)",
              "y": "y (along the lidar y axis)", "z": "z (height, along the lidar z axis)"}

FOLD_WORDS = (" from the profile likelihood: the range residuals change only at second order along it here, where "
              "two of the boards' solutions meet")
"""How a fold direction's sigma (``degeneracy.FOLD_SPAN``) is named in the message."""

LEAN_WORDS = (": only their lean fixes these, so that board-pose errors of the lean's order are not in this "
              "1-sigma")
"""How an answered vertical-board set's cause goes on (``degeneracy.undetermined_directions``)."""


def fixed_key(axis: str) -> str:
    """The ``calibrate(..., fixed=...)`` key of a lidar axis name (``"z"`` -> ``"z_m"``)."""
    return f"{axis}_deg" if axis in AXES[:3] else f"{axis}_m"


def describe(v: np.ndarray, min_share: float = 0.1) -> str:
    """``0.71 roll - 0.70 y`` of a unit 6-vector (components whose square is at least ``min_share``)."""
    keep = [j for j in np.argsort(-np.abs(v)) if v[j] ** 2 >= min_share] or [int(np.argmax(np.abs(v)))]
    return " ".join(f"{'-' if v[j] < 0 else '+'} {abs(v[j]):.2f} {AXES[j]}" for j in keep).lstrip("+ ")


def join_words(words: list[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]


def axis_sigma_words(axis: str, sigma: float, scale_m: float) -> str:
    """``roll 5.1 deg`` / ``y 81 mm`` of an axis's 1-sigma ``sigma`` in scaled units."""
    return f"{axis} {np.degrees(sigma):.1f} deg" if AXES.index(axis) < 3 else f"{axis} {1000 * sigma * scale_m:.0f} mm"


def flat_words(axes: tuple[str, ...], profile: np.ndarray, scale_m: float, vertical: bool) -> str:
    """What leaves a refused set free, for its cause: the axes whose own profile 1-sigma (``profile``, scaled, in
    the order of ``axes``) is infinite, that is, stays flat across the physically possible span, and the profile
    1-sigma of the others (named for the calibration with given axes; with ``vertical`` boards, fixed beyond first
    order only)."""
    flat = [a for a, p in zip(axes, profile, strict=True) if not np.isfinite(p)]
    rest = [axis_sigma_words(a, p, scale_m) for a, p in zip(axes, profile, strict=True) if np.isfinite(p)]
    how = "profile 1-sigma, beyond first order only" if vertical else "profile 1-sigma: the boards fix these, weakly"
    return (f": {join_words(flat)} {'stays' if len(flat) == 1 else 'stay'} flat across the physically possible span"
            + (f" ({', '.join(rest)}: {how})" if rest else ""))
