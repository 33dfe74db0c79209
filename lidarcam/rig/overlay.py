"""Scan-on-image overlays of a real rig: the scan projected through the distorted camera, coloured by its
distance to the board plane, and the palette PNG ``make real-data`` commits (``lidarcam.rig.report`` puts them in
reports).

The overlay PNG maps image pixel (u, v) to PNG pixel (u, v): the image fills the left part of the figure at one
PNG pixel per image pixel, the colorbar sits to its right.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from calib_core.data.observations import ScanData
from calib_core.geometry.transforms import invert_T, transform_points
from calib_core.model.residuals import plane_residuals

from .dataset import CameraModel

OVERLAY_CMAP = "turbo"  # saturated everywhere (a diverging map is grey at 0 mm: invisible on the board)
OVERLAY_BEYOND = "0.8"
"""Colour of scan points beyond the colour range (walls, floor: far from the board plane): a light grey, so that
only the board's neighbourhood takes the map's colours and no wall reads as the saturated end of the scale."""
OVERLAY_PERCENTILE = 95.0
"""The colour range is ``OVERLAY_RANGE_FACTOR`` x this percentile of the board points' |distance| (mm)..."""
OVERLAY_RANGE_FACTOR = 1.5
OVERLAY_MIN_CLIM_MM = 10.0
"""... at least this (mm), rounded up to ``OVERLAY_CLIM_STEP_MM``."""
OVERLAY_CLIM_STEP_MM = 5.0


def overlay_clim_mm(board_dist_mm) -> float:
    """Half-width (mm) of an overlay's colour range from the board points' distances to their planes (mm)."""
    d = np.abs(np.asarray(board_dist_mm, float))
    d = d[np.isfinite(d)]
    q = OVERLAY_RANGE_FACTOR * float(np.percentile(d, OVERLAY_PERCENTILE)) if len(d) else 0.0
    return float(math.ceil(max(OVERLAY_MIN_CLIM_MM, q) / OVERLAY_CLIM_STEP_MM) * OVERLAY_CLIM_STEP_MM)


def board_plane_distances(T_cam_lidar: np.ndarray, T_cam_board: np.ndarray, scan: np.ndarray) -> np.ndarray:
    """Signed distances (m) of lidar points ``scan`` (K,2) to the board plane, along the board's +z
    (``calib_core.model.residuals.plane_residuals`` of one board)."""
    n = T_cam_board[:3, 2]
    data = ScanData(np.column_stack([scan, np.zeros(len(scan))]), np.zeros(len(scan), int), n[None],
                    np.array([n @ T_cam_board[:3, 3]]))
    return plane_residuals(invert_T(T_cam_lidar), data)


def project_scan(camera: CameraModel, T_cam_lidar: np.ndarray, scan: np.ndarray, min_depth_m: float = 0.05
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (K,2) of lidar points ``scan`` (K,2) through the camera's lens, and a mask of the points that
    are in front of the camera (depth > ``min_depth_m``), inside the image and within the field of view where
    the distortion model holds (undistorted image bounds + 20 %)."""
    import cv2

    P = transform_points(T_cam_lidar, np.column_stack([scan, np.zeros(len(scan))]))
    uv = np.full((len(P), 2), np.nan)
    if not camera.is_opencv_pinhole:  # any other lens: through its model, where the model projects one-to-one
        lens = camera.core()
        ok = lens.valid(P) & (np.linalg.norm(P, axis=1) > min_depth_m)
        uv[ok] = lens.project(P[ok])
        return uv, ok & (uv[:, 0] >= -0.5) & (uv[:, 0] <= camera.width - 0.5) & (uv[:, 1] >= -0.5) & \
            (uv[:, 1] <= camera.height - 0.5)
    ok = P[:, 2] > min_depth_m
    if ok.any():
        w, h = camera.width, camera.height
        edge = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1], [w / 2, 0], [w / 2, h - 1], [0, h / 2],
                         [w - 1, h / 2]], float)
        nb = cv2.undistortPoints(edge.reshape(-1, 1, 2), camera.K, camera.dist).reshape(-1, 2)
        lim = 1.2 * np.abs(nb).max(axis=0)
        xn = P[ok, :2] / P[ok, 2:3]
        ok[np.flatnonzero(ok)] = np.all(np.abs(xn) <= lim, axis=1)
    if ok.any():
        proj, _ = cv2.projectPoints(P[ok], np.zeros(3), np.zeros(3), camera.K, camera.dist)
        uv[ok] = proj.reshape(-1, 2)
        inside = (uv[:, 0] >= -0.5) & (uv[:, 0] <= camera.width - 0.5) & (uv[:, 1] >= -0.5) & \
                 (uv[:, 1] <= camera.height - 0.5)
        ok &= inside
    return uv, ok


def draw_overlay(path: Path, gray: np.ndarray, camera: CameraModel, T_cam_lidar, T_cam_board, outline, full_scan,
             board_scan, clim_mm: float, title: str, rejected: str | None = None):
    """Draw and save one overlay (colour range +-``clim_mm``, points beyond it in ``OVERLAY_BEYOND``); the figure."""
    import matplotlib
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    h, w = gray.shape[:2]
    dpi = 100.0
    extra = 120
    W = w + extra
    fig = Figure(figsize=(W / dpi, h / dpi), dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0, 0, w / W, 1))
    ax.imshow(gray, cmap="gray", vmin=0, vmax=255, extent=(-0.5, w - 0.5, h - 0.5, -0.5), interpolation="nearest")
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.set_axis_off()
    import cv2

    ring = np.zeros((0, 3)) if outline is None else np.column_stack([outline, np.zeros(len(outline))])
    ring = transform_points(T_cam_board, np.vstack([ring, ring[:1]]))
    if len(ring) and not camera.is_opencv_pinhole:   # the outline's edges bend through the lens
        t = np.linspace(0.0, 1.0, 33)[:-1]
        ring = np.vstack([a + t[:, None] * (b - a) for a, b in zip(ring[:-1], ring[1:], strict=True)] + [ring[:1]])
    if len(ring) and not camera.is_opencv_pinhole and camera.core().valid(ring).all():
        uvb = camera.core().project(ring)
        ax.plot(uvb[:, 0], uvb[:, 1], "-", color="yellow", lw=1.0, alpha=0.8)
    elif len(ring) and camera.is_opencv_pinhole and np.all(ring[:, 2] > 0):  # no outline: nothing to draw
        uvb, _ = cv2.projectPoints(ring, np.zeros(3), np.zeros(3), camera.K, camera.dist)
        uvb = uvb.reshape(-1, 2)
        ax.plot(uvb[:, 0], uvb[:, 1], "-", color="yellow", lw=1.0, alpha=0.8)
    norm = Normalize(-clim_mm, clim_mm)
    cmap = matplotlib.colormaps[OVERLAY_CMAP].with_extremes(over=OVERLAY_BEYOND, under=OVERLAY_BEYOND)
    sc = None
    for pts, size, edge in ((full_scan, 6, "none"), (board_scan, 18, "black")):
        if pts is None or len(pts) == 0:
            continue
        uv, ok = project_scan(camera, T_cam_lidar, pts)
        if not ok.any():
            continue
        dist = 1000 * board_plane_distances(T_cam_lidar, T_cam_board, pts[ok])
        sc = ax.scatter(uv[ok, 0], uv[ok, 1], c=dist, cmap=cmap, norm=norm,
                        s=size, edgecolors=edge, linewidths=0.4)
    ax.text(4, 4, title, color="white", fontsize=8, va="top", ha="left",
            bbox={"facecolor": "black", "alpha": 0.5, "pad": 2, "edgecolor": "none"})
    if rejected:  # the calibration left this pose out: a red frame and the reason
        ax.add_patch(_frame(w, h))
        ax.text(4, h - 6, "REJECTED by the calibration: " + rejected, color="white", fontsize=8, va="bottom",
                ha="left", wrap=True, bbox={"facecolor": "red", "alpha": 0.75, "pad": 2, "edgecolor": "none"})
    cax = fig.add_axes(((w + 15) / W, 0.08, 14 / W, 0.84))
    if sc is None:
        from matplotlib.cm import ScalarMappable

        sc = ScalarMappable(norm=norm, cmap=cmap)
    cb = fig.colorbar(sc, cax=cax, extend="both")
    cb.set_label("distance to board plane (mm)", fontsize=8)
    cb.ax.tick_params(labelsize=7)
    fig.savefig(path, dpi=dpi, pil_kwargs={"compress_level": 1})
    return fig


def _frame(w: int, h: int):
    from matplotlib.patches import Rectangle

    return Rectangle((-0.5, -0.5), w, h, fill=False, edgecolor="red", linewidth=6)


def save_overlay(path, gray: np.ndarray, camera: CameraModel, T_cam_lidar, T_cam_board, outline, full_scan,
                 board_scan, title: str, clim_mm: float | None = None, colours: int = 128) -> Path:
    """One scan-on-image overlay (as in ``write_report``) saved as a small palette PNG (``colours`` colours):
    the whole scan through ``T_cam_lidar`` coloured by its distance to the board plane (mm), the board's own
    points larger, the board outline from the camera in yellow. ``clim_mm`` None: ``overlay_clim_mm`` of the board's
    points."""
    from PIL import Image

    path = Path(path)
    if clim_mm is None:
        clim_mm = overlay_clim_mm(1000 * board_plane_distances(T_cam_lidar, T_cam_board, board_scan))
    draw_overlay(path, gray, camera, T_cam_lidar, T_cam_board, outline, full_scan, board_scan, clim_mm, title)
    with Image.open(path) as im:
        small = im.convert("RGB").quantize(colours, method=Image.Quantize.MEDIANCUT)
    small.save(path, optimize=True)
    return path
