"""The capture plan of captured boards against the calibration, and against the same boards with the grid written
the other way round.

For each observations file: ``lidarcam``'s 1-sigma, the plan's (``plan_from_observations`` with the calibration's
covariance and noise model, as ``lidarcam plan --from`` does), their ratio, the predicted 1-sigma after K proposed
boards and the boards to the target; then the same for the file with its grid transposed as a detector that keeps
the corners row-major over the transposed grid gives it (board x and y swapped, the normal flipped, the corners
re-ordered; ``lidarcam import --board-grid 5x8`` with the project's detector gives a quarter turn instead, which
``tests/calib_core/planning/test_plan_layout.py`` also covers).

    python dev/plan_orientation.py OUT_DIR OBS.json [OBS.json ...] [--next K]     (default K = 6)

Writes the transposed files to OUT_DIR and prints one line per file and orientation.
"""

from __future__ import annotations

import copy
import json
import sys
from pathlib import Path

import numpy as np

from calib_core import calibrate
from calib_core.data.io import load_observations
from calib_core.planning.observed import plan_from_observations

TRANSPOSE = np.array([[0.0, 1, 0, 0], [1, 0, 0, 0], [0, 0, -1, 0], [0, 0, 0, 1]])   # board' -> board


def transposed(path: Path, out: Path) -> Path:
    """``path``'s boards with the grid transposed (module docstring), written to ``out``."""
    d = copy.deepcopy(json.loads(path.read_text()))
    for b in d["boards"]:
        b["T_cam_board"] = (np.array(b["T_cam_board"]) @ TRANSPOSE).tolist()
        if b.get("outline") is not None:
            b["outline"] = np.array(b["outline"])[::-1][:, ::-1].tolist()
        if b.get("corners_board") is not None:
            cb, px = np.array(b["corners_board"], float), np.array(b["corners_px"], float)
            order = np.lexsort((np.round(cb[:, 1], 6), np.round(cb[:, 0], 6)))
            swapped = cb[order].copy()
            swapped[:, [0, 1]] = swapped[:, [1, 0]]
            b["corners_board"], b["corners_px"] = swapped.tolist(), px[order].tolist()
    out.write_text(json.dumps(d))
    return out


def line(path: Path, k: int) -> str:
    obs = load_observations(path)
    r = calibrate(obs)
    if not r.ok:
        return f"{path.name}: lidarcam refused ({r.reason[:120]})"
    p = plan_from_observations(obs, r.T_lidar_cam, k, covariance=r.covariance, info=r.info)
    cur, last = p.plan.current, p.plan.after[-1]
    return (f"{path.name}: calibrate {r.sigma_rot_deg:.3f} deg {r.sigma_trans_mm:.1f} mm; plan {cur.rot_sigma_deg:.3f} "
            f"deg {cur.trans_sigma_mm:.1f} mm (ratio {cur.rot_sigma_deg / r.sigma_rot_deg:.2f}, "
            f"{cur.trans_sigma_mm / r.sigma_trans_mm:.2f}); after {k}: {last.rot_sigma_deg:.3f} deg "
            f"{last.trans_sigma_mm:.1f} mm; to target {p.plan.to_target}; bearings "
            f"{p.rig.workspace.bearing_deg[0]:.0f}..{p.rig.workspace.bearing_deg[1]:.0f} deg; "
            f"roll {p.rig.workspace.roll_deg[0]:.0f} deg")


def main(argv: list[str]) -> None:
    k = 6
    if "--next" in argv:
        i = argv.index("--next")
        k, argv = int(argv[i + 1]), argv[:i] + argv[i + 2:]
    out = Path(argv[0])
    out.mkdir(parents=True, exist_ok=True)
    for f in map(Path, argv[1:]):
        print(line(f, k))
        print(line(transposed(f, out / f"{f.stem}_transposed.json"), k))


if __name__ == "__main__":
    main(sys.argv[1:])
