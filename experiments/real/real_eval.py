"""Evaluation of methods on one real rig without ground truth: full fit, leave-one-pose-out residual
(``calib_core.evaluate.crossval``), agreement with a published result, time, and the degeneracy verdict
(``calib_core.checks.degeneracy``).
"""

from __future__ import annotations

import math

import numpy as np

import calib_core
from calib_core.checks.degeneracy import undetermined_directions
from calib_core.data.observations import Observations
from calib_core.evaluate.crossval import leave_one_out
from calib_core.geometry.metrics import pose_errors
from calib_core.geometry.mounting import UNIT_NAMES
from calib_core.geometry.transforms import invert_T
from lidarcam.rig.markdown import md_table, num
from lidarcam.rig.report import board_plane_distances as plane_distances


def held_out(obs: Observations, method: str, sigma_m: float, **options) -> dict:
    """Leave-one-pose-out: pooled RMS of the held-out poses' point-to-plane distances (mm and in units of the
    range noise), the joint held-out residual (corners and scan, board pose re-estimated; in noise units and its
    scan part in mm), the held-out residuals in units of their predicted spread, folds that failed, seconds."""
    cv = leave_one_out(obs, method, range_sigma_m=sigma_m, **options)
    d = cv.to_dict()
    return {"rms_mm": cv.overall_rms_mm, "rms_sigmas": cv.overall_rms_sigmas, "n_ok": cv.n_ok,
            "n": len(cv.names), "seconds": cv.seconds, "source": "calib_core.evaluate.crossval",
            "joint_rms_sigmas": d["joint_rms_sigmas"], "joint_scan_rms_mm": d["joint_scan_rms_mm"],
            "corner_sigma_px": cv.corner_sigma_px, "range_sigma_mm": 1000 * cv.range_sigma_m, "spread": d["spread"],
            "spread_scan_noise": d["spread_scan_noise"], "folds": cv.T_lidar_cam}


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
                row.update(explained_sigma(obs, res, row["cv"], sigma_m))
        rows.append(row)
        if cv:
            c = row["cv"]
            held = (f", held-out {num(c['rms_mm'], '.1f')} mm" if math.isfinite(c["rms_mm"])
                    else f", held-out none ({c.get('n_ok', 0)} of {c.get('n', '?')} folds solved)")
        print(f"  {m}: ok={res.ok} {res.seconds:.2f} s" + (held if cv else ""), flush=True)
    return rows


def loo_spread(res, folds: np.ndarray) -> dict:
    """The leave-one-out (jackknife) 1-sigma of the answer (rotation deg, translation mm: roots of the traces, as
    the reported ones) and its ratio to the reported 1-sigma (> 1: the reported sigma is too small)."""
    from calib_core.evaluate.crossval import jackknife_covariance
    from calib_core.geometry.metrics import sigma_rot_deg, sigma_trans_m

    cov = jackknife_covariance(res.T_lidar_cam, folds)
    if cov is None:
        return {}
    out = {"loo_sigma_rot_deg": sigma_rot_deg(cov), "loo_sigma_trans_mm": 1000 * sigma_trans_m(cov),
           "covariance_model": (res.info or {}).get("covariance_model"),
           "board_dispersion": (res.info or {}).get("board_dispersion")}
    if res.sigma_rot_deg:
        out["loo_ratio_rot"] = out["loo_sigma_rot_deg"] / res.sigma_rot_deg
        out["loo_ratio_trans"] = out["loo_sigma_trans_mm"] / res.sigma_trans_mm
    return out


def explained_sigma(obs: Observations, res, cv: dict, sigma_m: float) -> dict:
    """The 1-sigma (rotation deg, translation mm) of the joint model at ``res``'s answer with the range noise of
    the scan lines (``sigma_m``) and the board poses' sigmas scaled by the factor that makes the held-out residuals
    agree with their predicted spread (``cv["spread_scan_noise"]["board_factor"]``; ``held_out.spread_summary``);
    {} where that factor or the joint model does not apply."""
    from calib_core.errors import UncertaintyError
    from calib_core.geometry.metrics import sigma_rot_deg, sigma_trans_m
    from calib_core.refine.joint import board_poses, marginal_covariance

    k = (cv.get("spread_scan_noise") or {}).get("board_factor")
    s_c = (res.info or {}).get("corner_sigma_px")
    if k is None or s_c is None or not obs.has_corners:
        return {}
    try:
        cov = marginal_covariance(obs, res.T_lidar_cam, board_poses(obs), k * s_c, sigma_m)
    except (UncertaintyError, np.linalg.LinAlgError):
        return {}
    return {"board_factor": k, "explained_sigma_rot_deg": sigma_rot_deg(cov),
            "explained_sigma_trans_mm": 1000 * sigma_trans_m(cov)}


def uncertainty_md(rows: list[dict]) -> list[str]:
    """Markdown: per method with a covariance, the reported 1-sigma against the leave-one-out spread, the held-out
    residuals in units of their predicted spread, and where the reported sigma is off, by how much and why."""
    rows = [r for r in rows if r.get("loo_ratio_rot") is not None]
    if not rows:
        return []
    body = []
    for r in rows:
        sp = (r.get("cv") or {}).get("spread") or {}
        d = r.get("board_dispersion") or {}
        body.append([f"`{r['method']}`", r.get("covariance_model") or "-",
                     (f"{d['statistic']:.1f} / {d['dof']} (p {d['p_value']:.0e}): "
                      + ("widened" if d["widened"] else "model's")) if d else "-",
                     f"{num(r['sigma_rot_deg'], '.3f')} / {num(r['sigma_trans_mm'], '.1f')}",
                     f"{num(r['loo_sigma_rot_deg'], '.3f')} / {num(r['loo_sigma_trans_mm'], '.1f')}",
                     f"{num(r['loo_ratio_rot'], '.2f')} / {num(r['loo_ratio_trans'], '.2f')}",
                     f"{num(sp.get('rms_z'), '.2f')} / {num(sp.get('q90_ratio'), '.2f')} / "
                     f"{num(sp.get('chi2_per_point'), '.2f')}"])
    out = md_table(["method", "covariance model", "boards' dispersion / dof: covariance",
                    "reported 1-sigma rot (deg) / trans (mm)", "leave-one-out 1-sigma", "ratio rot / trans",
                    "held-out z: RMS / q90 / chi2 per point"], body, "lllrrrr")
    off = [why_off(r) for r in rows if max(r["loo_ratio_rot"], r["loo_ratio_trans"]) > 1.5]
    out += [""] + [f"- {o}" for o in off] if off else []
    return out + ["", "Boards' dispersion: the chi-square test of how the boards pull on the extrinsic, in units "
                  "of the noise each sensor shows alone (`calib_core.refine.dispersion`, docs/lidarcam.md); where it "
                  "fails at 1% the reported covariance is widened to the boards' spread (the larger of the model's "
                  "times the dispersion ratio and the boards' one-step jackknife), else it is the model's.",
                  "", "Leave-one-out 1-sigma: the jackknife spread of the fold answers, "
                  "`(n-1)/n sum (x_i - mean)^2` over the poses left out "
                  "(`calib_core.evaluate.crossval.jackknife_covariance`); "
                  "ratio = leave-one-out / reported (within 1.5 of 1: the reported sigma holds on this data). "
                  "Held-out z: each held-out scan point's range residual (against its board plane from the camera, "
                  "through the fold's extrinsic) over its predicted std, range noise as the fold's model estimates it "
                  "+ the fold's extrinsic covariance + the board pose's from its corners "
                  "(`calib_core.evaluate.held_out`); RMS, "
                  "90% quantile of |z| over the Gaussian's 1.645, and the Mahalanobis statistic per point over each "
                  "board's correlated points: all 1 when the model's spread holds."]


def why_off(r: dict) -> str:
    """One sentence: by how much ``r``'s reported 1-sigma is off, and what the held-out residuals say about why."""
    cv = r.get("cv") or {}
    sp, sl = cv.get("spread") or {}, cv.get("spread_scan_noise") or {}
    head = (f"`{r['method']}`'s reported 1-sigma is {r['loo_ratio_rot']:.1f} x too small in rotation and "
            f"{r['loo_ratio_trans']:.1f} x in translation against the leave-one-out spread. ")
    if not sp:
        return head + "No held-out residuals in units of a predicted spread (no covariance in the folds)."
    size = (f"Its held-out residuals in units of their predicted spread have chi2 per point "
            f"{sp['chi2_per_point']:.2f}: a factor {sp['inflation']:.2f} on every predicted sigma would make them "
            "agree. ")
    if r.get("board_factor") is not None and r["board_factor"] > 1:
        k_rot = r["loo_sigma_rot_deg"] / r["explained_sigma_rot_deg"]
        k_tr = r["loo_sigma_trans_mm"] / r["explained_sigma_trans_mm"]
        return head + size + (
            f"With the range noise of the scan lines ({cv.get('range_sigma_mm', 0):.1f} mm, the scatter within a "
            f"board) they agree when the board poses' sigmas are {r['board_factor']:.1f} x those their corners give "
            "(camera-side error the corner noise does not hold, such as intrinsics taken as exact; the fold's own "
            "range noise absorbs it as if independent per point, and averages it down). The joint model with "
            f"that factor gives 1-sigma {r['explained_sigma_rot_deg']:.2f} deg / "
            f"{r['explained_sigma_trans_mm']:.1f} mm, against the leave-one-out {r['loo_sigma_rot_deg']:.2f} / "
            f"{r['loo_sigma_trans_mm']:.1f} (ratio {k_rot:.2f} / {k_tr:.2f})."
            + (" The rest is not explained by the held-out residuals." if max(k_rot, k_tr) > 1.5 else ""))
    if sl and sl.get("board_factor") is None:   # no factor within the search explains them
        return head + size + (
            f"With the range noise of the scan lines ({cv.get('range_sigma_mm', 0):.1f} mm) no factor on the board "
            f"poses' sigmas explains them: with the poses free the statistic stays at {sl['chi2_boards_free']:.2f}, "
            "so the excess is within each board's scan, beyond any plane the board could take (a range error "
            "that varies along the scan, such as a bearing- or incidence-dependent bias, or a board that is not "
            "flat), which neither the range noise nor the board pose holds.")
    return head + size + ("The held-out boards, one at a time, show no unmodelled error of the size the "
                          "leave-one-out spread needs: the excess is not explained by the held-out residuals.")


def degeneracy_note(obs: Observations, T_lidar_cam: np.ndarray, sigma_m: float) -> tuple[str, bool | None]:
    """(one sentence, determined?) from the library's information-matrix analysis."""
    d = undetermined_directions(obs, T_lidar_cam, sigma_m)
    return d.message(), d.determined


def leaderboard_md(rows: list[dict], sigma_m: float, published: bool) -> list[str]:
    """The leaderboard as a Markdown table, best held-out residual first."""
    def key(r):
        v = (r.get("cv") or {}).get("rms_mm")
        return (0, v) if v is not None and math.isfinite(v) else (1, 0.0)

    joint = any((r.get("cv") or {}).get("joint_rms_sigmas") is not None for r in rows)
    head = ["method", "ok", "held-out RMS (mm)", "held-out (x noise)",
            *(["held-out joint (x noise) / its scan (mm)"] if joint else []), "folds ok", "fit RMS (mm)",
            "1-sigma rot (deg) / trans (mm)", *(["vs published (deg / mm)"] if published else []), "time (s)"]
    body = []
    for r in sorted(rows, key=key):
        cv = r.get("cv") or {}
        cells = [f"`{r['method']}`", "yes" if r["ok"] else f"no: {r['reason']}", num(cv.get("rms_mm"), ".1f"),
                 num(cv.get("rms_sigmas"), ".2f"),
                 *([f"{num(cv.get('joint_rms_sigmas'), '.2f')} / {num(cv.get('joint_scan_rms_mm'), '.1f')}"]
                   if joint else []), f"{cv.get('n_ok', '-')}/{cv.get('n', '-')}",
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
    if joint:
        s_c = next(r["cv"]["corner_sigma_px"] for r in rows if (r.get("cv") or {}).get("corner_sigma_px"))
        out += ["", "Held-out joint: the held-out pose's board pose re-estimated from its corners and its scan with "
                "the fold's extrinsic held, then the RMS of its corner and range residuals, each over its noise (range "
                f"as above, corners {s_c:.2f} px from the boards' own pose fits; 1 = the noise), and the RMS of its "
                "range residuals (mm). It scores the extrinsic on both sensors rather than on the camera's plane "
                "alone, the quantity `zhang_pless` minimises."]
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
