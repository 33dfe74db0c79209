"""The minimal solvers' benchmark (PoseLib / posebench style), part of ``make bench``: per board triple, for each
minimal solver (``calib_core.solvers.candidates.MINIMAL_SOLVERS``), the share of triples with a candidate within
1 deg and 50 mm of the truth, the share within 1e-6 deg (meaningful on noise-free data), the mean number of
candidates, the share of triples refused (degenerate or no real root) and the time per triple of one vectorised
call, over the range-noise levels of the paper's sweeps (0 = noise-free, then 5-30 mm).

Triples: every ``C(6,3) = 20`` triple of simulated 6-board problems (the paper's sweep B), lines fitted once.

    python -m experiments solvers [--problems 50] [--noise-mm 0 5 10 15 20 25 30] [--out results/bench]
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from calib_core.data.lines import triple_inputs
from calib_core.geometry.metrics import rotation_error_deg, translation_error_m
from calib_core.solvers._common import board_triples
from calib_core.solvers.candidates import MINIMAL_SOLVERS
from lidarcam.rig.markdown import md_table
from simulate import SimOptions, generate

from ..engine.cli import nonnegative_float, positive_int, study_parser
from ..engine.keep import write_unless_timings

NOISE_LEVELS_MM = (0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0)
NEAR_DEG, NEAR_M = 1.0, 0.050
EXACT_DEG = 1e-6


def solver_rows(n_problems: int, noise_mm: float, n_boards: int = 6, seed: int = 4242, repeats: int = 3) -> list[dict]:
    """One row per minimal solver on the triples of ``n_problems`` problems at ``noise_mm``; the time is the best of
    ``repeats`` calls."""
    obs_list = [generate(SimOptions(n_boards=n_boards, noise_mm=noise_mm), seed=seed, trial=i)
                for i in range(n_problems)]
    tri = board_triples(n_boards)
    parts = [triple_inputs(o, tri) for o in obs_list]
    n, d, p, u = (np.concatenate([x[k] for x in parts]) for k in range(4))
    T = np.repeat(np.stack([o.T_lidar_cam_true for o in obs_list]), len(tri), axis=0)
    rows = []
    for name, solve in MINIMAL_SOLVERS.items():
        dt = float("inf")
        for _ in range(repeats):                                                 # best of: a shared core
            t0 = time.perf_counter()
            sol = solve(n, d, p, u)
            dt = min(dt, time.perf_counter() - t0)
        eR = rotation_error_deg(sol.T_lidar_cam[:, :3, :3], T[sol.triple, :3, :3])
        et = translation_error_m(sol.T_lidar_cam[:, :3, 3], T[sol.triple, :3, 3])
        near = np.zeros(len(n), dtype=bool)
        exact = np.zeros(len(n), dtype=bool)
        near[sol.triple[(eR < NEAR_DEG) & (et < NEAR_M)]] = True
        exact[sol.triple[eR < EXACT_DEG]] = True
        refused = np.array([r is not None for r in sol.reasons])
        rows.append({"solver": name, "noise_mm": noise_mm, "triples": len(n),
                     "near_rate": float(near.mean()), "exact_rate": float(exact.mean()),
                     "candidates": len(sol) / len(n), "refused": float(refused.mean()),
                     "us_per_triple": 1e6 * dt / len(n)})
    return rows


def table(rows: list[dict]) -> list[str]:
    """Markdown table of ``solver_rows`` rows."""
    head = ["solver", "noise mm", "triples", f"candidate within {NEAR_DEG:g} deg / {1e3 * NEAR_M:g} mm",
            f"within {EXACT_DEG:g} deg", "candidates per triple", "refused", "us per triple"]
    return md_table(head, [[r["solver"], f"{r['noise_mm']:g}", r["triples"], f"{100 * r['near_rate']:.1f}%",
                            f"{100 * r['exact_rate']:.1f}%", f"{r['candidates']:.2f}", f"{100 * r['refused']:.1f}%",
                            f"{r['us_per_triple']:.1f}"] for r in rows])


def run(n_problems: int = 50, noise_levels: Sequence[float] = NOISE_LEVELS_MM,
        out: str | Path | None = None) -> list[dict]:
    """All rows; prints the table and, with ``out``, writes it to ``out/solvers.md``."""
    rows = [r for s in noise_levels for r in solver_rows(n_problems, s)]
    lines = ["# Minimal solvers per board triple", "",
             f"`python -m experiments solvers --problems {n_problems}`: every triple of {n_problems} simulated "
             "6-board problems per noise level (the paper's settings), one vectorised call per solver and level "
             "(the best time of 3), one process.", "", *table(rows), ""]
    print("\n".join(lines))
    if out is not None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        write_unless_timings(out / "solvers.md", "\n".join(lines), columns=("us per triple",))  # times alone: kept
    return rows


def main(argv: Sequence[str] | None = None) -> None:
    ap = study_parser(__doc__)
    ap.add_argument("--problems", type=positive_int, default=50)
    ap.add_argument("--noise-mm", type=nonnegative_float, nargs="+", default=list(NOISE_LEVELS_MM))
    ap.add_argument("--out", type=Path, default=Path("results/bench"))
    a = ap.parse_args(argv)
    run(a.problems, a.noise_mm, a.out)
