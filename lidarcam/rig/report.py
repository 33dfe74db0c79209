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
from .report_figures import board_view, summary_figure
from .report_html import BoardCard, HtmlReport, write_html

OUTLIER_FACTOR = 3.0


@dataclass
class ReportSummary:
    """What ``write_report`` wrote and found: file paths (``report.md``, ``report.html``, the overlays, the residual
    plots and, for boards without an image, the face-on views), per-board residual RMS (mm), warnings."""

    markdown: Path
    html: Path | None = None
    overlays: list[Path] = field(default_factory=list)
    residual_plots: list[Path] = field(default_factory=list)
    board_views: list[Path] = field(default_factory=list)
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


def capture_advice(observations: Observations, result=None) -> str:
    """The capture planner's verdict on the boards captured (``calib_core.planning.observed.plan_from_observations``)
    from their calibration ``result`` (a CalibrationResult or a result dict: its extrinsic, covariance and noise
    estimates; None: the ``lidarcam`` calibration of the boards, as ``lidarcam plan --from`` makes it), with the
    noise it assumed."""
    from calib_core import calibrate
    from calib_core.planning.capture import plan_summary
    from calib_core.planning.observed import plan_from_observations

    try:
        res = calibrate(observations) if result is None else result
        ok = res.ok if isinstance(res, CalibrationResult) else bool(res.get("ok"))
        if not ok:
            reason = res.reason if isinstance(res, CalibrationResult) else res.get("reason")
            return f"no plan: the calibration failed ({reason})"
        if isinstance(res, CalibrationResult):
            T, cov, info = res.T_lidar_cam, res.covariance, res.info
        else:
            T, cov, info = res["T_lidar_cam"], res.get("covariance"), res.get("info") or res
        p = plan_from_observations(observations, np.asarray(T, float), 2, covariance=cov, info=info)
    except (LidarcamError, ValueError) as err:
        return f"no plan: {err}"
    return (f"{plan_summary(p.plan)}. (Assumed noise: range {1000 * p.range_sigma_m:.1f} mm, corners "
            f"{p.corner_sigma_px:.2g} px ({p.noise_source}); `lidarcam plan --from OBS.json` gives the whole plan.)")


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


def _bearing_deg(scan: np.ndarray) -> np.ndarray:
    """Bearings (deg) of scan points (K,2), continuous across +-180 deg (a board behind the lidar stays one run):
    within 180 deg of the points' mean direction."""
    a = np.arctan2(scan[:, 1], scan[:, 0])
    c = np.arctan2(np.sin(a).mean(), np.cos(a).mean())
    return np.degrees(c + np.angle(np.exp(1j * (a - c))))


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
                 summary: ReportSummary, rms_mm: list[float], clim: float) -> tuple[list[str], list[list]]:
    """Per board: its residual plot and its overlay (with a dataset) or, without an image, its face-on view
    (``lidarcam.rig.report_figures.board_view``), written under ``out``; the markdown links and each board's
    (file, caption) list."""
    rejected = {int(r["index"]): r for r in res.get("boards_rejected") or []}
    links, images = [], []
    for i, b in enumerate(observations.boards):
        name = _pose_name(observations, i)
        bearing = _bearing_deg(b.scan)
        d = 1000 * board_plane_distances(Ti, b.T_cam_board, b.scan)
        rp = out / f"residual_{name}.png"
        _residual_plot(rp, bearing, d, f"pose {name} (board {i}): {len(d)} points")
        summary.residual_plots.append(rp)
        link, figs = f"[residuals](residual_{name}.png)", []
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
                figs.append((op, f"pose {name}: the scan projected into the image through the extrinsic"))
            except (KeyError, LidarcamError) as err:
                summary.warnings.append(f"pose {name}: no overlay ({err})")
        if not figs:  # no image: the board face-on, the scan laid on it
            bv = board_view(out / f"board_{name}.png", Ti, b, clim, f"pose {name} (board {i}) face-on, scan "
                            f"through the extrinsic: RMS {rms_mm[i]:.1f} mm")
            summary.board_views.append(bv)
            link = f"[board view](board_{name}.png), " + link
            figs.append((bv, f"pose {name}: the board face-on with its scan points through the extrinsic"))
        figs.append((rp, f"pose {name}: point-to-plane residuals against bearing"))
        links.append(link)
        images.append(figs)
    return links, images


def _boards_md(observations: Observations, res: dict, Ti: np.ndarray, rms_mm: list[float], mean_mm: list[float],
               links: list[str]) -> list[str]:
    """The per-board table (points, residual RMS and mean, corners used, their reprojection, status, plots) and the
    totals."""
    rejected = {int(r["index"]): r for r in res.get("boards_rejected") or []}
    reproj = (observations.meta or {}).get("reproj_rms_px") or []
    rows = []
    for i, b in enumerate(observations.boards):
        rp_px = reproj[i] if i < len(reproj) and reproj[i] is not None else math.nan
        status = "rejected: " + str(rejected[i]["reason"]) if i in rejected else "used"
        n_corners = len(b.corners_px) if b.corners_px is not None else "-"
        rows.append([i, f"`{_pose_name(observations, i)}`", len(b.scan), f"{rms_mm[i]:.1f}", f"{mean_mm[i]:+.1f}",
                     n_corners, num(rp_px, ".3f"), status, links[i]])
    md = ["## Boards", "", "Residual: signed distance of the board's scan points to its plane (camera's pose of "
          "the board), through the extrinsic.", ""]
    md += md_table(["board", "pose", "points", "residual RMS (mm)", "mean (mm)", "corners", "corner reproj. RMS (px)",
                    "status", "plots"], rows, "rlrrrrrll") + [""]
    finite = [r for r in rms_mm if math.isfinite(r)]
    if finite:
        every = np.concatenate([1000 * board_plane_distances(Ti, b.T_cam_board, b.scan) for b in observations.boards])
        md += [f"Median board RMS: {float(np.median(finite)):.1f} mm; all points: "
               f"{math.sqrt(np.mean(every ** 2)):.1f} mm.", ""]
    if observations.n_boards >= 2:
        md += [f"Board set: largest angle between two board normals {pair_angle_deg(observations):.1f} deg; "
               f"normals {normal_spread_deg(observations):.1f} deg from one plane (spread).", ""]
    return md


def write_report(dataset: Dataset | None, observations: Observations, result, out_dir, alerts=()) -> ReportSummary:
    """Write the report of ``result`` on ``observations`` (extracted from ``dataset``) into ``out_dir``.

    Files: ``overlay_<pose>.png`` (the image with the whole scan projected through ``T_cam_lidar``, coloured by
    the signed distance to that board's plane in mm; the board's own points larger, the board outline from the
    camera pose in yellow), ``residual_<pose>.png`` (point-to-plane distance of the board's points against
    bearing), ``extrinsic.yaml`` and ``report.md`` (the extrinsic both ways with quaternion (x, y, z, w) and
    translation, 1-sigma where the result has a covariance, per-board residual RMS, skipped poses, warnings),
    ``summary.png`` (``lidarcam.rig.report_figures.summary_figure``) and ``report.html``
    (``lidarcam.rig.report_html``: all of it on one self-contained page, warnings first). ``dataset`` may be None
    (no overlays: ``board_<pose>.png``, each board face-on with its scan, instead). ``result``: a CalibrationResult,
    a ``load_result`` dict or a path.
    ``alerts``: warnings that come first, under the title and in ``ReportSummary.warnings`` (e.g.
    ``lidarcam.rig.result_match.result_fit``'s: the result does not fit these boards).
    """
    res = _as_result(result)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    title = f"lidarcam calibration report ({res['method']})"
    md = [f"# {title}", ""]
    intro = [f"Dataset: {dataset.root}, {len(dataset.poses)} poses, {observations.n_boards} used."] \
        if dataset is not None else [f"Observations: {observations.n_boards} boards (no images: each board is "
                                     "shown face-on with its scan instead of an overlay)."]
    md += [intro[0].replace(f"{dataset.root}", f"`{dataset.root}`") if dataset is not None else intro[0], ""]
    md += [f"**Warning: {a}**" for a in alerts] + ([""] if alerts else [])
    skipped = (observations.meta or {}).get("skipped") or {}
    skipped_md = ["## Skipped poses", ""] + [f"- `{k}`: {v}" for k, v in skipped.items()] + [""] if skipped else []
    summary = ReportSummary(out / "report.md", out / "report.html", warnings=list(alerts))
    page = HtmlReport(title, intro, summary.warnings, alerts=len(alerts), result=res, skipped=skipped)
    if not res["ok"] or res["T_lidar_cam"] is None:
        md += ["**The calibration failed**: " + str(res.get("reason")), ""] + skipped_md
        summary.warnings.append(f"calibration failed: {res.get('reason')}")
        summary.markdown.write_text("\n".join(md) + "\n")
        page.failure = str(res.get("reason"))
        write_html(summary.html, page)
        return summary

    T = np.asarray(res["T_lidar_cam"], float)
    Ti = invert_T(T)
    (out / "extrinsic.yaml").write_text(_result_object(result).to_yaml())  # as lidarcam calibrate --yaml
    md += _extrinsic_md(res, T, Ti) + _mounting_md(res)
    if observations.T_lidar_cam_true is not None:
        e_R, e_t = pose_errors(T, observations.T_lidar_cam_true)
        page.truth = f"Against the ground truth: e_R = {float(e_R):.4f} deg, e_t = {1000 * float(e_t):.1f} mm."
        md += [page.truth, ""]

    d_mm = [1000 * board_plane_distances(Ti, b.T_cam_board, b.scan) for b in observations.boards]
    rms_mm = [float(np.sqrt(np.mean(d ** 2))) for d in d_mm]
    mean_mm = [float(np.mean(d)) for d in d_mm]
    summary.board_rms_mm = rms_mm
    clim = overlay_clim_mm(np.concatenate(d_mm) if d_mm else [])  # one colour range for every board's overlay
    links, images = _board_plots(dataset, observations, res, Ti, out, summary, rms_mm, clim)
    md += ["## Summary", "", "![the boards from above, residual RMS per board](summary.png)", ""]
    md += _boards_md(observations, res, Ti, rms_mm, mean_mm, links) + skipped_md
    every = summary.warnings + report_warnings(observations, rms_mm, T) + list(res.get("warnings") or [])
    summary.warnings = list(dict.fromkeys(every))  # alerts first; the method's board-set warnings are the library's too
    md += ["## Warnings", ""] + ([f"- {w}" for w in summary.warnings] or ["None."]) + [""]
    page.capture = capture_advice(observations, result if isinstance(result, CalibrationResult) else res)
    page.yaml = (out / "extrinsic.yaml").read_text().rstrip()
    md += ["## Capture plan", "", page.capture, ""]
    md += ["## Extrinsic as YAML", "", "```yaml", page.yaml, "```", ""]
    summary.markdown.write_text("\n".join(md) + "\n")
    _fill_page(page, observations, res, T, rms_mm, mean_mm, images, out, summary.warnings)
    write_html(summary.html, page)
    return summary


def _headline(res: dict, n_boards: int, n_rejected: int, rms_mm: list[float], noise_mm: float | None,
              misfit: bool) -> str:
    """The answer at a glance: whether it fits (``misfit``: the median residual is above the level at which
    ``lidarcam.rig.result_match`` says it does not), the 1-sigma, the boards used, the median residual against the
    scans' noise."""
    verdict = res.get("verdict") if isinstance(res.get("verdict"), dict) else {}
    state = "does not fit these boards" if misfit else "the method's own test finds the data contradict it" \
        if verdict.get("consistent") is False else "ok"
    parts = [f"{res['method']}: {state}"]
    cov = res.get("covariance")
    if cov is not None:
        cov = np.asarray(cov, float)
        parts.append(f"1-sigma {sigma_rot_deg(cov):.2f} deg, {1000 * sigma_trans_m(cov):.1f} mm")
    parts.append(f"{n_boards - n_rejected} of {n_boards} boards used")
    if rms_mm:
        med = float(np.median(rms_mm))
        parts.append(f"median board residual {med:.1f} mm" + (f" ({med / noise_mm:.1f} x the scans' noise)"
                                                               if noise_mm else ""))
    return "; ".join(parts)


def _fill_page(page: HtmlReport, observations: Observations, res: dict, T: np.ndarray, rms_mm: list[float],
               mean_mm: list[float], images: list[list], out: Path, warnings: list[str]) -> None:
    """The HTML page's answer, summary figure, fit line and board cards."""
    from .result_match import MISFIT_FLOOR_MM, MISFIT_NOISE_FACTOR, scan_noise_mm

    page.warnings, page.T_lidar_cam = warnings, T
    rejected = {int(r["index"]): str(r["reason"]) for r in res.get("boards_rejected") or []}
    names = [_pose_name(observations, i) for i in range(observations.n_boards)]
    noise = scan_noise_mm(observations)
    misfit = None if noise is None else max(MISFIT_NOISE_FACTOR * noise, MISFIT_FLOOR_MM)
    page.summary_png = summary_figure(out / "summary.png", observations, T, rms_mm, names, set(rejected),
                                      noise if noise is not None else math.nan, misfit)
    finite = [r for r in rms_mm if math.isfinite(r)]
    if finite and noise is not None:
        med = float(np.median(finite))
        page.fit = (f"Median board residual RMS {med:.1f} mm against the scans' own noise {noise:.1f} mm (from "
                    f"their lines alone): {med / max(noise, 1e-9):.1f} x; above {misfit:.0f} mm the result would "
                    "not fit these boards.")
    misfits = bool(finite) and misfit is not None and float(np.median(finite)) > misfit
    page.headline = _headline(res, observations.n_boards, len(rejected), finite, noise, misfits)
    reproj = (observations.meta or {}).get("reproj_rms_px") or []
    page.cards = [BoardCard(i, names[i], len(b.scan), rms_mm[i], mean_mm[i],
                            reproj[i] if i < len(reproj) and isinstance(reproj[i], (int, float)) else None,
                            rejected.get(i), images[i]) for i, b in enumerate(observations.boards)]
    if observations.n_boards >= 2:
        page.totals = [f"Board set: largest angle between two board normals {pair_angle_deg(observations):.1f} deg; "
                       f"normals {normal_spread_deg(observations):.1f} deg from one plane (spread)."]


__all__ = ["ReportSummary", "board_plane_distances", "capture_advice", "project_scan", "report_warnings",
           "save_overlay", "write_report"]
