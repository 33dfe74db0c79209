"""``lidarcam calibrate --std-intrinsics``: the 1-sigma of the camera's intrinsics when the observation file does not
state it (``camera.std_intrinsics``, docs/formats.md), so the joint model holds the camera-side error.

Two forms: the full list ``fx,fy,cx,cy[,k1,k2,...]`` (pixels for fx fy cx cy, unitless for the distortion
coefficients, one per coefficient of the file's ``dist``), or the shorthand ``F%,Cpx`` (focal lengths' 1-sigma as a
percentage of each, principal point's in pixels; the distortion taken as exact).
"""

from __future__ import annotations

import numpy as np

STD_INTRINSICS_HELP = ("1-sigma of the camera intrinsics when the file states none (camera.std_intrinsics): "
                       "fx,fy,cx,cy[,k1,k2,p1,p2,k3] in px and unitless (OpenCV's stdDeviationsIntrinsics order), "
                       "or the shorthand F%%,Cpx, e.g. 0.3%%,2px (focal lengths' 1-sigma in percent, principal "
                       "point's in pixels, distortion exact); the joint model then estimates the intrinsics with "
                       "that prior")


def parse_std_intrinsics(text: str, K: np.ndarray) -> np.ndarray:
    """The 1-sigma vector (fx, fy, cx, cy[, dist...]) that ``text`` states for a camera matrix ``K``;
    CalibrationError naming the flag and the bad item."""
    from calib_core.errors import CalibrationError

    items = [p.strip() for p in text.split(",") if p.strip()]
    if len(items) == 2 and items[0].endswith("%") and items[1].endswith("px"):
        try:
            rel, pp = float(items[0][:-1]) / 100.0, float(items[1][:-2])
        except ValueError:
            raise CalibrationError(f"--std-intrinsics: bad shorthand {text!r}; expected e.g. 0.3%,2px") from None
        return np.array([rel * K[0, 0], rel * K[1, 1], pp, pp])
    try:
        return np.array([float(v) for v in items])
    except ValueError:
        raise CalibrationError(f"--std-intrinsics: expected numbers fx,fy,cx,cy[,k1,...] or F%,Cpx, got {text!r}"
                               ) from None


def with_std_intrinsics(obs, text: str):
    """``obs`` with its camera's ``std_intrinsics`` set from the flag ``text``; CalibrationError (one line) when the
    file has no camera or the values are not valid for it."""
    from calib_core.data.camera import Camera
    from calib_core.data.observations import Observations
    from calib_core.errors import CalibrationError, ObservationError

    if obs.camera is None:
        raise CalibrationError("--std-intrinsics: the observation file has no camera intrinsics")
    c = obs.camera
    std = parse_std_intrinsics(text, c.K)
    dist = c.to_dict()["dist"]
    if len(std) not in (4, 4 + len(dist)):
        raise CalibrationError(f"--std-intrinsics: {len(std)} values; expected 4 (fx fy cx cy) or {4 + len(dist)} "
                               f"(with the file's {len(dist)} distortion coefficients)")
    try:
        camera = Camera(c.K, dist, c.width, c.height, std)
    except ObservationError as err:
        raise CalibrationError(f"--std-intrinsics: {err}") from None
    return Observations(obs.boards, obs.T_lidar_cam_true, obs.meta, camera)
