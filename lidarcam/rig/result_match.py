"""Does a calibration result belong to the observations a report is drawn on? ``result_fit`` answers before the
report is written.

A result names the boards it used and left out, and (written by this version on) the fingerprint of the
observations it was computed from (``calib_core.data.result.observations_fingerprint``). A board index outside
the set, or a fingerprint of another board count, means another set's result: ``ResultMismatch`` (one line, exit
2). Otherwise the residuals judge: each board's scan points against its plane (camera's pose, through the result's
extrinsic), the boards' median RMS against the scans' own noise (``calib_core.data.lines.range_sigma``, from the
scan lines alone, no extrinsic). A result that does not fit them is another set's when its fingerprint differs
(``ResultMismatch``), and a wrong answer on these data otherwise: the report is written, its first warning says so,
and ``lidarcam report`` exits 1.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from calib_core.data.lines import range_sigma
from calib_core.data.observations import Observations
from calib_core.data.result import observations_fingerprint
from calib_core.errors import LidarcamError
from calib_core.geometry.transforms import invert_T

from .overlay import board_plane_distances

MISFIT_NOISE_FACTOR = 10.0
"""A result does not fit boards whose median residual RMS is above this many times the scans' noise ..."""
MISFIT_FLOOR_MM = 50.0
"""... and above this (mm). Fits of the public rigs: median RMS 0.8-1.3 x the noise (4.5-26 mm); another set's
result or a rotation three times too large: 160 mm to metres."""


class ResultMismatch(LidarcamError):
    """The result was computed from another set of boards than the observations given."""


@dataclass
class ResultFit:
    """How a result fits the observations: the median board RMS (mm), the scans' noise (mm), whether the result
    was computed from other observations (``other``: the fingerprint differs), and the loud warnings."""

    median_rms_mm: float | None
    noise_mm: float
    fits: bool
    other: bool
    warnings: list[str] = field(default_factory=list)


def scan_noise_mm(obs: Observations) -> float | None:
    """The scans' range noise (mm) from their lines alone (``calib_core.data.lines.range_sigma``), or None where
    the lines give none."""
    try:
        noise = 1000 * range_sigma(obs)
    except (LidarcamError, ValueError, np.linalg.LinAlgError):
        return None
    return noise if np.isfinite(noise) else None


def _named_boards(res: dict):
    """(field, board index) of every board the result names."""
    for i, b in enumerate(res.get("boards_used") or []):
        yield f"boards_used[{i}]", int(b)
    for i, r in enumerate(res.get("boards_rejected") or []):
        yield f"boards_rejected[{i}].index", int(r["index"])
    boards = (res.get("verdict") or {}).get("boards")  # free-form: only the indices it names are read
    for i, b in enumerate(boards if isinstance(boards, list) else []):
        if isinstance(b, dict) and isinstance(b.get("board"), int) and not isinstance(b["board"], bool):
            yield f"verdict.boards[{i}].board", b["board"]


def result_fit(res: dict, obs: Observations, result_name: str, obs_name: str) -> ResultFit:
    """Check that ``res`` (a ``load_result`` dict) is a result of ``obs``; ResultMismatch naming ``result_name``
    and ``obs_name`` when it is another set's; the fit of its extrinsic on ``obs`` otherwise."""
    n = obs.n_boards
    for where, b in _named_boards(res):
        if b >= n:
            raise ResultMismatch(f"{result_name}: field '{where}' names board {b}, but {obs_name} has {n} boards "
                                 f"(0-{n - 1}): the result of another board set")
    stamp = res.get("observations")
    mine = observations_fingerprint(obs)
    if isinstance(stamp, dict) and stamp.get("boards") is not None and stamp["boards"] != n:
        raise ResultMismatch(f"{result_name}: computed from {stamp['boards']} boards (field 'observations'), but "
                             f"{obs_name} has {n}: the result of another board set")
    other = isinstance(stamp, dict) and stamp.get("sha256") not in (None, mine["sha256"])
    noise_mm = scan_noise_mm(obs)
    noise_mm = 0.0 if noise_mm is None else noise_mm  # unknown: the floor alone judges
    if res.get("T_lidar_cam") is None:
        return ResultFit(None, noise_mm, True, other)
    Ti = invert_T(np.asarray(res["T_lidar_cam"], float))
    rms = [1000 * float(np.sqrt(np.mean(board_plane_distances(Ti, b.T_cam_board, b.scan) ** 2)))
           for b in obs.boards]
    med = float(np.median(rms))
    fits = not (med > MISFIT_NOISE_FACTOR * noise_mm and med > MISFIT_FLOOR_MM)
    misfit = f"median board residual {med:.0f} mm, " + (
        f"{med / noise_mm:.0f} x the scans' noise ({noise_mm:.1f} mm)" if noise_mm > 0 else
        f"above {MISFIT_FLOOR_MM:.0f} mm (the scans' noise unknown)")
    if other and not fits:
        raise ResultMismatch(f"{result_name}: computed from other observations than {obs_name} (field "
                             f"'observations': another fingerprint) and does not fit them ({misfit}): the result "
                             "of another board set")
    out = ResultFit(med, noise_mm, fits, other)
    if not fits:
        out.warnings.append(f"THE RESULT DOES NOT FIT THESE BOARDS: {misfit}; a wrong extrinsic or another set's "
                            "result: do not use it")
    if other:
        out.warnings.append(f"the result was computed from other observations than {obs_name} (another "
                            "fingerprint: extracted with other options?); the residuals here are of these")
    return out
