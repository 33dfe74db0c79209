"""The stated per-board systematic scale of an observation set (``board_range_sigma_m``, metres)."""

from __future__ import annotations

import numpy as np

from ..errors import ObservationError

MAX_BOARD_RANGE_SIGMA_M = 1.0
"""Largest stated per-board systematic scale accepted (metres): more is no calibration board."""


def check_board_range_sigma(value) -> float | None:
    """A stated ``board_range_sigma_m`` as a float (None stays None); ObservationError (field
    ``board_range_sigma_m``) when it is not a number, NaN, negative or over ``MAX_BOARD_RANGE_SIGMA_M``."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ObservationError(f"must be a number (metres), got {type(value).__name__}", field="board_range_sigma_m")
    v = float(value)
    if not (0.0 <= v <= MAX_BOARD_RANGE_SIGMA_M):
        raise ObservationError(f"must be in [0, {MAX_BOARD_RANGE_SIGMA_M:g}] m, got {v!r}",
                               field="board_range_sigma_m")
    return v
