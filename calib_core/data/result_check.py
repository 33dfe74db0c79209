"""The checks ``load_result`` runs on a ``lidarcam.result/1`` file: every field it knows has its type, shape and
range (a 4x4 rigid ``T_lidar_cam``, its inverse where ``T_cam_lidar`` is given, a symmetric positive semi-definite
6x6 covariance, board indices as non-negative integers), or ObservationError naming the file and the field.

Unknown fields are kept as they are (the schema takes optional fields); the known ones are what the report and
``CalibrationResult.from_dict`` read.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ObservationError
from ..geometry.transforms import ROTATION_TOL, invert_T, rotation_defect
from .observations import LOAD_ROTATION_TOL, MAX_BOARDS, numeric_array, orthonormalised

INVERSE_TOL = 1e-6
"""Largest entry of ``T_cam_lidar @ T_lidar_cam - I`` accepted (the file's two directions must agree)."""
MAX_TRANSLATION_M = 1000.0
"""Longest translation a result's transform may hold (metres): beyond it, a unit mistake or garbage."""
COVARIANCE_TOL = 1e-9
"""Relative asymmetry and negative eigenvalue (of the largest) a covariance may have from rounding."""
TEXT_FIELDS = ("method", "reason", "covariance_model", "note", "intrinsics")
NUMBER_FIELDS = ("seconds", "conditioning", "sigma_rot_deg", "sigma_trans_mm")
DICT_FIELDS = ("verdict", "degeneracy", "prior", "board_dispersion", "covariance_bend", "observations", "noise",
               "residual_rms", "noise_model", "board_error")
NUMBER_DICTS = ("mounting", "mounting_sigma", "fixed")
NESTED_NUMBERS = {"board_dispersion": ("statistic", "dof", "p_value"),
                  "covariance_bend": ("departure_sigmas", "sigma_rot_deg_laplace", "sigma_trans_mm_laplace"),
                  "residual_rms": ("answer_m",), "board_error": ("offset_m", "tilt_m")}
"""Numbers inside an object field that the readers format (required where the object is given)."""
OPTIONAL_NUMBERS = {"residual_rms": ("start_m",), "noise": ("scan_lines_m", "trimmed_m", "joint_m", "verdict_spread_m")}
"""Numbers inside an object field that may be null."""


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _board_index(v, name: str) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v < MAX_BOARDS:
        raise ObservationError(f"not a board index (an integer 0..{MAX_BOARDS - 1}): {str(v)[:20]!r}", field=name)
    return v


def _transform(value, name: str) -> np.ndarray:
    """A 4x4 rigid transform (rotation re-orthonormalised when written with few decimals)."""
    A = numeric_array(value, name, (4, 4))
    if np.max(np.abs(A[:3, :3])) > 1.0 + LOAD_ROTATION_TOL:  # before any product of it can overflow
        raise ObservationError(f"not a rigid transform: the rotation block holds {np.max(np.abs(A[:3, :3])):.3g}, "
                               "a rotation's entries lie within [-1, 1]", field=name)
    T, _ = orthonormalised(A, name)
    defect = rotation_defect(T[:3, :3])
    if defect > ROTATION_TOL:
        why = "its determinant is not positive" if not math.isfinite(defect) else f"|R^T R - I| = {defect:.2g}"
        raise ObservationError(f"not a rigid transform: the rotation block is not a rotation ({why})", field=name)
    if not np.allclose(T[3], [0, 0, 0, 1]):
        raise ObservationError("not a rigid transform: the last row is not [0, 0, 0, 1]", field=name)
    if np.max(np.abs(T[:3, 3])) > MAX_TRANSLATION_M:
        raise ObservationError(f"a translation of {np.max(np.abs(T[:3, 3])):.3g} m along an axis, more than the "
                               f"limit of {MAX_TRANSLATION_M:g} m (metres expected)", field=name)
    return T


def _covariance(value) -> np.ndarray:
    C = np.array(numeric_array(value, "covariance", (6, 6)))
    scale = float(np.max(np.abs(C))) or 1.0
    if np.max(np.abs(C - C.T)) > COVARIANCE_TOL * scale:
        raise ObservationError("not a covariance: not symmetric", field="covariance")
    if np.linalg.eigvalsh(C / scale)[0] < -COVARIANCE_TOL:
        raise ObservationError("not a covariance: a negative eigenvalue", field="covariance")
    return C


def _check_scalars(d: dict) -> None:
    if "ok" in d and not isinstance(d["ok"], bool):
        raise ObservationError(f"expected true or false, got {str(d['ok'])[:20]!r}", field="ok")
    for k in TEXT_FIELDS:
        if d.get(k) is not None and not isinstance(d[k], str):
            raise ObservationError(f"expected text, got {type(d[k]).__name__}", field=k)
    for k in NUMBER_FIELDS:
        if d.get(k) is not None and not _is_number(d[k]):
            raise ObservationError(f"expected a finite number, got {str(d[k])[:20]!r}", field=k)
    n = d.get("n_candidates")
    if n is not None and (isinstance(n, bool) or not isinstance(n, int) or n < 0):
        raise ObservationError(f"expected a count, got {str(n)[:20]!r}", field="n_candidates")
    if not isinstance(d.get("warnings", []), list) or not all(isinstance(w, str) for w in d.get("warnings", [])):
        raise ObservationError("expected a list of text lines", field="warnings")
    for k in DICT_FIELDS + NUMBER_DICTS:
        if d.get(k) is not None and not isinstance(d[k], dict):
            raise ObservationError(f"expected an object, got {type(d[k]).__name__}", field=k)
    for k in NUMBER_DICTS:
        for name, v in (d.get(k) or {}).items():
            if not _is_number(v):
                raise ObservationError(f"expected a finite number, got {str(v)[:20]!r}", field=f"{k}.{name}")
    stamp = d.get("observations")
    if stamp is not None and (isinstance(stamp.get("boards"), bool) or not isinstance(stamp.get("boards"), int)
                              or not isinstance(stamp.get("sha256"), str)):
        raise ObservationError("expected {\"boards\": a count, \"sha256\": text}", field="observations")
    for k, names in NESTED_NUMBERS.items():
        for name in names:
            if d.get(k) is not None and not _is_number(d[k].get(name)):
                raise ObservationError(f"expected a finite number, got {str(d[k].get(name))[:20]!r}",
                                       field=f"{k}.{name}")
    for k, names in OPTIONAL_NUMBERS.items():
        for name in names:
            v = (d.get(k) or {}).get(name)
            if v is not None and not _is_number(v):
                raise ObservationError(f"expected a finite number or null, got {str(v)[:20]!r}", field=f"{k}.{name}")
    _check_verdict(d.get("verdict"))


def _check_verdict(v) -> None:
    """The parts of ``verdict`` the readers take (``data.outcome.VerdictPart``); the rest is free-form."""
    if v is None:
        return
    if v.get("consistent") is not None and not isinstance(v["consistent"], bool):
        raise ObservationError("expected true, false or null", field="verdict.consistent")
    if v.get("reason") is not None and not isinstance(v["reason"], str):
        raise ObservationError("expected text or null", field="verdict.reason")
    for k in ("warnings", "causes"):
        if not isinstance(v.get(k, []), list) or not all(isinstance(w, str) for w in v.get(k, [])):
            raise ObservationError("expected a list of text lines", field=f"verdict.{k}")


def _check_boards(d: dict) -> None:
    used = d.get("boards_used")
    if used is not None:
        if not isinstance(used, list) or len(used) > MAX_BOARDS:
            raise ObservationError(f"expected a list of at most {MAX_BOARDS} board indices", field="boards_used")
        for i, v in enumerate(used):
            _board_index(v, f"boards_used[{i}]")
    rejected = d.get("boards_rejected") or []
    if not isinstance(rejected, list) or len(rejected) > MAX_BOARDS:
        raise ObservationError(f"expected a list of at most {MAX_BOARDS} objects", field="boards_rejected")
    for i, r in enumerate(rejected):
        if not isinstance(r, dict):
            raise ObservationError(f"expected an object, got {type(r).__name__}", field=f"boards_rejected[{i}]")
        _board_index(r.get("index"), f"boards_rejected[{i}].index")
        if not isinstance(r.get("reason", ""), str):
            raise ObservationError("expected text", field=f"boards_rejected[{i}].reason")
        if r.get("statistic") is not None and not _is_number(r["statistic"]):
            raise ObservationError("expected a finite number or null", field=f"boards_rejected[{i}].statistic")


def check_result_dict(d) -> dict:
    """``d`` (a parsed ``lidarcam.result/1`` file) checked, its matrices as numpy arrays (``T_cam_lidar`` the
    exact inverse of ``T_lidar_cam``); ObservationError naming the field otherwise (the caller adds the file)."""
    if not isinstance(d, dict):
        raise ObservationError(f"expected a JSON object at the top, got {type(d).__name__}")
    _check_scalars(d)
    _check_boards(d)
    T = d.get("T_lidar_cam")
    if T is None and d.get("ok"):
        raise ObservationError("missing: an ok result carries its extrinsic", field="T_lidar_cam")
    if T is not None:
        d["T_lidar_cam"] = _transform(T, "T_lidar_cam")
        if d.get("T_cam_lidar") is not None:
            Ti = _transform(d["T_cam_lidar"], "T_cam_lidar")
            if np.max(np.abs(Ti @ d["T_lidar_cam"] - np.eye(4))) > INVERSE_TOL:
                raise ObservationError("not the inverse of T_lidar_cam (the file's two directions disagree)",
                                       field="T_cam_lidar")
        d["T_cam_lidar"] = invert_T(d["T_lidar_cam"])
    elif d.get("T_cam_lidar") is not None:
        raise ObservationError("given without T_lidar_cam", field="T_cam_lidar")
    if d.get("covariance") is not None:
        d["covariance"] = _covariance(d["covariance"])
    return d
