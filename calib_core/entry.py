"""The one entry of the library: ``calibrate(observations, method=...)`` -> ``CalibrationResult``."""

from __future__ import annotations

import time

import numpy as np

from .errors import CalibrationError
from .observations import Observations
from .registry import get_method
from .result import CalibrationResult, SolveFailure


def calibrate(observations: Observations, method: str = "lidarcam", **options) -> CalibrationResult:
    """Calibrate ``T_lidar_cam`` from ``observations`` with the registered ``method``.

    Returns a ``CalibrationResult``; a method that cannot solve (too few boards, degenerate data) gives
    ``ok=False`` and a reason, never a guess. Unknown methods or options raise ``CalibrationError``.
    """
    m = get_method(method)
    t0 = time.perf_counter()
    if observations.n_boards < m.min_boards:
        return CalibrationResult(method, False, reason=f"{method} needs at least {m.min_boards} boards, "
                                 f"got {observations.n_boards}", seconds=time.perf_counter() - t0)
    try:
        T, cands, info = m.func(observations, **options)
    except SolveFailure as fail:
        return CalibrationResult(method, False, reason=fail.reason, candidates=fail.candidates,
                                 seconds=time.perf_counter() - t0, info=fail.info)
    except TypeError as exc:
        if "unexpected keyword" in str(exc):
            raise CalibrationError(f"{method}: {exc}") from None
        raise
    cov = info.pop("covariance", None)
    return CalibrationResult(method, True, np.asarray(T, float), None, np.asarray(cands, float),
                             time.perf_counter() - t0, None if cov is None else np.asarray(cov, float), info=info)


