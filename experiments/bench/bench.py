"""``make bench``: lidarcam's median time per call and its ratio to peng2022's at 3-8 boards (exact poses, timed
alternately in one run), the time of one ``calibrate`` per registered method on 8 boards (median over many
repetitions), how the default method's time grows with the number of boards (8, 20, 40, 100), the minimal
solver's throughput on one core (``calib_core.solvers.vasconcelos.solve_triples``) and its accuracy on noise-free
simulated triples (closed-form and eigenvalue quartic roots), and the joint model over image corners and ranges at
8 and 40 boards (0.5 px corner noise): the joint refinement alone (``calib_core.refine.joint.joint_refine`` from the
range-only answer) and whole ``calibrate`` calls that end in it.

    python -m experiments bench [--boards 8] [--problems 10] [--repeats 20] [--triples 10000] [--joint-boards 8 40]
                                [--scaling 8,20,40,100] [--scaling-problems 3]
                                [--ratio-boards 3,4,5,6,7,8] [--ratio-problems 10] [--ratio-repeats 3]
                                [--ratio-seeds 4321,8642]

Single process, run it with ``OMP_NUM_THREADS=1`` (the Makefile exports it) for one-core numbers.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from calib_core import METHODS, calibrate
from calib_core.data.lines import triple_inputs
from calib_core.geometry.metrics import is_valid, pose_errors
from simulate import SimOptions, generate

from ..engine.catalog import method_order
from ..engine.cli import int_at_least, int_list, positive_int, study_parser


def problems(n_boards: int, count: int, seed: int = 12345) -> list:
    """``count`` simulated problems of ``n_boards`` boards with the simulator's default (paper) settings."""
    opts = SimOptions(n_boards=n_boards)
    return [generate(opts, seed=seed, trial=i) for i in range(count)]


def time_methods(obs_list: list, repeats: int) -> list[dict]:
    """Median wall time of one ``calibrate`` per method over ``repeats`` runs on each problem."""
    rows = []
    for m in method_order(METHODS):
        times, valid, error = [], [], ""
        for obs in obs_list:
            try:
                for _ in range(repeats):
                    t0 = time.perf_counter()
                    res = calibrate(obs, m)
                    times.append(time.perf_counter() - t0)
            except Exception as exc:  # noqa: BLE001 -- one broken method must not hide the others' timings
                error = f"{type(exc).__name__}: {exc}"[:60]
                break
            if res.ok:
                valid.append(bool(is_valid(*pose_errors(res.T_lidar_cam, obs.T_lidar_cam_true))))
            else:
                valid.append(False)
        rows.append({"method": m, "median_ms": 1e3 * float(np.median(times)) if times else float("nan"),
                     "p90_ms": 1e3 * float(np.percentile(times, 90)) if times else float("nan"),
                     "runs": len(times), "valid": f"{sum(valid)}/{len(valid)}" + (f" error {error}" if error else "")})
    return rows


RATIO_SEEDS = (4321, 8642)
"""The seeds of the ratio table's problem sets: the bench's own, and a second set of the paper's 20 mm scenes."""


def time_ratio(counts: Sequence[int], n_problems: int, repeats: int, method: str = "lidarcam",
               reference: str = "peng2022", seed: int = RATIO_SEEDS[0]) -> list[dict]:
    """Per board count, the median ms of one ``calibrate`` of ``method`` and of ``reference`` on the same
    ``n_problems`` problems drawn with ``seed`` (exact board poses, the simulator's defaults: the paper's 20 mm),
    the two timed alternately call by call so that both see the same machine; ``ratio`` is method over reference."""
    rows = []
    for n in counts:
        t: dict[str, list[float]] = {method: [], reference: []}
        for obs in problems(n, n_problems, seed=seed):
            for _ in range(repeats):
                for m in (reference, method):
                    t0 = time.perf_counter()
                    calibrate(obs, m)
                    t[m].append(time.perf_counter() - t0)
        ms = {m: 1e3 * float(np.median(v)) for m, v in t.items()}
        rows.append({"boards": n, "method_ms": ms[method], "reference_ms": ms[reference],
                     "ratio": ms[method] / ms[reference], "runs": len(t[method])})
    return rows


def time_scaling(counts: Sequence[int], n_problems: int, method: str = "lidarcam") -> list[dict]:
    """Median wall time of one ``calibrate(obs, method)`` on ``n_problems`` problems per board count."""
    rows = []
    for n in counts:
        times, valid = [], 0
        for obs in problems(n, n_problems, seed=777):
            t0 = time.perf_counter()
            res = calibrate(obs, method)
            times.append(time.perf_counter() - t0)
            valid += bool(res.ok and is_valid(*pose_errors(res.T_lidar_cam, obs.T_lidar_cam_true)))
        rows.append({"boards": n, "median_s": float(np.median(times)), "max_s": float(np.max(times)),
                     "valid": f"{valid}/{len(times)}"})
    base = rows[0]["median_s"] if rows else float("nan")
    for r in rows:
        r["ratio"] = r["median_s"] / base
    return rows


def triple_arrays(obs_list: list, n_triples: int):
    """Stacked plane/line arrays of at least ``n_triples`` board triples drawn from ``obs_list``, and the true
    ``T_lidar_cam`` (B,4,4) of each triple's problem."""
    from calib_core.solvers._common import board_triples

    ns, ds, ps, us, Ts = [], [], [], [], []
    while sum(len(x) for x in ns) < n_triples:
        for obs in obs_list:
            tri = board_triples(obs.n_boards)
            n, d, p, u = triple_inputs(obs, tri)
            ns.append(n), ds.append(d), ps.append(p), us.append(u)
            Ts.append(np.repeat(obs.T_lidar_cam_true[None], len(tri), axis=0))
    return tuple(np.concatenate(a)[:n_triples] for a in (ns, ds, ps, us, Ts))


def minimal_accuracy(n_boards: int, count: int, n_triples: int, quartic: str = "closed") -> dict:
    """On noise-free simulated triples: the largest error of the candidate nearest the truth
    (``max(|dR|_F, |dt| in m)``), over triples the solver solved, binned by the smallest singular value of
    the triple's normal matrix (its conditioning)."""
    from calib_core.solvers.vasconcelos import solve_triples

    obs_list = [generate(SimOptions(n_boards=n_boards, noise_mm=0.0), seed=777, trial=i) for i in range(count)]
    n, d, p, u, T = triple_arrays(obs_list, n_triples)
    sol = solve_triples(n, d, p, u, quartic=quartic)
    err = np.maximum(np.linalg.norm(sol.T_lidar_cam[:, :3, :3] - T[sol.triple, :3, :3], axis=(1, 2)),
                     np.linalg.norm(sol.T_lidar_cam[:, :3, 3] - T[sol.triple, :3, 3], axis=1))
    best = np.full(len(n), np.inf)
    np.minimum.at(best, sol.triple, err)
    solved = np.array([r is None for r in sol.reasons])
    sv = np.linalg.svd(n, compute_uv=False)[:, -1]
    out = {"quartic": quartic, "triples": len(n), "solved": int(solved.sum())}
    for lo in (1e-3, 1e-2, 1e-1):
        m = solved & (sv >= lo)
        out[f"max_err(sv>={lo:g})"] = float(best[m].max()) if m.any() else float("nan")
    return out


def time_minimal(obs_list: list, n_triples: int, repeats: int = 3) -> dict:
    """Triples per second of one vectorised ``solve_triples`` call on ``n_triples`` triples (best of repeats)."""
    from calib_core.solvers.vasconcelos import solve_triples

    n, d, p, u, _ = triple_arrays(obs_list, n_triples)
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        sol = solve_triples(n, d, p, u)
        best = min(best, time.perf_counter() - t0)
    return {"triples": len(n), "seconds": best, "triples_per_s": len(n) / best,
            "solutions": int(len(sol.T_lidar_cam))}


def _median_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def time_joint(n_boards: int, count: int, repeats: int, seed: int = 12345) -> dict:
    """Median ms of the joint refinement alone, of ``calibrate(lidarcam)`` and of ``zhang_pless_linear+joint`` on
    ``count`` problems of ``n_boards`` boards with image corners (0.5 px) (``lidarcam`` at every board count: its
    consensus search samples the hypotheses beyond 12 boards)."""
    from calib_core.refine.joint import joint_refine

    opts = SimOptions(n_boards=n_boards, pose_mode="pixel", pixel_noise_px=0.5)
    obs_list = [generate(opts, seed=seed, trial=i) for i in range(count)]
    out = {"boards": n_boards, "joint_refine_ms": [], "lidarcam_ms": [], "zpl_joint_ms": []}
    for obs in obs_list:
        T0 = calibrate(obs, "zhang_pless_linear+ml").T_lidar_cam
        out["joint_refine_ms"].append(_median_ms(lambda o=obs, T=T0: joint_refine(o, T), repeats))
        out["zpl_joint_ms"].append(_median_ms(lambda o=obs: calibrate(o, "zhang_pless_linear+joint"), repeats))
        out["lidarcam_ms"].append(_median_ms(lambda o=obs: calibrate(o, "lidarcam"), repeats))
    return {k: (float(np.median(v)) if v else float("nan")) if isinstance(v, list) else v for k, v in out.items()}


def method_lines(rows: list[dict]) -> list[str]:
    """The per-method table of ``time_methods`` rows, its first column as wide as the longest method name."""
    w = max([22, *(len(r["method"]) + 2 for r in rows)])
    return [f"  {'method':<{w}}{'median ms':>11}{'p90 ms':>10}{'runs':>7}  valid",
            *(f"  {r['method']:<{w}}{r['median_ms']:>11.2f}{r['p90_ms']:>10.2f}{r['runs']:>7}  {r['valid']}"
              for r in rows)]


def main(argv: Sequence[str] | None = None) -> None:
    ap = study_parser(__doc__)
    ap.add_argument("--boards", type=int_at_least(3), default=8)
    ap.add_argument("--problems", type=positive_int, default=10)
    ap.add_argument("--repeats", type=positive_int, default=20)
    ap.add_argument("--triples", type=positive_int, default=10_000)
    ap.add_argument("--scaling", type=int_list(3, empty=True), default="8,20,40,100",
                    help="board counts of the default method's scaling table ('': none)")
    ap.add_argument("--scaling-problems", type=positive_int, default=3)
    ap.add_argument("--joint-boards", type=int_at_least(3), nargs="*", default=[8, 40])
    ap.add_argument("--ratio-boards", type=int_list(3, empty=True), default="3,4,5,6,7,8",
                    help="board counts of the lidarcam / peng2022 table ('': none)")
    ap.add_argument("--ratio-problems", type=positive_int, default=10)
    ap.add_argument("--ratio-repeats", type=positive_int, default=3)
    ap.add_argument("--ratio-seeds", type=int_list(0, empty=True), default=",".join(map(str, RATIO_SEEDS)),
                    help="seeds of the ratio table's problem sets, one table each (default: %(default)s)")
    args = ap.parse_args(argv)
    ratio_counts = args.ratio_boards
    for seed in args.ratio_seeds if ratio_counts else ():
        print(f"lidarcam vs peng2022 per call, exact board poses, {args.ratio_problems} problems (seed {seed}) x "
              f"{args.ratio_repeats} repetitions each, timed alternately:")
        print(f"  {'boards':>6}{'lidarcam ms':>13}{'peng2022 ms':>13}{'ratio':>8}")
        for r in time_ratio(ratio_counts, args.ratio_problems, args.ratio_repeats, seed=seed):
            print(f"  {r['boards']:>6}{r['method_ms']:>13.2f}{r['reference_ms']:>13.2f}{r['ratio']:>8.1f}")
    counts = args.scaling
    if counts:
        print(f"default method (lidarcam) vs board count, {args.scaling_problems} problems each, one process:")
        print(f"  {'boards':>6}{'median s':>10}{'max s':>9}{'x 1st':>8}  valid")
        for r in time_scaling(counts, args.scaling_problems):
            print(f"  {r['boards']:>6}{r['median_s']:>10.3f}{r['max_s']:>9.3f}{r['ratio']:>8.1f}  {r['valid']}")
    obs_list = problems(args.boards, args.problems)
    rows = time_methods(obs_list, args.repeats)
    print(f"calibrate() on {args.boards} boards, {args.problems} problems x {args.repeats} repetitions:")
    print("\n".join(method_lines(rows)))
    mt = time_minimal(obs_list, args.triples)
    print(f"minimal solver (solve_triples, one call, one core): {mt['triples']} triples in {mt['seconds']:.3f} s = "
          f"{mt['triples_per_s']:,.0f} triples/s ({mt['solutions']} real solutions)")
    for quartic in ("closed", "eig"):
        print("minimal solver accuracy on noise-free triples:", minimal_accuracy(args.boards, args.problems,
                                                                                 args.triples, quartic))
    for nb in args.joint_boards:
        j = time_joint(nb, min(args.problems, 5), max(3, args.repeats // 4))
        print(f"joint model, {nb} boards with corners (0.5 px), median ms: joint_refine {j['joint_refine_ms']:.1f}, "
              f"calibrate zhang_pless_linear+joint {j['zpl_joint_ms']:.1f}, calibrate lidarcam {j['lidarcam_ms']:.1f}")
    from .solver_bench import run as solver_bench  # both minimal solvers per triple over the sweeps' noise
    solver_bench(out="results/bench")
