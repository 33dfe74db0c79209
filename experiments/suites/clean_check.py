"""Clean-data check of the default method on the paper's board sweep (20 mm, seed 0: the same trials as
``results/paper``): valid rate, RMS rotation error over the CRLB, mean NEES, trials with a board rejected.

    python -m experiments clean-check [--trials 100]

Only absolute imports of ``calib_core`` and ``simulate``: run as a script against another checkout
(``python /path/to/experiments/suites/clean_check.py`` with that checkout installed) to compare two versions.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from ..engine.cli import int_list, positive_int, study_parser


def clean_check(trials: int, boards: Sequence[int] = (3, 4, 5, 6, 7, 8), method: str = "lidarcam") -> pd.DataFrame:
    """The paper's board sweep (20 mm, seed 0, trials 0..trials-1: the same data as ``results/paper``) with the
    default method: valid rate, RMS e_R over the mean CRLB, mean NEES, trials with a board rejected."""
    from calib_core import calibrate
    from calib_core.geometry.metrics import is_valid, nees, pose_errors
    from calib_core.refine.uncertainty import crlb
    from simulate import SimOptions, generate

    rows = []
    for n in boards:
        o = SimOptions(n_boards=n)
        v, eR, cr, ne, rej = [], [], [], [], 0
        for t in range(trials):
            obs = generate(o, seed=0, trial=t)
            res = calibrate(obs, method)
            if res.ok:
                e_R, e_t = pose_errors(res.T_lidar_cam, obs.T_lidar_cam_true)
                v.append(bool(is_valid(e_R, e_t)))
                if v[-1]:
                    eR.append(float(e_R))
                    ne.append(nees(res.T_lidar_cam, obs.T_lidar_cam_true, res.covariance)
                              if res.covariance is not None else np.nan)
                rej += bool(res.info.get("boards_rejected"))
            else:
                v.append(False)
            try:
                cr.append(crlb(obs, 0.02).rot_rms_deg)
            except Exception:  # noqa: BLE001 -- a degenerate set has no bound
                pass
        rms = float(np.sqrt(np.mean(np.square(eR))))
        rows.append({"n_boards": n, "valid_rate": np.mean(v), "rms_e_R_valid_deg": rms,
                     "crlb_rot_deg": float(np.mean(cr)), "rms_over_crlb": rms / float(np.mean(cr)),
                     "mean_nees_valid": float(np.nanmean(ne)), "trials_with_rejection": rej / trials})
    return pd.DataFrame(rows)


def main(argv: Sequence[str] | None = None) -> None:
    ap = study_parser(__doc__)
    ap.add_argument("--trials", type=positive_int, default=100)
    ap.add_argument("--boards", type=int_list(3), default="3,4,5,6,7,8", help="board counts (3 or more each)")
    args = ap.parse_args(argv)
    df = clean_check(args.trials, args.boards)
    print(df.to_string(index=False, float_format=lambda x: f"{x:.3f}"))
