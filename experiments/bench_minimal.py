"""Throughput and accuracy of the minimal solver on random noise-free triples (plain script, no Hydra).

Run: ``OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1 python -m experiments.bench_minimal``
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from calib_core.solvers.vasconcelos import solve_triples


def random_instance(rng: np.random.Generator, n_triples: int, *, max_tilt_deg: float = 60.0,
                    depth_range: tuple[float, float] = (2.0, 6.0), translation_std: float = 0.3):
    """Random noise-free triples with their truth: ``(T_lidar_cam (B,4,4), n, d, p, u)``.

    Rotation uniformly random, translation N(0, translation_std^2) per axis (metres).  Board i is the plane
    through a point at depth in ``depth_range`` in front of the camera, its normal within ``max_tilt_deg``
    of the viewing axis; its scan line is that plane, in the lidar frame, cut with z = 0.
    """
    B = int(n_triples)
    quat = rng.normal(size=(B, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    x, y, zq, w = quat.T
    R = np.stack([np.stack([1 - 2 * (y * y + zq * zq), 2 * (x * y - zq * w), 2 * (x * zq + y * w)], -1),
                  np.stack([2 * (x * y + zq * w), 1 - 2 * (x * x + zq * zq), 2 * (y * zq - x * w)], -1),
                  np.stack([2 * (x * zq - y * w), 2 * (y * zq + x * w), 1 - 2 * (x * x + y * y)], -1)], axis=1)
    t = rng.normal(scale=translation_std, size=(B, 3))
    T = np.zeros((B, 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = R, t, 1.0
    centre = np.concatenate([rng.uniform(-1.0, 1.0, size=(B, 3, 2)),
                             rng.uniform(*depth_range, size=(B, 3, 1))], axis=-1)
    tilt = np.radians(max_tilt_deg) * np.sqrt(rng.uniform(size=(B, 3)))
    az = rng.uniform(0, 2 * np.pi, size=(B, 3))
    n = np.stack([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), -np.cos(tilt)], axis=-1)
    d = np.einsum("bki,bki->bk", n, centre)
    nL = np.einsum("bij,bkj->bki", R, n)
    dL = d + np.einsum("bki,bi->bk", nL, t)
    g = nL[..., :2]
    g2 = np.sum(g * g, -1, keepdims=True)
    p = dL[..., None] * g / g2
    u = np.stack([-g[..., 1], g[..., 0]], -1) / np.sqrt(g2)
    return T, n, d, p, u


def throughput(n_triples: int = 10_000, seed: int = 0, repeats: int = 5, **options) -> dict:
    """Triples solved per second (best of ``repeats``) on random noise-free triples; run with OMP_NUM_THREADS=1."""
    rng = np.random.default_rng(seed)
    _, n, d, p, u = random_instance(rng, n_triples)
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        sol = solve_triples(n, d, p, u, **options)
        best = min(best, time.perf_counter() - t0)
    return {"n_triples": n_triples, "seconds": best, "triples_per_s": n_triples / best,
            "solutions_per_triple": len(sol) / n_triples}


def accuracy(n_triples: int, seed: int, **options) -> dict:
    """Error of the best candidate to the truth (max(|dR|_F, |dt|)), binned by sigma_min of the normal matrix."""
    T, n, d, p, u = random_instance(np.random.default_rng(seed), n_triples)
    sol = solve_triples(n, d, p, u, **options)
    err = np.maximum(np.linalg.norm(sol.T_lidar_cam[:, :3, :3] - T[sol.triple, :3, :3], axis=(1, 2)),
                     np.linalg.norm(sol.T_lidar_cam[:, :3, 3] - T[sol.triple, :3, 3], axis=1))
    best = np.full(n_triples, np.inf)
    np.minimum.at(best, sol.triple, err)
    solved = np.array([r is None for r in sol.reasons])
    sv = np.linalg.svd(n, compute_uv=False)[:, -1]
    out = {"solved": int(solved.sum()), "degenerate_or_no_real": int((~solved).sum()),
           "max_solutions": int(np.bincount(sol.triple).max())}
    for lo in (1e-3, 1e-2, 1e-1):
        m = solved & (sv >= lo)
        out[f"sv>={lo:g}"] = {"n": int(m.sum()), "max_err": float(best[m].max()),
                              "share_err>1e-9": float(np.mean(best[m] > 1e-9))}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    for quartic in ("closed", "eig"):
        print(quartic, "throughput", throughput(args.n, args.seed, quartic=quartic))
        print(quartic, "accuracy", accuracy(args.n, args.seed, quartic=quartic))


if __name__ == "__main__":
    main()
