"""Physical plausibility of candidate extrinsics, per board (vectorised over candidates x boards).

A candidate ``T_lidar_cam = (R, t)`` is plausible on board i when

* **same side**: the lidar's origin and the camera's origin lie on the same side of the board plane. The plane is
  ``n . p_C = d`` in the camera frame; the camera's origin gives ``-d``, the lidar's (``p_C = -R^T t``) gives
  ``-(d + m . t)`` with ``m = R n``, so the test is ``d (d + m . t) > 0``: ``d + m . t`` is the plane's offset in
  the lidar frame (``m . p_L = d + m . t``), the same number the range residuals use;
* **in front of the lidar**: the beams of the scan's two ends meet the board plane at a positive range,
  ``(d + m . t) / (m . b) > 0`` (``b`` the beam's unit direction);
* **in front of the camera**: the scan's centroid, mapped into the camera frame, has positive depth (the board
  itself is in front of the camera by its PnP pose).

The minimal solver's mirror solutions (the P3P roots reflected through the planes' common point) put the lidar on
the far side of a board plane: with three boards, whose scan lines every minimal solution fits exactly, this test
is what tells most of them apart.

A board seen from behind (the lidar meets its back face, e.g. through an open stand, the camera its printed
face) fails the same-side test under the true extrinsic, and only that test: the in-front tests hold for either
face. The test reads the two origins and the plane only, whichever face the board's pose names (flipping the
normal flips ``d`` and ``d + m . t`` together), so no pose convention can tell a board seen from behind from a
wrong candidate. Such a board is therefore read as the data contradicting a one-faced board: from 4 boards on the
consensus leaves it out and names it (its per-board statistic is infinite, as for a board behind the camera,
``search.board_reason``), and with 3 boards no candidate is plausible and the method refuses. A rig that
really sees boards from behind leaves those boards out of the observations.
"""

from __future__ import annotations

import numpy as np

from ..data.observations import Observations
from .residuals import scan_endpoints


def _constants(obs: Observations):
    """(N,3) normals and (N,) offsets of the board planes (camera frame), (N,2,3) beams of the scan ends, (N,3)
    scan centroids (lidar frame)."""
    n, d = obs.planes_cam()
    ends = scan_endpoints(obs)
    beams = ends / np.linalg.norm(ends, axis=-1, keepdims=True)
    return n, d, beams, np.array([b.scan_3d.mean(axis=0) for b in obs.boards]).reshape(-1, 3)


def plausibility(obs: Observations, candidates: np.ndarray) -> dict[str, np.ndarray]:
    """Per test (``same_side``, ``lidar_front``, ``camera_front``), (M,N) bool: whether each candidate
    ``T_lidar_cam`` (M,4,4) passes it on each board (see the module doc)."""
    C = np.asarray(candidates, float).reshape(-1, 4, 4)
    n, d, beams, centres = obs.derived("plausible.constants", _constants)
    R, t = C[:, :3, :3], C[:, :3, 3]
    m = n @ R.swapaxes(-1, -2)                                               # (M,N,3) rows R n
    c = d[None] + np.einsum("mna,ma->mn", m, t)                              # the plane's offset in {L}
    mb = np.einsum("mna,nka->mnk", m, beams)                                 # (M,N,2)
    with np.errstate(divide="ignore", invalid="ignore"):
        front = (c[..., None] / mb > 0).all(axis=-1)
    depth = np.einsum("mna,ma->mn", centres[None] - t[:, None], R[:, :, 2])  # z of R^T (c - t)
    return {"same_side": c * d[None] > 0, "lidar_front": front, "camera_front": depth > 0}


def plausible_boards(obs: Observations, candidates: np.ndarray) -> np.ndarray:
    """(M,N) bool: every test of ``plausibility`` passes on the board."""
    p = plausibility(obs, candidates)
    return p["same_side"] & p["lidar_front"] & p["camera_front"]


def implausible_reason(obs: Observations, T: np.ndarray, board: int) -> str | None:
    """Why board ``board`` is implausible under one (4,4) ``T``, or None when it is plausible."""
    p = {k: bool(v[0, board]) for k, v in plausibility(obs, T[None]).items()}
    why = {"camera_front": "its scan falls behind the camera",
           "same_side": "the lidar and the camera lie on opposite sides of its plane (a board seen from behind, "
                        "or not this board's scan)",
           "lidar_front": "its plane lies behind the lidar along the beams of its scan"}
    bad = [why[k] for k in ("camera_front", "same_side", "lidar_front") if not p[k]]
    return "; ".join(bad) if bad else None
