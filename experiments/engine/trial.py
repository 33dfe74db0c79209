"""One Monte-Carlo trial: one simulated problem, every configured method run on that same data, one row per
method with its metric columns (errors, validity, candidates, CRLB, NEES, boards rejected).

A bad draw never kills a cell: an exception from the simulator or a method becomes rows with ``ok=False``
and the reason (a ``CalibrationError`` -- unknown method or option -- is a configuration error and raised).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from calib_core import CalibrationError, calibrate, get_method
from calib_core.geometry.metrics import is_valid, nees, pose_errors
from calib_core.refine.joint import corner_residuals, joint_crlb
from calib_core.refine.uncertainty import conditioning, crlb

from .cell import Cell


def _failure_row(base: dict, method: str, reason: str) -> dict:
    return {**base, "method": method, "ok": False, "reason": reason, "e_R_deg": np.nan, "e_t_m": np.nan,
            "valid": False, "n_candidates": 0, "true_among_candidates": False, "some_candidate_valid": False,
            "best_candidate_e_R_deg": np.nan, "best_candidate_e_t_m": np.nan, "seconds": np.nan,
            "nees": np.nan, "sigma_rot_deg": np.nan, "sigma_trans_mm": np.nan}


def evaluate(result, T_true: np.ndarray, metrics: dict[str, Any]) -> dict[str, Any]:
    """The metric columns of one ``CalibrationResult`` against the true ``T_lidar_cam``."""
    row: dict[str, Any] = {"ok": bool(result.ok), "reason": result.reason or "", "seconds": float(result.seconds),
                           "n_candidates": result.n_candidates, "e_R_deg": np.nan, "e_t_m": np.nan,
                           "valid": False, "true_among_candidates": False, "some_candidate_valid": False,
                           "best_candidate_e_R_deg": np.nan, "best_candidate_e_t_m": np.nan,
                           "nees": np.nan, "sigma_rot_deg": np.nan, "sigma_trans_mm": np.nan}
    if result.ok:
        e_R, e_t = pose_errors(result.T_lidar_cam, T_true)
        row.update(e_R_deg=float(e_R), e_t_m=float(e_t),
                   valid=bool(is_valid(e_R, e_t, metrics["max_rot_deg"], metrics["max_trans_m"])))
        if result.covariance is not None:
            row.update(nees=nees(result.T_lidar_cam, T_true, result.covariance),
                       sigma_rot_deg=result.sigma_rot_deg, sigma_trans_mm=result.sigma_trans_mm)
    if result.n_candidates:
        cR, ct = pose_errors(result.candidates, T_true)
        best = int(np.nanargmin(cR)) if np.isfinite(cR).any() else 0
        row.update(best_candidate_e_R_deg=float(cR[best]), best_candidate_e_t_m=float(ct[best]),
                   true_among_candidates=bool(np.any((cR < metrics["truth_rot_deg"])
                                                     & (ct < metrics["truth_trans_m"]))),
                   some_candidate_valid=bool(np.any(is_valid(cR, ct, metrics["max_rot_deg"],
                                                             metrics["max_trans_m"]))))
    return row


def rejection_columns(result, wrong_boards: Sequence[int]) -> dict[str, Any]:
    """Boards the method left out: how many (NaN for methods that do not report it, or when it failed), how many
    of the simulated wrong boards it caught, how many good boards it lost."""
    out: dict[str, Any] = {"n_wrong": len(wrong_boards), "n_rejected": np.nan, "wrong_caught": np.nan,
                           "good_lost": np.nan}
    if result.ok and result.boards_used is not None:
        rej = {int(r["index"]) for r in result.boards_rejected}
        wrong = {int(i) for i in wrong_boards}
        out.update(n_rejected=len(rej), wrong_caught=len(rej & wrong), good_lost=len(rej - wrong))
    return out


def corner_sigma_px(obs, sim: dict) -> float | None:
    """The corner noise std (px) of a simulated trial with image corners: ``pixel_noise_px`` in ``pixel`` mode, the
    RMS detection error against the true poses in ``image`` mode; None without corners or true poses."""
    if not obs.has_corners or "T_cam_board_true" not in obs.meta:
        return None
    from simulate import SimOptions

    o = SimOptions(**sim)
    if o.pose_mode == "pixel":
        return o.pixel_noise_px
    e = corner_residuals(obs, np.asarray(obs.meta["T_cam_board_true"], float))
    return float(np.sqrt(np.mean(e**2)))


def uncertainty_columns(obs, cell: Cell) -> dict[str, float]:
    """CRLB of the rotation (deg) and translation (mm) at the trial's noise, and the conditioning number.

    With image corners the bound is that of the joint model (range and corner noise, board poses unknown, at the
    true poses; ``corner_sigma_px``), else that of the range model (board poses exact)."""
    out = {"crlb_rot_deg": np.nan, "crlb_trans_mm": np.nan, "conditioning": np.nan}
    if not cell.metrics.get("uncertainty", True):
        return out

    sigma_mm = cell.metrics.get("crlb_sigma_mm")
    sigma_mm = cell.sim.get("noise_mm", 0.0) if sigma_mm is None else sigma_mm
    try:
        px = corner_sigma_px(obs, cell.sim)
        if px is None:
            bound = crlb(obs, range_sigma_m=float(sigma_mm) / 1000.0)
        else:
            bound = joint_crlb(obs, float(sigma_mm) / 1000.0, px, T_cam_board=np.asarray(obs.meta["T_cam_board_true"]))
        out.update(crlb_rot_deg=float(bound.rot_rms_deg), crlb_trans_mm=1000.0 * float(bound.trans_rms_m))
    except Exception:  # noqa: BLE001 -- a degenerate board set has no bound: NaN, not a dead cell
        pass
    try:
        out["conditioning"] = float(conditioning(obs))
    except Exception:  # noqa: BLE001
        pass
    return out


def simulate_trial(cell: Cell, trial: int, methods: Sequence[str]) -> list[dict[str, Any]]:
    """Simulate trial ``trial`` of ``cell`` once and run every method in ``methods`` on it: one row each."""
    from simulate import SimOptions, generate

    base = {**cell.columns(), "trial": int(trial), "crlb_rot_deg": np.nan, "crlb_trans_mm": np.nan,
            "conditioning": np.nan, "n_wrong": 0, "n_rejected": np.nan, "wrong_caught": np.nan, "good_lost": np.nan}
    try:
        obs = generate(SimOptions(**cell.sim), seed=cell.seed, trial=int(trial), stream=cell.crn_stream)
    except Exception as exc:  # noqa: BLE001 -- a bad draw is a status, not a crash
        return [_failure_row(base, m, f"simulate: {type(exc).__name__}: {exc}") for m in methods]
    base.update(uncertainty_columns(obs, cell))
    rows = []
    for m in methods:
        try:
            # the verdict decides ok for our methods; for the paper's it is a warning no column reads
            res = calibrate(obs, m, verdict=not get_method(m).paper, **cell.options_for(m))
        except CalibrationError:
            raise  # unknown method or option: the configuration is wrong, every trial would fail
        except Exception as exc:  # noqa: BLE001
            rows.append(_failure_row(base, m, f"error: {type(exc).__name__}: {exc}"))
            continue
        rows.append({**base, "method": m, **evaluate(res, obs.T_lidar_cam_true, cell.metrics),
                     **rejection_columns(res, obs.meta.get("wrong_boards", []))})
    return rows


TrialFn = Callable[[Cell, int, Sequence[str]], list[dict[str, Any]]]
