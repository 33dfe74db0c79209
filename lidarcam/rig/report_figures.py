"""Figures of the calibration report (``lidarcam.rig.report``) beside the overlays (``lidarcam.rig.overlay``): the
summary figure (the boards seen from above in the lidar frame, with the camera where the result puts it, and each
board's residual RMS against the scans' noise) and, for sets given as observations without images, each board seen
face-on with the scan laid on it through the extrinsic.

Plots use matplotlib's Agg canvas directly (no pyplot, no global backend change). Lengths in the figures are
labelled: metres for positions, millimetres for residuals.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calib_core.data.observations import Observations
from calib_core.geometry.transforms import invert_T, transform_points

from .overlay import OVERLAY_BEYOND, OVERLAY_CMAP, board_plane_distances

USED, REJECTED, NOISE = "#1f77b4", "#d62728", "#2ca02c"


def _figure(w_in: float, h_in: float, dpi: float = 100.0):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w_in, h_in), dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def _plane_trace(T_lidar_cam: np.ndarray, T_cam_board: np.ndarray, scan: np.ndarray, margin_m: float = 0.15):
    """The board plane's trace in the scan plane (lidar frame, z = 0) as a segment spanning the board's scan points
    (plus ``margin_m`` each side), or None where the plane is nearly parallel to the scan plane."""
    T_lb = T_lidar_cam @ T_cam_board
    n, p0 = T_lb[:3, 2], T_lb[:3, 3]
    d2 = np.array([-n[1], n[0]])  # the line n.x = n.p0 in the plane z = 0 runs along (-n_y, n_x)
    if np.hypot(*n[:2]) < 1e-3:
        return None
    d2 = d2 / np.linalg.norm(d2)
    foot = n[:2] * (n @ p0) / (n[:2] @ n[:2])
    s = (scan - foot) @ d2
    return foot + np.outer([s.min() - margin_m, s.max() + margin_m], d2)


def summary_figure(path: Path, observations: Observations, T_lidar_cam: np.ndarray, rms_mm: list[float],
                   names: list[str], rejected: set[int], noise_mm: float, misfit_mm: float | None) -> Path:
    """Two panels: (left) the scene from above in the lidar frame (x forward, y left; metres): each board's scan
    points, numbered, with its plane's trace through ``T_lidar_cam`` dashed, the lidar at the origin and the
    camera with its optical axis; (right) each board's residual RMS (mm, boards left out by the calibration in red)
    with the scans' noise ``noise_mm`` and the level ``misfit_mm`` above which a median says the result does not
    fit."""
    fig = _figure(11.0, 5.0)
    ax = fig.add_axes((0.08, 0.2, 0.38, 0.72))
    for i, b in enumerate(observations.boards):
        colour = REJECTED if i in rejected else USED
        ax.plot(b.scan[:, 0], b.scan[:, 1], ".", ms=2.5, color=colour)
        seg = _plane_trace(T_lidar_cam, b.T_cam_board, b.scan)
        if seg is not None:
            ax.plot(seg[:, 0], seg[:, 1], "--", lw=0.8, color="0.35")
        c = b.scan.mean(axis=0)
        ax.annotate(str(i), c, xytext=(4, 4), textcoords="offset points", fontsize=7, color=colour)
    ax.plot([0], [0], marker=(3, 0, -90), ms=10, color="black", ls="none", label="lidar (x forward)")
    cam = T_lidar_cam[:3, 3]
    axis = T_lidar_cam[:3, 2]
    span = max(float(np.abs(np.concatenate([b.scan for b in observations.boards])).max()), 0.5)
    a = 0.12 * span * axis[:2] / max(np.linalg.norm(axis[:2]), 1e-9)
    ax.plot([cam[0]], [cam[1]], "s", ms=6, color="darkorange", label="camera (optical axis arrow)")
    ax.annotate("", cam[:2] + a, cam[:2], arrowprops={"arrowstyle": "->", "color": "darkorange", "lw": 1.5})
    ax.plot([], [], "--", lw=0.8, color="0.35", label="board plane through the result")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m, lidar frame)")
    ax.set_ylabel("y (m, lidar frame)")
    ax.set_title("From above: board scans and the camera where the result puts it", fontsize=9)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=3, frameon=False)
    ax.grid(alpha=0.3)

    bx = fig.add_axes((0.56, 0.2, 0.42, 0.70))
    x = np.arange(len(rms_mm))
    shown = np.nan_to_num(np.asarray(rms_mm, float), nan=0.0)
    bx.bar(x, shown, color=[REJECTED if i in rejected else USED for i in x])
    bx.axhline(noise_mm, color=NOISE, lw=1.2, label=f"scans' noise {noise_mm:.1f} mm")
    if misfit_mm is not None and misfit_mm < 1.5 * shown.max(initial=0):  # else it would squash the bars
        bx.axhline(misfit_mm, color=REJECTED, lw=1.0, ls=":", label=f"no fit above (median) {misfit_mm:.0f} mm")
    bx.set_xticks(x, [f"{i}\n{n}" if n != f"{i:03d}" else str(i) for i, n in zip(x, names, strict=True)],
                  fontsize=7 if len(x) <= 20 else 5)
    bx.set_xlabel("board (and pose)")
    bx.set_ylabel("residual RMS (mm)")
    bx.set_title("Residual RMS per board (red: left out by the calibration)", fontsize=9)
    bx.legend(fontsize=7, loc="upper right")
    bx.grid(axis="y", alpha=0.3)
    fig.savefig(path, pil_kwargs={"compress_level": 6})
    return path


def board_view(path: Path, T_cam_lidar: np.ndarray, board, clim_mm: float, title: str) -> Path:
    """One board face-on in its own frame (x right, y along the board; metres): its outline, its corners where the
    observations carry them, and its scan points mapped onto it through ``T_cam_lidar``, coloured by their signed
    distance to the board plane (mm, +-``clim_mm``): what an overlay shows for a set without images."""
    import matplotlib
    from matplotlib.colors import Normalize

    fig = _figure(5.0, 3.6)
    ax = fig.add_axes((0.13, 0.14, 0.66, 0.76))
    if board.outline is not None:
        ring = np.vstack([board.outline, board.outline[:1]])
        ax.plot(ring[:, 0], ring[:, 1], "-", color="0.2", lw=1.2, label=f"outline ({board.outline_kind})")
    if board.corners_board is not None:
        cb = np.asarray(board.corners_board)
        ax.plot(cb[:, 0], cb[:, 1], "+", color="0.55", ms=4, label="corners")
    P = transform_points(invert_T(board.T_cam_board) @ T_cam_lidar,
                         np.column_stack([board.scan, np.zeros(len(board.scan))]))
    dist = 1000 * board_plane_distances(T_cam_lidar, board.T_cam_board, board.scan)
    cmap = matplotlib.colormaps[OVERLAY_CMAP].with_extremes(over=OVERLAY_BEYOND, under=OVERLAY_BEYOND)
    sc = ax.scatter(P[:, 0], P[:, 1], c=dist, cmap=cmap, norm=Normalize(-clim_mm, clim_mm), s=10,
                    edgecolors="black", linewidths=0.3, label="scan points")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("board x (m)")
    ax.set_ylabel("board y (m)")
    ax.set_title(title, fontsize=8)
    ax.legend(fontsize=6, loc="upper right")
    ax.grid(alpha=0.3)
    cax = fig.add_axes((0.83, 0.14, 0.03, 0.76))
    cbar = fig.colorbar(sc, cax=cax, extend="both")
    cbar.set_label("distance to board plane (mm)", fontsize=7)
    cbar.ax.tick_params(labelsize=6)
    fig.savefig(path, pil_kwargs={"compress_level": 6})
    return path
