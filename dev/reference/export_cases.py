"""Export seeded simulated cases for the authors' MATLAB reference of Francisco's method (a development check).

    python dev/reference/export_cases.py OUT.mat [--boards 3 4 6 8] [--cases 100] [--seed 2023]

Writes, per case, the board poses ``Tp`` (4x4xN, camera frame, millimetres) and the scans ``Pl`` (1xN cell of
2xK points, lidar scan plane, millimetres) that the reference's ``lccMinSol(Tp, Pl)`` takes, plus the true
``T_lidar_cam`` (mm).  ``run_reference.m`` runs the reference on them; ``collect_fixture.py`` stores the inputs and
its answers, numbers only, as the test fixture.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.io import savemat

from simulate import SimOptions, generate


def case_arrays(obs) -> dict:
    """The reference's inputs of one problem, in millimetres."""
    Tp = np.stack([b.T_cam_board for b in obs.boards], axis=2).copy()
    Tp[:3, 3, :] *= 1e3
    Pl = np.empty((1, obs.n_boards), dtype=object)
    for i, b in enumerate(obs.boards):
        Pl[0, i] = 1e3 * b.scan.T
    T = obs.T_lidar_cam_true.copy()
    T[:3, 3] *= 1e3
    return {"Tp": Tp, "Pl": Pl, "T_true": T}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--boards", type=int, nargs="+", default=[3, 4, 6, 8])
    ap.add_argument("--cases", type=int, default=100)
    ap.add_argument("--seed", type=int, default=2023)
    ap.add_argument("--noise-mm", type=float, default=20.0)
    ap.add_argument("--sweep-trials", action="store_true",
                    help="the paper sweep A's own trials (make reproduce-paper's seeds) instead of --seed")
    a = ap.parse_args()
    cases = []
    for nb in a.boards:
        if a.sweep_trials:
            from experiments.config.sweeps import experiment_cells

            cell = experiment_cells("boards", [f"scene.n_boards={nb}", f"n_trials={a.cases}"])[0]
            opts, seed, stream = SimOptions(**cell.sim), cell.seed, cell.crn_stream
        else:
            opts, seed, stream = SimOptions(n_boards=nb, noise_mm=a.noise_mm), a.seed, None
        for i in range(a.cases):
            obs = generate(opts, seed=seed, trial=i, stream=stream)
            cases.append({**case_arrays(obs), "boards": nb, "trial": i})
    cell = np.empty((1, len(cases)), dtype=object)
    for k, c in enumerate(cases):
        cell[0, k] = c
    savemat(a.out, {"cases": cell, "seed": a.seed, "noise_mm": a.noise_mm})
    print(f"{len(cases)} cases -> {a.out}")


if __name__ == "__main__":
    main()
