"""Compare vasconcelos_msac(_refined) with the reference's answers (a development check).

    python dev/reference/compare.py CASES.mat REF_OUT.mat

Per board count: the share of cases where our answer lies within 0.01 deg (rotation) of the reference's, for the
MSAC solution (``Ti``) and the refined one (``T``); the reference works in a frame whose scan plane is z = 10 mm,
so its translation is moved down by 10 mm and to metres before comparing.
"""

from __future__ import annotations

import sys

import numpy as np
from scipy.io import loadmat

from calib_core import calibrate
from calib_core.data.observations import BoardObservation, Observations
from calib_core.geometry.metrics import pose_errors
from calib_core.methods.francisco import MSAC_SCAN_PLANE_Z_MM

OUTLINE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


def observations(case) -> Observations:
    """Our Observations of one exported case (the outline is not read by the methods compared)."""
    Tp = np.array(case["Tp"], float)
    Pl = case["Pl"].ravel()
    boards = []
    for i in range(Tp.shape[2]):
        T = Tp[:, :, i].copy()
        T[:3, 3] /= 1e3
        boards.append(BoardObservation(T, OUTLINE, np.asarray(Pl[i], float).T / 1e3))
    Tt = np.array(case["T_true"], float)
    Tt[:3, 3] /= 1e3
    return Observations(tuple(boards), Tt)


def ours_frame(T_ref_mm: np.ndarray) -> np.ndarray:
    T = np.array(T_ref_mm, float)
    T[2, 3] -= MSAC_SCAN_PLANE_Z_MM
    T[:3, 3] /= 1e3
    return T


def main() -> None:
    cases = loadmat(sys.argv[1], simplify_cells=True)["cases"]
    ref = loadmat(sys.argv[2])
    rows = {}
    for k, c in enumerate(cases):
        if not ref["ok"][k, 0]:
            continue
        obs = observations(c)
        nb = obs.n_boards
        r0 = calibrate(obs, "vasconcelos_msac", verdict=False)
        r1 = calibrate(obs, "vasconcelos_msac_refined", verdict=False)
        e0 = pose_errors(r0.T_lidar_cam, ours_frame(ref["Ti_all"][:, :, k]))[0] if r0.ok else np.inf
        e1 = pose_errors(r1.T_lidar_cam, ours_frame(ref["T_all"][:, :, k]))[0] if r1.ok else np.inf
        inl_ref = np.flatnonzero(ref["inl_all"][k]).tolist()
        rows.setdefault(nb, []).append((e0 < 0.01, e1 < 0.01, inl_ref == r0.info.get("inliers") if r0.ok else False))
    for nb, v in sorted(rows.items()):
        a = np.array(v)
        print(f"{nb} boards: {len(a)} cases, MSAC same {a[:, 0].mean():.1%}, refined within 0.01 deg "
              f"{a[:, 1].mean():.1%}, same inliers {a[:, 2].mean():.1%}")


if __name__ == "__main__":
    main()
