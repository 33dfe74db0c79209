"""Efficiency and honesty of ``lidarcam`` on the simulated wide-angle rigs (conf/preset/wide-fisheye.yaml and
wide-ds.yaml): per trial the error against the truth, the joint model's Cramer-Rao bound at the true board poses
(``experiments.engine.trial.uncertainty_columns``, as the crlb_joint experiment computes it) and the NEES; then RMS
error over RMS bound and the NEES median (``experiments.summary.aggregate``'s definitions).

    python dev/wide_angle_crlb.py OUT_DIR [N_TRIALS] [PRESET ...]     (default 100 trials, both presets)

Writes ``OUT_DIR/wide_angle_<preset>.csv`` (one row per trial) and prints one summary line per preset.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd
import yaml

from experiments.engine.cell import Cell
from experiments.engine.trial import simulate_trial
from experiments.summary.aggregate import _efficiency

ROOT = Path(__file__).resolve().parents[1]


def preset_sim(name: str) -> dict:
    """Every SimOptions field: the preset file's (its scene, camera and noise groups, flattened), else the
    default."""
    from simulate import SimOptions

    d = yaml.safe_load((ROOT / "conf" / "preset" / f"{name}.yaml").read_text())
    return {**SimOptions().to_dict(), **{k: v for g in ("scene", "lidar", "camera", "noise")
                                        for k, v in (d.get(g) or {}).items()}}


def main(out: str, n: int, presets: list[str]) -> None:
    Path(out).mkdir(parents=True, exist_ok=True)
    for name in presets:
        cell = Cell(sweep="wide_angle", sim=preset_sim(name), seed=0)
        rows = [r for t in range(n) for r in simulate_trial(cell, t, ["lidarcam"])]
        df = pd.DataFrame(rows)
        df.to_csv(Path(out) / f"wide_angle_{name}.csv", index=False)
        v = df[df["ok"] & df["valid"]]
        eff = _efficiency(v)
        print(f"{name}: {len(v)}/{len(df)} valid; rms/crlb rot {eff['rms_over_crlb_rot']:.3f} trans "
              f"{eff['rms_over_crlb_trans']:.3f}; NEES median {eff['median_nees']:.2f} mean {eff['mean_nees']:.2f}; "
              f"rms e_R {eff['rms_e_R_deg']:.3f} deg e_t {eff['rms_e_t_mm']:.1f} mm; failures: "
              f"{df.loc[~df['ok'], 'reason'].value_counts().head(2).to_dict()}")
        sys.stdout.flush()


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 100,
         sys.argv[3:] or ["wide-fisheye", "wide-ds"])
