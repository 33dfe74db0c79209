"""The tool's detector (lidarcam.rig.detect) on the project's own renders (simulate.camera, as simulate.dataset
draws the demo):
its corners against the rendered truth, and the board poses they give against the noise their own residuals imply
(the corner noise the calibration assumes). A structured corner error (shared along the board) moves the pose more
than the residuals show: the demo's false "boards disagree" warning came from it."""

import cv2
import numpy as np
import pytest

from lidarcam.rig.dataset import BoardSpec as DatasetBoard
from lidarcam.rig.detect import find_chessboard
from simulate import SimOptions
from simulate.camera import BoardSpec, camera_matrix, checkerboard_corners, project, render_board_image
from simulate.scene import sample_scene

DEMO_RIG = dict(n_boards=10, cam_width=640, cam_height=480, focal_px=600.0, lidar_res_deg=0.25, noise_mm=5.0,
                render_supersample=2, dist_min_m=2.0, dist_max_m=4.0, max_tilt_deg=55.0)


def _renders(seed: int):
    o = SimOptions(**DEMO_RIG)
    rng = np.random.default_rng(seed)
    scene = sample_scene(o, rng)
    K = camera_matrix(o.focal_px, o.cam_width, o.cam_height)
    spec = BoardSpec.of(o)
    for T in scene.T_cam_board:
        img = cv2.GaussianBlur(render_board_image(K, T, spec, o.cam_width, o.cam_height, o.render_supersample)
                               .astype(np.float32), (0, 0), 0.7)              # simulate.dataset's defaults
        img = np.clip(np.rint(img + rng.normal(0.0, 2.0, img.shape)), 0, 255).astype(np.uint8)
        yield K, T, spec, img


def _detections(seed: int):
    """Per detected board: (pose NEES at the residuals' own corner noise, true corner errors (J,2))."""
    out = []
    for K, T, spec, img in _renders(seed):
        board = DatasetBoard(spec.squares_x - 1, spec.squares_y - 1, spec.square_m, spec.outline())
        uv = find_chessboard(img, board)
        if uv is None:
            continue
        P = checkerboard_corners(spec)
        truth = project(K, T, P)
        uv = uv.astype(float)
        if np.abs(uv - truth).max() > 5:
            uv = uv[::-1]
        ok, rv, tv = cv2.solvePnP(P, uv, K, None, flags=cv2.SOLVEPNP_IPPE)
        rv, tv = cv2.solvePnPRefineLM(P, uv, K, None, rv, tv)
        res = uv - cv2.projectPoints(P, rv, tv, K, None)[0].reshape(-1, 2)
        sigma = np.sqrt(np.sum(res ** 2) / (2 * len(P) - 6))                  # as camera_side.corner_noise_px
        rv0 = cv2.Rodrigues(T[:3, :3])[0]
        J = cv2.projectPoints(P, rv0, T[:3, 3], K, None)[1][:, :6]
        e = np.r_[rv.ravel() - rv0.ravel(), tv.ravel() - T[:3, 3]]
        out.append((float(e @ (J.T @ J) @ e) / sigma ** 2, uv - truth))
    return out


@pytest.mark.parametrize("seed", [0, 1])
def test_detected_corners_are_near_the_rendered_truth_and_the_poses_within_their_residual_noise(seed):
    dets = _detections(seed)
    assert len(dets) >= 8
    nees = np.array([d[0] for d in dets])
    err = np.concatenate([d[1] for d in dets])
    assert np.sqrt(np.mean(err ** 2)) < 0.05                                  # px, against the rendered truth
    assert np.abs(err.mean(axis=0)).max() < 0.01                              # no shift of the whole pattern
    assert np.mean(nees) < 12.0, nees                                         # chi-square 6: mean 6
