"""Evaluation of methods on one real rig without ground truth: full fit, leave-one-pose-out residual
(``calib_core.crossval``), agreement with a published result, time, and the degeneracy verdict
(``calib_core.checks.degeneracy``).
"""

from __future__ import annotations

import math

import numpy as np

import calib_core
from calib_core.checks.degeneracy import undetermined_directions
from calib_core.crossval import leave_one_out
from calib_core.data.lines import scan_noise_estimate
from calib_core.data.observations import Observations
from calib_core.geometry.metrics import pose_errors
from calib_core.geometry.mounting import UNIT_NAMES
from calib_core.geometry.transforms import invert_T
from rig.markdown import md_table, num
from rig.report import board_plane_distances as plane_distances


def range_noise_m(obs: Observations) -> float:
    """Range-noise std (m) from the scan lines alone (no extrinsic): the library's estimate."""
    return float(scan_noise_estimate(obs))


def held_out(obs: Observations, method: str, sigma_m: float, **options) -> dict:
    """Leave-one-pose-out: pooled RMS of the held-out poses' point-to-plane distances (mm and in units of the
    range noise), folds that failed, seconds."""
    cv = leave_one_out(obs, method, range_sigma_m=sigma_m, **options)
    return {"rms_mm": cv.overall_rms_mm, "rms_sigmas": cv.overall_rms_sigmas, "n_ok": cv.n_ok,
            "n": len(cv.names), "seconds": cv.seconds, "source": "calib_core.crossval", "folds": cv.T_lidar_cam}


def in_sample_rms_mm(obs: Observations, T_lidar_cam: np.ndarray) -> float:
    """RMS point-to-plane distance of every board's points through ``T_lidar_cam`` (mm)."""
    Ti = invert_T(T_lidar_cam)
    e = np.concatenate([plane_distances(Ti, b.T_cam_board, b.scan) for b in obs.boards])
    return 1000 * float(np.sqrt(np.mean(e ** 2)))


def leaderboard(obs: Observations, methods, sigma_m: float, published: np.ndarray | None = None,
                cv: bool = True, options: dict | None = None) -> list[dict]:
    """One row per method: ok / reason, seconds, in-sample RMS, 1-sigma, agreement with ``published``
    (deg, mm), held-out RMS (mm, sigmas). ``options``: per-method keyword arguments."""
    rows = []
    for m in methods:
        opts = (options or {}).get(m, {})
        res = calib_core.calibrate(obs, m, **opts)
        row = {"method": m, "ok": res.ok, "reason": res.reason, "seconds": res.seconds,
               "T_lidar_cam": None if not res.ok else res.T_lidar_cam.tolist(),
               "sigma_rot_deg": res.sigma_rot_deg if res.ok else None,
               "sigma_trans_mm": res.sigma_trans_mm if res.ok else None}
        if res.ok:
            row["fit_rms_mm"] = in_sample_rms_mm(obs, res.T_lidar_cam)
            if published is not None:
                e_R, e_t = pose_errors(res.T_lidar_cam, published)
                row["vs_published_deg"], row["vs_published_mm"] = float(e_R), 1000 * float(e_t)
        if cv:
            row["cv"] = held_out(obs, m, sigma_m, **opts)
            folds = row["cv"].pop("folds", None)
            if res.ok and folds is not None:
                row.update(loo_spread(res, folds))
        rows.append(row)
        print(f"  {m}: ok={res.ok} {res.seconds:.2f} s" + (f", held-out {row['cv']['rms_mm']:.1f} mm"
                                                            if cv else ""), flush=True)
    return rows


def loo_spread(res, folds: np.ndarray) -> dict:
    """The leave-one-out (jackknife) 1-sigma of the answer (rotation deg, translation mm: roots of the traces, as
    the reported ones) and its ratio to the reported 1-sigma (> 1: the reported sigma is too small)."""
    from calib_core.crossval import jackknife_covariance
    from calib_core.geometry.metrics import sigma_rot_deg, sigma_trans_m

    cov = jackknife_covariance(res.T_lidar_cam, folds)
    if cov is None:
        return {}
    out = {"loo_sigma_rot_deg": sigma_rot_deg(cov), "loo_sigma_trans_mm": 1000 * sigma_trans_m(cov),
           "covariance_model": (res.info or {}).get("covariance_model")}
    if res.sigma_rot_deg:
        out["loo_ratio_rot"] = out["loo_sigma_rot_deg"] / res.sigma_rot_deg
        out["loo_ratio_trans"] = out["loo_sigma_trans_mm"] / res.sigma_trans_mm
    return out


def uncertainty_md(rows: list[dict]) -> list[str]:
    """Markdown: per method with a covariance, the reported 1-sigma against the leave-one-out spread."""
    body = [[f"`{r['method']}`", r.get("covariance_model") or "-",
             f"{num(r['sigma_rot_deg'], '.3f')} / {num(r['sigma_trans_mm'], '.1f')}",
             f"{num(r['loo_sigma_rot_deg'], '.3f')} / {num(r['loo_sigma_trans_mm'], '.1f')}",
             f"{num(r['loo_ratio_rot'], '.2f')} / {num(r['loo_ratio_trans'], '.2f')}"]
            for r in rows if r.get("loo_ratio_rot") is not None]
    if not body:
        return []
    out = md_table(["method", "covariance model", "reported 1-sigma rot (deg) / trans (mm)", "leave-one-out 1-sigma",
                    "ratio rot / trans"], body, "llrrr")
    off = [f"`{r['method']}`'s reported 1-sigma is {r['loo_ratio_rot']:.1f} x too small in rotation and "
           f"{r['loo_ratio_trans']:.1f} x in translation on this data (the leave-one-out answers scatter more than its "
           "noise model predicts: errors it does not hold, such as intrinsics taken as exact or range biases, make up "
           "the difference)" for r in rows if r.get("loo_ratio_rot") is not None
           and max(r["loo_ratio_rot"], r["loo_ratio_trans"]) > 1.5]
    out += [""] + [f"- {o}." for o in off] if off else []
    return out + ["", "Leave-one-out 1-sigma: the jackknife spread of the fold answers, "
                  "`(n-1)/n sum (x_i - mean)^2` over the poses left out (`calib_core.crossval.jackknife_covariance`); "
                  "ratio = leave-one-out / reported (within 1.5 of 1: the reported sigma holds on this data)."]


def degeneracy_verdict(obs: Observations, T_lidar_cam: np.ndarray, sigma_m: float) -> tuple[str, bool | None]:
    """(one sentence, determined?) from the library's information-matrix analysis."""
    d = undetermined_directions(obs, T_lidar_cam, sigma_m)
    return d.message(), d.determined


def leaderboard_md(rows: list[dict], sigma_m: float, published: bool) -> list[str]:
    """The leaderboard as a Markdown table, best held-out residual first."""
    def key(r):
        v = (r.get("cv") or {}).get("rms_mm")
        return (0, v) if v is not None and math.isfinite(v) else (1, 0.0)

    head = ["method", "ok", "held-out RMS (mm)", "held-out (x noise)", "folds ok", "fit RMS (mm)",
            "1-sigma rot (deg) / trans (mm)", *(["vs published (deg / mm)"] if published else []), "time (s)"]
    body = []
    for r in sorted(rows, key=key):
        cv = r.get("cv") or {}
        cells = [f"`{r['method']}`", "yes" if r["ok"] else f"no: {r['reason']}", num(cv.get("rms_mm"), ".1f"),
                 num(cv.get("rms_sigmas"), ".2f"), f"{cv.get('n_ok', '-')}/{cv.get('n', '-')}",
                 num(r.get("fit_rms_mm"), ".1f"),
                 f"{num(r.get('sigma_rot_deg'), '.2f')} / {num(r.get('sigma_trans_mm'), '.1f')}"]
        if published:
            cells.append(f"{num(r.get('vs_published_deg'), '.3f')} / {num(r.get('vs_published_mm'), '.2f')}")
        cells.append(num(r["seconds"] + cv.get("seconds", 0.0), ".2f"))
        body.append(cells)
    out = md_table(head, body, "ll" + "r" * (len(head) - 2))
    out += ["", f"Range noise (from the scan lines, no extrinsic): {1000 * sigma_m:.1f} mm. Held-out: each pose "
            "calibrated from the others, its scan points against its board plane from the camera; time: the full "
            "fit plus every fold."]
    return out


def planar_calibration(obs: Observations, verdict_axes, given: dict | None = None
                       ) -> tuple[list[str], np.ndarray | None]:
    """(Markdown lines, T_lidar_cam or None): ``lidarcam`` with the undetermined mounting parameters fixed
    (``calibrate(..., fixed=)``; ``given`` values, else 0) and the estimated ones with their 1-sigma."""
    names = [f"{a}_deg" if f"{a}_deg" in UNIT_NAMES else f"{a}_m" for a in verdict_axes]
    fixed = {n: (given or {}).get(n, 0.0) for n in names}
    res = calib_core.calibrate(obs, "lidarcam", fixed=fixed)
    if not res.ok:
        return [f"Calibration with {fixed} fixed failed: {res.reason}"], None
    info = res.info or {}
    val, sig = info.get("mounting", {}), info.get("mounting_sigma", {})
    cells = ", ".join(f"{n} = {val[n]:.3f} +- {sig[n]:.3f}" for n in UNIT_NAMES if n in sig)
    fixed_txt = ", ".join(f"{k} = {v:g}" for k, v in fixed.items())
    return [f"`lidarcam` with {fixed_txt} fixed (not measured for this rig: placeholders for the mounting a "
            f"user measures; the estimated parameters do not depend on them here): {cells} (1-sigma).",
            *(f"- warning: {w}" for w in info.get("warnings", []))], res.T_lidar_cam
