"""Which axes ``lidarcam``'s refusals name on the real rigs' subsets, and how flat each named axis really is.

For every subset of ``results/real/subsets_<rig>.csv`` on which ``lidarcam`` refused naming an axis (its
``refused_axes`` column), calibrate it again with the checkout's code and read the axes its reason names as not
determined (``experiments.summary.tables.refused_axes``); for each named axis compute its own profile-likelihood
1-sigma again (``calib_core.checks.profile.profile_extent`` along the axis, the other five re-fitted, across
``free_span``) at the refusal's extrinsic, on the boards and points the analysis used. The observations come from
the public sets (``experiments.real.real_data``'s loaders), cached in OUT_DIR.

    python dev/refusal_axes.py OUT_DIR [DATA_DIR] [rig ...]    (default ../shared/real-data, the four rigs)

Writes ``OUT_DIR/refusal_axes.csv`` (one row per refusal) and prints the refusals per rig and board count, the
axes named, and how many named axes have a profile 1-sigma under 10 deg (rotation) or 0.3 m (translation).
"""

from __future__ import annotations

import contextlib
import io
import sys
from pathlib import Path

import numpy as np
import pandas as pd

import calib_core
from calib_core.checks.degeneracy import AXES
from calib_core.checks.profile import free_span, profile_extent
from calib_core.data.io import load_observations, save_observations
from calib_core.errors import SolveFailure
from calib_core.methods.lidarcam import search_and_refine
from calib_core.methods.options import LidarcamOptions
from experiments.real import real_data as rd
from experiments.summary.tables import refused_axes

RIGS = ("edenshin", "kazmierczak", "nowicki", "yongkgu")
SMALL = (np.radians(10.0), 0.3)
"""A named axis whose profile 1-sigma is under this (rotation rad, translation m) is counted as wrongly named."""


def observations(short: str, data: Path, out: Path):
    """The rig's observations as the real experiment extracts them (cached in ``out``)."""
    path = out / f"obs_{short}.json"
    if not path.exists():
        name = {v: k for k, v in rd.SHORT.items()}[short]
        with contextlib.redirect_stdout(io.StringIO()):
            save_observations(rd._observations(rd.LOADERS[name](data / name))[0], path)
    return load_observations(path)


def named_axes(obs, subset: list[int]) -> dict:
    """One refusal: the axes its reason names, each named axis's own profile 1-sigma (deg or m; inf: flat), and
    the analysis's full set of axes (the ``fixed=`` hint)."""
    sub = obs.subset(subset)
    r = calib_core.calibrate(sub, "lidarcam")
    deg = r.info.get("degeneracy") or {}
    row = {"n_boards": len(subset), "subset": " ".join(map(str, subset)), "ok": r.ok,
           "named": " ".join(refused_axes(r.reason)), "hint_axes": " ".join(deg.get("axes", []))}
    if r.ok or not deg:
        return row
    T = np.asarray(r.candidates[0])
    try:                                    # the analysis's own boards and points, where it ran at the optimum
        found = search_and_refine(sub, LidarcamOptions())
        sub = found.tests.obs_used if np.allclose(found.best.T, T) else sub
    except SolveFailure:                    # explain_failure: the subset at its vertical start
        pass
    L, sigma = deg["scale_m"], deg["range_sigma_m"]
    sig, small = [], []
    for a in refused_axes(r.reason):
        j = AXES.index(a)
        p = profile_extent(sub.scan_data, T, np.eye(6)[j], free_span(L), L, sigma)
        value = p if j < 3 else p * L
        sig.append(f"{a}={np.degrees(value) if j < 3 else value:.3g}{'deg' if j < 3 else 'm'}")
        if np.isfinite(value) and value < SMALL[j >= 3]:
            small.append(a)
    return {**row, "named_profile": " ".join(sig), "named_small": " ".join(small)}


def main(argv: list[str]) -> None:
    out = Path(argv[0])
    out.mkdir(parents=True, exist_ok=True)
    data = Path(argv[1]) if len(argv) > 1 else Path("../shared/real-data")
    rows = []
    for short in argv[2:] or RIGS:
        obs = observations(short, data, out)
        d = pd.read_csv(f"results/real/subsets_{short}.csv")
        d = d[(d.method == "lidarcam") & (d.refused_axes.fillna("") != "")]
        rows += [{"rig": short, **named_axes(obs, [int(i) for i in s.split()])} for s in d.subset]
    df = pd.DataFrame(rows)
    df.to_csv(out / "refusal_axes.csv", index=False)
    ref = df[df.named != ""]
    print(ref.groupby(["rig", "n_boards"]).size().rename("refusals").to_string())
    print("axes named:", pd.Series(" ".join(ref.named).split()).value_counts().to_dict())
    small = ref.get("named_small", pd.Series(dtype=str)).fillna("")
    print(f"named axes with a profile 1-sigma under 10 deg / 0.3 m: {int(small.str.split().map(len).sum())} in "
          f"{int((small != '').sum())} of {len(ref)} refusals")


if __name__ == "__main__":
    main(sys.argv[1:])
