"""The one entry of the library: ``calibrate(observations, method=...)`` -> ``CalibrationResult``."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from .checks.diagnose import data_causes, judge
from .checks.verdict import check, data_warnings
from .data.observations import Observations
from .data.outcome import InfoParts, ObservationsPart, ResidualRmsPart, VerdictPart
from .data.result import CalibrationResult, observations_fingerprint
from .errors import CalibrationError, SolveFailure, UncertaintyError
from .geometry.mounting import MountingPrior
from .methods.last_steps import PRIOR_CONTRADICTS
from .model.residuals import range_residuals
from .registry import METHODS, check_options, get_method


def _failure(obs: Observations, method: str, reason: str, candidates, t0: float, verdict: bool,
             extra: dict | None = None) -> CalibrationResult:
    """``ok=False`` with ``reason`` and the method's ``extra`` info (e.g. the directions a degenerate board set
    does not determine); with ``verdict``, what the data alone show (units, mispaired scans) is added to the
    warnings and, as likely causes, to the reason."""
    info: dict = dict(extra or {})
    if verdict:
        warnings = list(info.get("warnings", []))
        warnings += [w for w in data_warnings(obs) if w not in warnings]
        causes = data_causes(obs)
        # the warnings keep their place ahead of the verdict, as the entries have always been ordered
        info = InfoParts(base={**info, "warnings": warnings}, warnings=warnings,
                         verdict=VerdictPart(None, None, tuple(warnings), tuple(dict.fromkeys(n for n, _ in causes)))
                         ).to_info()
        reason += "".join(f"; likely cause: {msg}" for _, msg in causes)
    return CalibrationResult(method, False, reason=reason,
                             candidates=np.zeros((0, 4, 4)) if candidates is None else candidates,
                             seconds=time.perf_counter() - t0, info=info)


def residual_rms(obs: Observations, T: np.ndarray, info: dict) -> ResidualRmsPart:
    """The range residuals' RMS (metres) over every scan point of the boards the answer rests on, at the answer
    and at the start the method refined from (``info["start_T_lidar_cam"]`` or an ``X+s`` method's base answer;
    None where the method has no start): the before and after of a refinement, as the summary prints them."""
    used = info.get("boards_used")
    data = (obs if used is None else obs.subset(list(used))).scan_data

    def rms(T_):
        e = range_residuals(np.asarray(T_, float), data)
        return float(np.sqrt(np.mean(e**2))) if e.size and np.all(np.isfinite(e)) else None

    start = info.pop("start_T_lidar_cam", info.get("base_T_lidar_cam"))
    return ResidualRmsPart(None if start is None else rms(start), rms(T))


def calibrate(observations: Observations, method: str = "lidarcam", *, verdict: bool = True,
              prior: MountingPrior | None = None, **options) -> CalibrationResult:
    """Calibrate ``T_lidar_cam`` from ``observations`` with the registered ``method``.

    Returns a ``CalibrationResult``; a method that cannot solve (too few boards, degenerate data) gives
    ``ok=False`` and a reason, never a guess. Every answer is then tested against the data
    (``calib_core.checks.verdict``, in ``info["verdict"]``, its warnings in ``info["warnings"]``): an answer the data
    contradict is ``ok=False`` with the reason, except for the paper's methods (``Method.paper``), whose answer
    stands with the contradiction as a warning. ``verdict=False`` skips the test. Unknown methods or options
    raise ``CalibrationError``.

    ``prior``: a mounting prior (``geometry.mounting.MountingPrior``: a rough guess of the pose with its sigmas),
    for the methods that take one (``Method.takes_prior``; the paper's have none in their model, and a prior given
    to any other method is refused rather than ignored): it enters the selection, the refinement and the
    covariance, and decides between answers the data leave tied (without it such a tie is ``ok=False`` naming the
    alternatives).
    """
    m = get_method(method)
    check_options(m, options)
    if prior is not None:
        if not m.takes_prior:
            takers = ", ".join(n for n, k in METHODS.items() if k.takes_prior)
            raise CalibrationError(f"{method}: takes no mounting prior (only {takers} does)")
        if not isinstance(prior, MountingPrior):
            raise CalibrationError(f"prior must be a MountingPrior, got {type(prior).__name__}")
        options["prior"] = prior
    t0 = time.perf_counter()
    if observations.n_boards < m.min_boards:
        return CalibrationResult(method, False, reason=f"{method} needs at least {m.min_boards} boards, "
                                 f"got {observations.n_boards}", seconds=time.perf_counter() - t0)
    try:
        T, cands, info = m.func(observations, **options)
    except SolveFailure as fail:
        return _failure(observations, method, fail.reason, fail.candidates, t0, verdict, fail.info)
    except UncertaintyError as err:
        return _failure(observations, method, f"{method}: {err}", None, t0, verdict)
    T = np.asarray(T, float)
    cands = np.asarray(cands, float)
    if not np.all(np.isfinite(T)):
        return CalibrationResult(method, False, reason=f"{method}: the solution is not finite", candidates=cands,
                                 seconds=time.perf_counter() - t0)
    parts = InfoParts(base=info, residual_rms=residual_rms(observations, T, info))
    cov = info.pop("covariance", None)
    cov = None if cov is None else np.asarray(cov, float)
    if verdict:
        used = info.get("boards_used")  # a method that left boards out is judged on the boards it used
        obs_v, ids = (observations, None) if used is None else (observations.subset(used), list(used))
        # the likely cause of a contradiction is searched for where it decides the answer (our methods); the
        # paper's methods carry the contradiction itself, which costs no search
        v = check(obs_v, T, board_ids=ids) if m.paper else judge(obs_v, T, board_ids=ids)
        if not v.consistent and ids is not None and not m.paper:
            full = judge(observations, T)  # the likely cause may lie in the boards left out (a mispaired scan)
            v = replace(v, warnings=tuple(dict.fromkeys([*v.warnings, *full.warnings])),
                        causes=tuple(dict.fromkeys([*v.causes, *full.causes])))
        warnings = list(info.get("warnings", []))
        if not v.consistent:
            warnings.append(f"the data contradict this answer: {v.reason}")
        warnings += [w for w in v.warnings if w not in warnings]
        parts = replace(parts, warnings=warnings, verdict=VerdictPart(v.consistent, v.reason, tuple(v.warnings),
                                                                      tuple(v.causes), v.sigma_m, tuple(v.boards)))
        if not v.consistent and not m.paper:
            causes = [w for w in v.warnings if w.startswith("likely cause")]
            if prior is not None and any(w.startswith(PRIOR_CONTRADICTS) for w in warnings):
                causes.insert(0, f"likely cause: {PRIOR_CONTRADICTS} (see the warnings; calibrate without it or "
                                 "widen its sigmas)")
            return CalibrationResult(method, False, None, f"{method}: the data contradict the answer: {v.reason}"
                                     + "".join(f"; {c}" for c in causes), cands, time.perf_counter() - t0,
                                     info=parts.to_info())
    parts = replace(parts, observations=ObservationsPart(**observations_fingerprint(observations)))
    return CalibrationResult(method, True, T, None, cands, time.perf_counter() - t0, cov, info=parts.to_info())
