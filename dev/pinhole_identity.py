"""Seeded pinhole problems through ``calibrate``: every output a number, for a bit-for-bit comparison of two trees.

Run ``python dev/pinhole_identity.py OUT.json`` with ``PYTHONPATH`` set to the tree under test; compare the two
files with ``python dev/pinhole_identity.py --compare A.json B.json``. A development check of a change that must
leave the pinhole camera's numbers as they were.
"""

from __future__ import annotations

import json
import sys

import numpy as np

CASES = [({"pose_mode": "pixel"}, "lidarcam"), ({"pose_mode": "pixel", "focal_error_rel": 0.01,
          "principal_point_error_px": 3.0, "distortion_error": 0.01}, "lidarcam"),
         ({"pose_mode": "exact"}, "lidarcam"), ({"pose_mode": "pixel"}, "zhang_pless+joint"),
         ({"pose_mode": "pixel", "n_boards": 10, "noise_mm": 10.0}, "vasconcelos")]


def run(out: str) -> None:
    from calib_core import calibrate
    from simulate import SimOptions, generate
    rows = []
    for ci, (opts, method) in enumerate(CASES):
        for trial in range(4):
            obs = generate(SimOptions(**opts), seed=7, trial=trial)
            r = calibrate(obs, method=method)
            rows.append({"case": ci, "trial": trial, "ok": r.ok, "reason": r.reason,
                         "T": None if r.T_lidar_cam is None else np.asarray(r.T_lidar_cam).tolist(),
                         "cov": None if r.covariance is None else np.asarray(r.covariance).tolist(),
                         "warnings": list(r.warnings)})
    with open(out, "w") as f:
        json.dump(rows, f)


def compare(a: str, b: str) -> int:
    A, B = json.load(open(a)), json.load(open(b))
    diff = [(x["case"], x["trial"]) for x, y in zip(A, B, strict=True) if x != y]
    print(f"{len(A)} problems, {len(diff)} differ: {diff}")
    return 1 if diff else 0


if __name__ == "__main__":
    sys.exit(compare(sys.argv[2], sys.argv[3]) if sys.argv[1] == "--compare" else run(sys.argv[1]))
