"""The camera's intrinsics as unknowns of the joint model, with the Gaussian prior the observation file states
(``camera.std_intrinsics``, the 1-sigma of a prior calibration such as ``cv2.calibrateCameraExtended``'s).

The intrinsics (``Camera.intrinsics`` order: fx, fy, cx, cy in pixels, then the distortion coefficients) are shared
by every board, so they join the extrinsic in the global block of the joint model's normal equations: the global
parameters are ``(w, dt, dk)`` with ``dk`` the change of the free intrinsics (those with a 1-sigma > 0) from the
file's values. Corner rows touch their board's pose and ``dk``, range rows their board's pose and ``(w, dt)``, and
one prior row per free intrinsic, ``(k - k0) / std``, touches ``dk`` alone. The Schur complement over the board poses
keeps each step's cost linear in the number of boards; the extrinsic's covariance is the ``(w, dt)`` block of the
inverse of the global information, so it holds the camera-side error the intrinsics carry into every board pose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.camera import Camera

EXACT_INTRINSICS = "taken as exact (the camera has no std_intrinsics)"
ESTIMATED_INTRINSICS = "estimated with the prior camera.std_intrinsics"
RANGE_ONLY_INTRINSICS = "not modelled: board poses taken as exact (neither corner noise nor intrinsics error is in " \
    "the covariance)"
"""Values of a result's ``info["intrinsics"]``: how its covariance model treated the camera's intrinsics (the
joint model with or without a prior; the range-only model, which takes the camera's board poses as exact)."""


@dataclass(frozen=True, eq=False)
class IntrinsicsPrior:
    """The free intrinsics of a camera and their prior.

    Attributes:
        camera: the file's camera (its intrinsics are the prior's mean).
        free: indices into ``Camera.intrinsics`` of the intrinsics with a 1-sigma > 0 (the others stay fixed).
        k0: (m,) their prior mean (the file's values); std: (m,) their 1-sigma (pixels, or unitless).
    """

    camera: Camera
    free: np.ndarray
    k0: np.ndarray
    std: np.ndarray

    @classmethod
    def of(cls, camera: Camera | None) -> IntrinsicsPrior | None:
        """The prior of ``camera``'s ``std_intrinsics``; None when it has none or every 1-sigma is 0."""
        if camera is None or camera.std_intrinsics is None:
            return None
        free = np.flatnonzero(camera.std_intrinsics > 0)
        if not len(free):
            return None
        return cls(camera, free, camera.intrinsics[free], camera.std_intrinsics[free])

    @property
    def size(self) -> int:
        """Number of free intrinsics."""
        return len(self.free)

    def camera_at(self, k: np.ndarray) -> Camera:
        """The camera with its free intrinsics at ``k`` (m,)."""
        v = self.camera.intrinsics
        v[self.free] = k
        return self.camera.with_intrinsics(v)

    def residuals(self, k: np.ndarray) -> np.ndarray:
        """The prior's normalised residuals ``(k - k0) / std`` (m,); their Jacobian is ``diag(1 / std)``."""
        return (np.asarray(k, float) - self.k0) / self.std


def augmented_blocks(blocks, oc: np.ndarray, ec: np.ndarray, Jc: np.ndarray, Jk: np.ndarray, prior_e: np.ndarray,
                     std: np.ndarray):
    """Gauss-Newton blocks (``joint._normal_equations``'s) with the free intrinsics appended to the extrinsic:
    ``ec`` (2J,) the normalised corner residuals, ``Jc`` (2J,6) their board Jacobian, ``Jk`` (2J,m) their
    intrinsics Jacobian, ``oc`` each board's first corner row, ``prior_e`` (m,) the prior residuals. Returns the
    global gradient (6+m,), the boards' gradient (N,6), the global information (6+m, 6+m), the global-board blocks
    (N, 6+m, 6) and the board blocks (N,6,6)."""
    g_e, g_b, H_ee, H_eb, H_bb = blocks
    m = Jk.shape[1]
    H_gg = np.zeros((6 + m, 6 + m))
    H_gg[:6, :6] = H_ee
    H_gg[6:, 6:] = Jk.T @ Jk + np.diag(1.0 / std**2)
    H_kb = np.add.reduceat(np.einsum("ra,rb->rab", Jk, Jc), oc)
    g_g = np.r_[g_e, Jk.T @ ec + prior_e / std]
    return g_g, g_b, H_gg, np.concatenate([H_eb, H_kb], axis=1), H_bb
