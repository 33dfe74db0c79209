"""Calibration report of a real rig: scan-on-image overlays (``lidarcam.rig.overlay``), residual plots per board and
``report.md``.

Plots use matplotlib's Agg canvas directly (no pyplot, no global backend change).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib_core.checks.degeneracy import degeneracy_warnings, pair_angle_deg
from calib_core.data.observations import Observations
from calib_core.data.result import JSON_INFO, CalibrationResult
from calib_core.errors import LidarcamError
from calib_core.geometry.metrics import pose_errors, sigma_rot_deg, sigma_trans_m
from calib_core.geometry.transforms import invert_T, quaternion_xyzw
from calib_core.refine.uncertainty import normal_spread_deg

from .dataset import Dataset
from .markdown import md_table, num
from .overlay import board_plane_distances, draw_overlay, overlay_clim_mm, project_scan, save_overlay

OUTLIER_FACTOR = 3.0


@dataclass
class ReportSummary:
    """What ``write_report`` wrote and found: file paths, per-board residual RMS (mm), warnings."""

    markdown: Path
    overlays: list[Path] = field(default_factory=list)
    residual_plots: list[Path] = field(default_factory=list)
    board_rms_mm: list[float] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def _result_object(result) -> CalibrationResult:
    """A CalibrationResult, a ``load_result`` dict or a path -> the CalibrationResult."""
    if isinstance(result, CalibrationResult):
        return result
    return CalibrationResult.load(result) if isinstance(result, (str, Path)) else CalibrationResult.from_dict(result)


def _as_result(result) -> dict:
    """A CalibrationResult, a ``load_result`` dict or a path -> dict with method, ok, reason, T, covariance."""
    if isinstance(result, (str, Path)):
        from calib_core.data.result import load_result

        result = load_result(result)
    if isinstance(result, CalibrationResult):
        return {"method": result.method, "ok": result.ok, "reason": result.reason,
                "T_lidar_cam": result.T_lidar_cam, "covariance": result.covariance,
                "covariance_model": result.info.get("covariance_model"), **{k: result.info.get(k) for k in JSON_INFO},
                "boards_rejected": result.boards_rejected, "warnings": result.warnings}
    return {"method": result.get("method", "?"), "ok": bool(result.get("ok")), "reason": result.get("reason"),
            "T_lidar_cam": result.get("T_lidar_cam"), "covariance": result.get("covariance"),
            "covariance_model": result.get("covariance_model"), **{k: result.get(k) for k in JSON_INFO},
            "boards_rejected": result.get("boards_rejected") or [], "warnings": result.get("warnings") or []}


def report_warnings(observations: Observations, rms_mm: list[float], T_lidar_cam: np.ndarray | None = None
                    ) -> list[str]:
    """Warnings on a board set and its residuals: the library's board-set warnings
    (``calib_core.checks.degeneracy.degeneracy_warnings``, one set of thresholds) and outlier boards."""
    out = degeneracy_warnings(observations, T_lidar_cam)
    finite = [r for r in rms_mm if math.isfinite(r)]
    if finite:
        med = float(np.median(finite))
        for i, r in enumerate(rms_mm):
            if math.isfinite(r) and med > 0 and r > OUTLIER_FACTOR * med:
                out.append(f"board {i}: residual RMS {r:.1f} mm > {OUTLIER_FACTOR:g} x the median ({med:.1f} mm); "
                           "check its scan segment and board detection")
    return out


def capture_verdict(observations: Observations, T_lidar_cam: np.ndarray | None = None) -> str:
    """The capture planner's verdict on the boards captured (``calib_core.planning.observed``) at ``T_lidar_cam``
    (None: the ``lidarcam`` calibration of the boards), with the noise it assumed."""
    from calib_core import calibrate
    from calib_core.planning.capture import verdict
    from calib_core.planning.observed import plan_from_observations

    info = None
    try:
        if T_lidar_cam is None:
            res = calibrate(observations)
            if not res.ok:
                return f"no plan: the calibration failed ({res.reason})"
            T_lidar_cam, info = res.T_lidar_cam, res.info
        p = plan_from_observations(observations, T_lidar_cam, 2, info=info)
    except (LidarcamError, ValueError) as err:
        return f"no plan: {err}"
    return (f"{verdict(p.plan)}. (Assumed noise: range {1000 * p.range_sigma_m:.1f} mm, corners "
            f"{p.corner_sigma_px:.2g} px; `lidarcam plan --from OBS.json` gives the whole plan.)")


def _mounting_md(res: dict) -> list[str]:
    """The mounting parameters of a calibration with fixed parameters (``calib_core.refine.partial``), as a table."""
    if not res.get("mounting"):
        return []
    sig, fixed = res.get("mounting_sigma") or {}, res.get("fixed") or {}
    rows = [[k, f"{v:.4f}", "given (fixed)" if k in fixed else f"{sig[k]:.4f}" if k in sig else "-"]
            for k, v in res["mounting"].items()]
    return ["### Mounting parameters", "", "The camera's pose in the lidar frame (`geometry.mounting`: x, y, z "
            "the camera centre; roll, pitch, yaw of its body frame, Z-Y-X). " + str(res.get("note") or ""), ""
            ] + md_table(["parameter", "value", "1-sigma"], rows, "lrr") + [""]


def _pose_name(observations: Observations, i: int) -> str:
    names = observations.meta.get("poses") if observations.meta else None
    return str(names[i]) if names and i < len(names) else f"{i:03d}"


def _residual_plot(path: Path, bearing_deg: np.ndarray, dist_mm: np.ndarray, title: str) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5.0, 3.0), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(111)
    rms = float(np.sqrt(np.mean(dist_mm ** 2)))
    ax.axhspan(-rms, rms, color="0.9", label=f"+-RMS {rms:.1f} mm")
    ax.axhline(0, color="0.4", lw=0.8)
    ax.plot(bearing_deg, dist_mm, ".", ms=4, color="C0", label="scan point")
    ax.set_xlabel("bearing (deg)")
    ax.set_ylabel("point-to-plane (mm)")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    fig.subplots_adjust(left=0.15, right=0.97, bottom=0.16, top=0.9)
    fig.savefig(path, pil_kwargs={"compress_level": 1})


def _fmt_row(v) -> str:
    return ", ".join(f"{x: .6f}" for x in v)


def _extrinsic_md(res: dict, T: np.ndarray, Ti: np.ndarray) -> list[str]:
    """The extrinsic both ways (matrix, quaternion, translation, angle) and its 1-sigma, as markdown lines."""
    md = ["## Extrinsic", "", "`T_a_b` maps points of frame b into frame a; metres. Lidar: scan plane z = 0, "
          "x forward. Camera: z optical axis, y down.", ""]
    for name, M, what in (("T_lidar_cam", T, "camera points into the lidar frame (p_L = R p_C + t)"),
                          ("T_cam_lidar", Ti, "lidar points into the camera frame (used for the overlays)")):
        q = quaternion_xyzw(M[:3, :3])
        md += [f"### {name}: maps {what}", "", "```"] + [_fmt_row(r) for r in M] + ["```", "",
               f"- quaternion (x, y, z, w): [{_fmt_row(q)}]",
               f"- translation (m): [{_fmt_row(M[:3, 3])}]",
               f"- rotation angle: {math.degrees(math.acos(np.clip((np.trace(M[:3, :3]) - 1) / 2, -1, 1))):.3f} deg,"
               f" |t| = {np.linalg.norm(M[:3, 3]):.4f} m", ""]
    cov = res.get("covariance")
    if cov is None:
        return md + ["No covariance in the result: no 1-sigma figures.", ""]
    cov = np.asarray(cov, float)
    sr = np.degrees(np.sqrt(np.diag(cov)[:3]))
    st = 1000 * np.sqrt(np.diag(cov)[3:])
    return md + ["### Uncertainty (1 sigma)", "",
                 f"- rotation: {sigma_rot_deg(cov):.3f} deg overall; per axis (lidar frame, x y z): "
                 f"{', '.join(f'{v:.3f}' for v in sr)} deg",
                 f"- translation of T_lidar_cam: {1000 * sigma_trans_m(cov):.1f} mm overall; per axis (x y z): "
                 f"{', '.join(f'{v:.1f}' for v in st)} mm",
                 f"- covariance model: {res.get('covariance_model') or 'not stated'}", ""]


def _board_plots(dataset: Dataset | None, observations: Observations, res: dict, Ti: np.ndarray, out: Path,
                 summary: ReportSummary, rms_mm: list[float], clim: float) -> list[str]:
    """Per board: its residual plot and (with a dataset) its overlay written under ``out``; the markdown links."""
    rejected = {int(r["index"]): r for r in res.get("boards_rejected") or []}
    links = []
    for i, b in enumerate(observations.boards):
        name = _pose_name(observations, i)
        bearing = np.degrees(np.arctan2(b.scan[:, 1], b.scan[:, 0]))
        d = 1000 * board_plane_distances(Ti, b.T_cam_board, b.scan)
        rp = out / f"residual_{name}.png"
        _residual_plot(rp, bearing, d, f"pose {name} (board {i}): {len(d)} points")
        summary.residual_plots.append(rp)
        link = f"[residuals](residual_{name}.png)"
        if dataset is not None:
            try:
                pose = dataset.pose(name)
                gray = pose.read_image()
                full = pose.scan.points if pose.scan is not None else None
                op = out / f"overlay_{name}.png"
                draw_overlay(op, gray, dataset.camera, Ti, b.T_cam_board, b.outline, full, b.scan, clim,
                         f"pose {name}: {len(b.scan)} board points, RMS {rms_mm[i]:.1f} mm",
                         rejected[i]["reason"] if i in rejected else None)
                summary.overlays.append(op)
                link = f"[overlay](overlay_{name}.png), " + link
            except (KeyError, LidarcamError) as err:
                summary.warnings.append(f"pose {name}: no overlay ({err})")
        links.append(link)
    return links


def _boards_md(observations: Observations, res: dict, Ti: np.ndarray, rms_mm: list[float], mean_mm: list[float],
               links: list[str]) -> list[str]:
    """The per-board table (points, residual RMS and mean, corner reprojection, status, plots) and the totals."""
    rejected = {int(r["index"]): r for r in res.get("boards_rejected") or []}
    reproj = (observations.meta or {}).get("reproj_rms_px") or []
    rows = []
    for i, b in enumerate(observations.boards):
        rp_px = reproj[i] if i < len(reproj) and reproj[i] is not None else math.nan
        status = "rejected: " + str(rejected[i]["reason"]) if i in rejected else "used"
        rows.append([i, f"`{_pose_name(observations, i)}`", len(b.scan), f"{rms_mm[i]:.1f}", f"{mean_mm[i]:+.1f}",
                     num(rp_px, ".3f"), status, links[i]])
    md = ["## Boards", "", "Residual: signed distance of the board's scan points to its plane (camera's pose of "
          "the board), through the extrinsic.", ""]
    md += md_table(["board", "pose", "points", "residual RMS (mm)", "mean (mm)", "corner reproj. RMS (px)", "status",
                    "plots"], rows, "rlrrrrll") + [""]
    finite = [r for r in rms_mm if math.isfinite(r)]
    if finite:
        every = np.concatenate([1000 * board_plane_distances(Ti, b.T_cam_board, b.scan) for b in observations.boards])
        md += [f"Median board RMS: {float(np.median(finite)):.1f} mm; all points: "
               f"{math.sqrt(np.mean(every ** 2)):.1f} mm.", ""]
    if observations.n_boards >= 2:
        md += [f"Board set: largest angle between two board normals {pair_angle_deg(observations):.1f} deg; "
               f"normals {normal_spread_deg(observations):.1f} deg from one plane (spread).", ""]
    return md


def write_report(dataset: Dataset | None, observations: Observations, result, out_dir) -> ReportSummary:
    """Write the report of ``result`` on ``observations`` (extracted from ``dataset``) into ``out_dir``.

    Files: ``overlay_<pose>.png`` (the image with the whole scan projected through ``T_cam_lidar``, coloured by
    the signed distance to that board's plane in mm; the board's own points larger, the board outline from the
    camera pose in yellow), ``residual_<pose>.png`` (point-to-plane distance of the board's points against
    bearing), ``extrinsic.yaml`` and ``report.md`` (the extrinsic both ways with quaternion (x, y, z, w) and
    translation, 1-sigma where the result has a covariance, per-board residual RMS, skipped poses, warnings).
    ``dataset`` may be None (no overlays). ``result``: a CalibrationResult, a ``load_result`` dict or a path.
    """
    res = _as_result(result)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    md = [f"# lidarcam calibration report ({res['method']})", ""]
    if dataset is not None:
        md += [f"Dataset: `{dataset.root}`, {len(dataset.poses)} poses, {observations.n_boards} used.", ""]
    skipped = (observations.meta or {}).get("skipped") or {}
    skipped_md = ["## Skipped poses", ""] + [f"- `{k}`: {v}" for k, v in skipped.items()] + [""] if skipped else []
    summary = ReportSummary(out / "report.md")
    if not res["ok"] or res["T_lidar_cam"] is None:
        md += ["**The calibration failed**: " + str(res.get("reason")), ""] + skipped_md
        summary.warnings.append(f"calibration failed: {res.get('reason')}")
        summary.markdown.write_text("\n".join(md) + "\n")
        return summary

    T = np.asarray(res["T_lidar_cam"], float)
    Ti = invert_T(T)
    (out / "extrinsic.yaml").write_text(_result_object(result).to_yaml())  # as lidarcam calibrate --yaml
    md += _extrinsic_md(res, T, Ti) + _mounting_md(res)
    if observations.T_lidar_cam_true is not None:
        e_R, e_t = pose_errors(T, observations.T_lidar_cam_true)
        md += [f"Against the ground truth: e_R = {float(e_R):.4f} deg, e_t = {1000 * float(e_t):.1f} mm.", ""]

    d_mm = [1000 * board_plane_distances(Ti, b.T_cam_board, b.scan) for b in observations.boards]
    rms_mm = [float(np.sqrt(np.mean(d ** 2))) for d in d_mm]
    mean_mm = [float(np.mean(d)) for d in d_mm]
    summary.board_rms_mm = rms_mm
    clim = overlay_clim_mm(np.concatenate(d_mm) if d_mm else [])  # one colour range for every board's overlay
    links = _board_plots(dataset, observations, res, Ti, out, summary, rms_mm, clim)
    md += _boards_md(observations, res, Ti, rms_mm, mean_mm, links) + skipped_md
    every = report_warnings(observations, rms_mm, T) + list(res.get("warnings") or []) + summary.warnings
    summary.warnings = list(dict.fromkeys(every))  # the method's own board-set warnings are the library's too
    md += ["## Warnings", ""] + ([f"- {w}" for w in summary.warnings] or ["None."]) + [""]
    md += ["## Capture plan", "", capture_verdict(observations, T), ""]
    md += ["## Extrinsic as YAML", "", "```yaml", (out / "extrinsic.yaml").read_text().rstrip(), "```", ""]
    summary.markdown.write_text("\n".join(md) + "\n")
    return summary


__all__ = ["ReportSummary", "board_plane_distances", "capture_verdict", "project_scan", "report_warnings",
           "save_overlay", "write_report"]
