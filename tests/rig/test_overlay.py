"""Overlay colours: the colour range follows the board points, and the scan points far from the board plane
(walls) are drawn in a neutral grey, never as the saturated end of the scale."""

from __future__ import annotations

import numpy as np
from matplotlib.colors import to_rgba

from calib_core.geometry.transforms import invert_T
from lidarcam.rig.dataset import CameraModel
from lidarcam.rig.overlay import OVERLAY_BEYOND, board_plane_distances, draw_overlay, overlay_clim_mm
from simulate import SimOptions, generate


def test_wall_points_are_grey_and_board_points_span_the_scale(tmp_path):
    obs = generate(SimOptions(n_boards=3, noise_mm=5.0), seed=0)
    b = obs.boards[0]
    Ti = invert_T(obs.T_lidar_cam_true)
    wall = 1.6 * b.scan  # the same bearings, well behind the board: a wall
    full = np.vstack([b.scan, wall])
    d_board = 1000 * board_plane_distances(Ti, b.T_cam_board, b.scan)
    clim = overlay_clim_mm(d_board)
    assert clim < 100 and np.percentile(np.abs(d_board), 95) <= clim  # set by the board points (5 mm noise)
    K = np.array([[800.0, 0, 399.5], [0, 800.0, 299.5], [0, 0, 1]])
    fig = draw_overlay(tmp_path / "o.png", np.full((600, 800), 128, np.uint8), CameraModel(800, 600, K, np.zeros(5)),
                       Ti, b.T_cam_board, b.outline, full, b.scan, clim, "test")
    fig.canvas.draw()
    full_pts = fig.axes[0].collections[0]
    colours = full_pts.get_facecolors()
    values = np.asarray(full_pts.get_array())
    beyond = np.abs(values) > clim
    assert beyond.any() and (~beyond).any()
    np.testing.assert_allclose(colours[beyond], np.tile(to_rgba(OVERLAY_BEYOND), (beyond.sum(), 1)))
    board_values = np.asarray(fig.axes[0].collections[1].get_array())
    assert np.abs(board_values).max() > 0.3 * clim  # the board points use the scale, not a sliver of it
