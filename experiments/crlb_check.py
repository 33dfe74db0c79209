"""Is ``lidarcam`` efficient and consistent? Monte-Carlo check against the CRLB of the range-noise model.

Per (boards, noise) cell, over simulated trials (``simulate.generate``): valid rate of ``lidarcam``; RMS
rotation error (norm of the rotation vector, = e_R) and translation error, against the CRLB at the truth
(``ratio = sqrt(mean |e|^2) / sqrt(mean trace CRLB)``, over valid trials; target <= 1.1); NEES
``e^T P^-1 e`` with the reported covariance ``P`` (expected 6); and the RMS of the same answer refined on the
point-to-plane distances instead (the cost that is not the likelihood). For few boards, the share of trials
where some candidate of the minimal solver is valid, against ``lidarcam``'s valid rate.

Run (about 3 minutes on 2 cores):
    OMP_NUM_THREADS=1 python -m experiments.crlb_check --trials 200 --n-jobs 2 --out results/crlb_check.json
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
from joblib import Parallel, delayed

from calib_core import calibrate
from calib_core.metrics import error_vector, is_valid, nees, pose_errors
from calib_core.refine import refine
from calib_core.uncertainty import UncertaintyError, crlb
from simulate import SimOptions, generate


def run_trial(n_boards: int, noise_mm: float, seed: int, trial: int, small: bool) -> dict:
    """One trial: lidarcam's errors, NEES, CRLB, the point-to-plane refinement's error, candidate validity."""
    obs = generate(SimOptions(n_boards=n_boards, noise_mm=noise_mm), seed=seed, trial=trial)
    T_true = obs.T_lidar_cam_true
    out: dict = {"n_boards": n_boards, "noise_mm": noise_mm, "trial": trial, "small": small}
    r = calibrate(obs, "lidarcam")
    C = r.candidates             # the minimal solver's (boards with a line-like scan) and, at >= 5 boards, Zhang's
    out["some_candidate_valid"] = bool(len(C) and np.any(is_valid(*pose_errors(C, T_true))))
    out["ok"] = r.ok
    if not r.ok:
        out["valid"] = False
        return out
    e = error_vector(r.T_lidar_cam, T_true)
    out["valid"] = bool(is_valid(*pose_errors(r.T_lidar_cam, T_true)))
    out["rot2"] = float(e[:3] @ e[:3])
    out["trans2"] = float(e[3:] @ e[3:])
    out["nees"] = nees(r.T_lidar_cam, T_true, r.covariance)
    try:
        b = crlb(obs, noise_mm / 1000.0)
        out["crlb_rot2"] = float(np.trace(b.cov[:3, :3]))
        out["crlb_trans2"] = float(np.trace(b.cov[3:, 3:]))
    except UncertaintyError:
        out["crlb_rot2"] = out["crlb_trans2"] = float("nan")
    out["norm_rot2"] = out["rot2"] / out["crlb_rot2"]
    out["norm_trans2"] = out["trans2"] / out["crlb_trans2"]
    if not small:
        rp = refine(obs.scan_data, r.T_lidar_cam, residual="plane")
        ep = error_vector(rp.T_lidar_cam, T_true)
        out["plane_rot2"] = float(ep[:3] @ ep[:3])
        out["plane_trans2"] = float(ep[3:] @ ep[3:])
    return out


def summarise(rows: list[dict]) -> dict:
    """The cell's figures (degrees, millimetres)."""
    v = [r for r in rows if r["valid"]]
    s: dict = {"trials": len(rows), "valid_rate": len(v) / len(rows),
               "some_candidate_valid_rate": float(np.mean([r["some_candidate_valid"] for r in rows]))}
    if not v:
        return s

    def rms(key):
        return float(np.sqrt(np.nanmean([r[key] for r in v])))

    s.update(rms_rot_deg=float(np.degrees(rms("rot2"))), rms_trans_mm=1000 * rms("trans2"),
             crlb_rot_deg=float(np.degrees(rms("crlb_rot2"))), crlb_trans_mm=1000 * rms("crlb_trans2"))
    s["ratio_rot"] = s["rms_rot_deg"] / s["crlb_rot_deg"]
    s["ratio_trans"] = s["rms_trans_mm"] / s["crlb_trans_mm"]
    # per trial, each error against its own scene's bound: sqrt(mean(|e|^2 / trace CRLB)), ~1 when efficient
    s["ratio_rot_per_trial"] = rms("norm_rot2")
    s["ratio_trans_per_trial"] = rms("norm_trans2")
    nees = np.array([r["nees"] for r in v])
    s.update(nees_mean=float(nees.mean()), nees_median=float(np.median(nees)),
             nees_mean_below_99pct=float(nees[nees < np.quantile(nees, 0.99)].mean()))
    if "plane_rot2" in v[0]:
        s.update(plane_rms_rot_deg=float(np.degrees(rms("plane_rot2"))), plane_rms_trans_mm=1000 * rms("plane_trans2"))
    return s


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--trials", type=int, default=200)
    p.add_argument("--small-trials", type=int, default=None, help="trials at the small board counts (default --trials)")
    p.add_argument("--boards", type=int, nargs="+", default=[6, 8])
    p.add_argument("--noise-mm", type=float, nargs="+", default=[20.0, 30.0])
    p.add_argument("--small-boards", type=int, nargs="+", default=[3, 4], help="at 20 mm only")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-jobs", type=int, default=2)
    p.add_argument("--out", help="write the summary JSON here")
    a = p.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    cells = [(n, s, False, a.trials) for n in a.boards for s in a.noise_mm]
    cells += [(n, 20.0, True, a.small_trials or a.trials) for n in a.small_boards]
    t0 = time.perf_counter()
    jobs = [delayed(run_trial)(n, s, a.seed, k, small) for n, s, small, T in cells for k in range(T)]
    rows = Parallel(n_jobs=a.n_jobs, batch_size=16)(jobs)
    summary = []
    for n, s, small, _ in cells:
        cell = summarise([r for r in rows if r["n_boards"] == n and r["noise_mm"] == s and
                          r["small"] == small])
        cell.update(n_boards=n, noise_mm=s)
        summary.append(cell)
        print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in cell.items()}))
    print(f"{time.perf_counter() - t0:.0f} s")
    if a.out:
        with open(a.out, "w") as f:
            json.dump({"command": "python -m experiments.crlb_check " + " ".join(argv or []), "cells": summary}, f,
                      indent=1)
    return 0


if __name__ == "__main__":
    import sys

    raise SystemExit(main(sys.argv[1:]))
