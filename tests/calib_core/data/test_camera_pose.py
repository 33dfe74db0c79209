"""Board poses from image corners through every camera model (calib_core.data.cameras.pose): exact on noise-free
corners, boards far off the optical axis, OpenCV's PnP on the pinhole, refusals."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from test_camera_models import NAMES, random_camera

from calib_core.data.cameras.pose import pose_from_corners
from calib_core.errors import ObservationError
from calib_core.geometry.transforms import make_T, rotvec_to_matrix

GRID = np.stack(np.meshgrid(np.arange(8) * 0.05, np.arange(6) * 0.05), -1).reshape(-1, 2)
BOARD = np.column_stack([GRID, np.zeros(len(GRID))])


def _board_pose(rng, off_axis_deg):
    """A pose whose board centre lies ``off_axis_deg`` from the optical axis, 0.6-2 m away, facing the camera
    within 40 deg."""
    th, ph = np.radians(off_axis_deg), rng.uniform(0, 2 * np.pi)
    c = rng.uniform(0.6, 2.0) * np.array([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)])
    z = c / np.linalg.norm(c)
    R = rotvec_to_matrix(rng.normal(0, 0.4, 3))
    R = rotvec_to_matrix(np.cross(R[:, 2], z) * np.arcsin(min(1, np.linalg.norm(np.cross(R[:, 2], z)))) /
                         max(np.linalg.norm(np.cross(R[:, 2], z)), 1e-12)) @ R
    return make_T(R, c - R @ np.r_[GRID.mean(0), 0])


@pytest.mark.parametrize("name", NAMES)
def test_noise_free_corners_give_the_true_pose(name):
    rng = np.random.default_rng(1)
    done = 0
    for _ in range(40):
        cam = random_camera(name, rng)
        T = _board_pose(rng, rng.uniform(0, 95 if name != "pinhole-radtan" else 30))
        X = BOARD @ T[:3, :3].T + T[:3, 3]
        uv = cam.project(X)
        inside = (uv >= 0).all(1) & (uv[:, 0] <= cam.width - 1) & (uv[:, 1] <= cam.height - 1)
        if not (cam.valid(X).all() and inside.all()):
            continue
        done += 1
        np.testing.assert_allclose(pose_from_corners(cam, BOARD, uv), T, atol=1e-8)
    assert done >= 15


def test_on_the_pinhole_it_agrees_with_opencvs_pnp():
    rng = np.random.default_rng(2)
    for _ in range(10):
        cam = random_camera("pinhole-radtan", rng)
        T = _board_pose(rng, rng.uniform(0, 25))
        uv = cam.project(BOARD @ T[:3, :3].T + T[:3, 3]) + rng.normal(0, 0.5, (len(BOARD), 2))
        ok, rvec, tvec = cv2.solvePnP(BOARD, uv, cam.K, cam.dist, flags=cv2.SOLVEPNP_IPPE)
        rvec, tvec = cv2.solvePnPRefineLM(BOARD, uv, cam.K, cam.dist, rvec, tvec,
                                          (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 200, 1e-15))
        ours = pose_from_corners(cam, BOARD, uv)
        theirs = make_T(cv2.Rodrigues(rvec)[0], tvec.ravel())
        np.testing.assert_allclose(ours, theirs, atol=1e-4)          # OpenCV's LM stops a little short
        cost = [np.sum((cam.project(BOARD @ T[:3, :3].T + T[:3, 3]) - uv) ** 2) for T in (ours, theirs)]
        assert cost[0] <= cost[1] * (1 + 1e-12)


def test_corners_without_rays_are_refused():
    rng = np.random.default_rng(3)
    cam = random_camera("ds", rng)
    far = np.full((len(BOARD), 2), -1e5)
    with pytest.raises(ObservationError, match="corners_px"):
        pose_from_corners(cam, BOARD, far)
