"""Store exported cases and the reference's answers as a numeric test fixture (a development check).

    python dev/reference/collect_fixture.py CASES.mat REF_OUT.mat tests/fixtures/francisco_reference.npz

Numbers only: per case the board poses (metres), the scans (metres), the truth, and the reference's MSAC
solution ``Ti``, refined solution ``T`` (both moved to our frame: scan plane z = 0, metres) and inlier boards.
"""

from __future__ import annotations

import sys

import numpy as np
from compare import observations, ours_frame
from scipy.io import loadmat


def main() -> None:
    cases = loadmat(sys.argv[1], simplify_cells=True)["cases"]
    ref = loadmat(sys.argv[2])
    keep = [k for k in range(len(cases)) if ref["ok"][k, 0]]
    poses, scans, counts, nb, Ti, T, inl, truth, trial = [], [], [], [], [], [], [], [], []
    for k in keep:
        obs = observations(cases[k])
        nb.append(obs.n_boards)
        trial.append(int(cases[k]["trial"]))
        truth.append(obs.T_lidar_cam_true)
        for b in obs.boards:
            poses.append(b.T_cam_board)
            scans.append(b.scan)
            counts.append(len(b.scan))
        Ti.append(ours_frame(ref["Ti_all"][:, :, k]))
        T.append(ours_frame(ref["T_all"][:, :, k]))
        inl.append(ref["inl_all"][k].astype(bool))
    np.savez_compressed(sys.argv[3], boards=np.array(nb), trial=np.array(trial), T_cam_board=np.array(poses),
                        scan_xy=np.concatenate(scans), scan_count=np.array(counts), T_true=np.array(truth),
                        ref_msac=np.array(Ti), ref_refined=np.array(T), ref_inliers=np.array(inl))
    print(f"{len(keep)} cases -> {sys.argv[3]}")


if __name__ == "__main__":
    main()
