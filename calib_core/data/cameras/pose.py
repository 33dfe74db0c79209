"""A planar board's pose from its image corners through any camera model: the homography from the board plane to
the corners' unprojected rays (a direct linear fit on rays, so corners beyond 90 deg from the optical axis count),
then the reprojection error in pixels minimised through the model (``scipy.optimize.least_squares``, analytic
Jacobian). Frames: board ``{W}`` (plane z = 0), camera ``{C}``; ``T_cam_board`` maps board points into ``{C}``;
metres and pixels."""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ...errors import ObservationError
from ...geometry.transforms import make_T, project_to_so3, rotvec_to_matrix, skew
from ..camera import CameraModel

MIN_POSE_CORNERS = 4
"""Fewest corners with a ray a pose needs."""


def homography_pose(rays: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """``T_cam_board`` (4x4) whose plane maps the board points ``xy`` (N,2) onto the directions ``rays`` (N,3):
    the homography ``rays ~ [r1 r2 t] (x, y, 1)`` by the direct linear fit (points centred and scaled), its scale
    and sign from the board lying along the rays, the rotation the nearest to ``[r1 r2 r1 x r2]``."""
    c, s = xy.mean(axis=0), np.sqrt(2) / max(np.linalg.norm(xy - xy.mean(axis=0), axis=1).mean(), 1e-12)
    N = np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1]])
    p = np.column_stack([xy, np.ones(len(xy))]) @ N.T
    r = rays / np.linalg.norm(rays, axis=1, keepdims=True)
    z = np.zeros_like(p)
    A = np.concatenate([np.hstack([z, -r[:, 2:3] * p, r[:, 1:2] * p]), np.hstack([r[:, 2:3] * p, z, -r[:, 0:1] * p]),
                        np.hstack([-r[:, 1:2] * p, r[:, 0:1] * p, z])])
    H = np.linalg.svd(A, full_matrices=False)[2][-1].reshape(3, 3) @ N
    if np.mean(np.einsum("na,na->n", r, np.column_stack([xy, np.ones(len(xy))]) @ H.T)) < 0:
        H = -H
    lam = 2.0 / (np.linalg.norm(H[:, 0]) + np.linalg.norm(H[:, 1]))
    R = project_to_so3(np.column_stack([H[:, 0], H[:, 1], np.cross(H[:, 0], H[:, 1])]) * np.r_[lam, lam, lam**2])
    return make_T(R, lam * H[:, 2])


def pose_from_corners(camera: CameraModel, corners_board: np.ndarray, corners_px: np.ndarray,
                      T0: np.ndarray | None = None) -> np.ndarray:
    """``T_cam_board`` (4x4) of the board whose corners ``corners_board`` (N,3 on z = 0, or N,2; metres) are seen
    at ``corners_px`` (N,2, pixels) through ``camera``: from ``T0`` when given, else from ``homography_pose`` of the
    corners' rays, the pixel reprojection error minimised through the model (Levenberg-Marquardt).

    ObservationError (field ``corners_px``) when fewer than ``MIN_POSE_CORNERS`` corners have a ray, or when the
    fitted pose puts a corner where the model cannot project it."""
    P = np.asarray(corners_board, float)
    P = np.column_stack([P[:, :2], np.zeros(len(P))])
    uv = np.asarray(corners_px, float)
    if T0 is None:
        rays, ok = camera.unproject(uv)
        if ok.sum() < MIN_POSE_CORNERS:
            raise ObservationError(f"{int(ok.sum())} of {len(uv)} corners have a ray through the {camera.name} "
                                   f"model (a pose needs {MIN_POSE_CORNERS})", field="corners_px")
        T0 = homography_pose(rays[ok], P[ok, :2])
    if not camera.valid(P @ T0[:3, :3].T + T0[:3, 3]).all():
        raise ObservationError(f"the corners' first pose puts some outside the {camera.name} model's field of view",
                               field="corners_px")
    T = np.asarray(T0, float)
    for _ in range(2):       # the second pass re-linearises the rotation at the first one's answer
        T = _refined(camera, P, uv, T)
    if not camera.valid(P @ T[:3, :3].T + T[:3, 3]).all():
        raise ObservationError(f"the fitted pose puts corners outside the {camera.name} model's field of view",
                               field="corners_px")
    return T


def _refined(camera: CameraModel, P: np.ndarray, uv: np.ndarray, T0: np.ndarray) -> np.ndarray:
    """``T0`` moved (left perturbation) to the least pixel reprojection error of ``P`` against ``uv``."""
    R0, t0 = T0[:3, :3], T0[:3, 3]

    def fun(x):
        X = P @ (rotvec_to_matrix(x[:3]) @ R0).T + t0 + x[3:]
        return (camera.project(X) - uv).ravel()

    def jac(x):
        RP = P @ (rotvec_to_matrix(x[:3]) @ R0).T
        _, Jp = camera.project(RP + t0 + x[3:], jacobian=True)
        return np.concatenate([Jp @ -skew(RP), Jp], axis=2).reshape(-1, 6)

    x = least_squares(fun, np.zeros(6), jac=jac, method="lm", xtol=1e-14, ftol=1e-14).x
    return make_T(rotvec_to_matrix(x[:3]) @ R0, t0 + x[3:])
