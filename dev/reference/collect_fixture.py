"""Store exported cases and the reference's answers as a numeric test fixture (a development check).

    python dev/reference/collect_fixture.py OUT.npz CASES.mat:REF_OUT.mat:TOLERANCE [...]

Numbers only: per case the board poses (metres), the scans (metres), the truth, and the reference's MSAC solution
(``Ti``), its refined solution (``T``; NaN for an MSAC-only run) and inlier boards, both solutions moved to our
frame (scan plane z = 0, metres). ``TOLERANCE`` names the reference's optimiser setting of that run: ``default``
(the code as written) or ``tight`` (``TolFun`` 1e-14, to test that both refinements share their minimum).
"""

from __future__ import annotations

import sys

import numpy as np
from compare import observations, ours_frame
from scipy.io import loadmat


def main() -> None:
    poses, scans, counts, nb, Ti, T, inl, truth, trial, tight = [], [], [], [], [], [], [], [], [], []
    for spec in sys.argv[2:]:
        cases_path, out_path, tol = spec.split(":")
        cases = loadmat(cases_path, simplify_cells=True)["cases"]
        ref = loadmat(out_path)
        for k in range(len(cases)):
            if not ref["ok"][k, 0]:
                continue
            obs = observations(cases[k])
            nb.append(obs.n_boards)
            trial.append(int(cases[k]["trial"]))
            truth.append(obs.T_lidar_cam_true)
            tight.append(tol == "tight")
            for b in obs.boards:
                poses.append(b.T_cam_board)
                scans.append(b.scan)
                counts.append(len(b.scan))
            Ti.append(ours_frame(ref["Ti_all"][:, :, k]))
            T.append(ours_frame(ref["T_all"][:, :, k]))
            inl.append(ref["inl_all"][k].astype(bool))
    np.savez_compressed(sys.argv[1], boards=np.array(nb), trial=np.array(trial), T_cam_board=np.array(poses),
                        scan_xy=np.concatenate(scans), scan_count=np.array(counts), T_true=np.array(truth),
                        ref_msac=np.array(Ti), ref_refined=np.array(T), ref_inliers=np.array(inl),
                        ref_tight=np.array(tight))
    print(f"{len(nb)} cases -> {sys.argv[1]}")


if __name__ == "__main__":
    main()
