"""Tests of calib_core.solvers.vasconcelos (Vasconcelos 2012 minimal solver) on noise-free synthetic triples."""

from __future__ import annotations

import itertools
import zlib

import numpy as np
import pytest

from calib_core.geometry.transforms import invert_T, make_T, rotvec_to_matrix
from calib_core.solvers._common import (
    MAX_SOLUTIONS,
    REASON_PLANES,
    REASON_SCAN_LINES,
    REASON_TRIANGLE,
    MinimalSolutions,
    board_triples,
)
from calib_core.solvers.orientation import kabsch
from calib_core.solvers.vasconcelos import solve_triple, solve_triples

N_SEEDS = 250
TOL = 1e-9
# The test scenes' well-conditioning: smallest singular value of the normal matrix, smallest |sine| between
# scan lines (solutions of worse-conditioned triples are accurate to ~1e-8 rather than 1e-9).
MIN_SV = 0.1
MIN_SIN = 0.05


def rng_for(name: str) -> np.random.Generator:
    return np.random.default_rng(zlib.crc32(name.encode()))


# ------------------------------------------------------------------------------------------------
# Problem generator: planes in the camera frame, scan lines = planes mapped to the lidar, cut with z = 0.


def random_T(rng: np.random.Generator) -> np.ndarray:
    w = rng.normal(size=3)
    w *= rng.uniform(0, np.pi) / np.linalg.norm(w)
    return make_T(rotvec_to_matrix(w), rng.normal(scale=0.3, size=3))


def scan_lines(T_lidar_cam: np.ndarray, n: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Scan lines (p (3,2), u (3,2)) of camera planes n (3,3), d (3,) seen by a lidar at ``T_lidar_cam``."""
    R, t = T_lidar_cam[:3, :3], T_lidar_cam[:3, 3]
    nL = n @ R.T
    dL = d + nL @ t
    g = nL[:, :2]
    g2 = np.sum(g * g, axis=1, keepdims=True)
    return dL[:, None] * g / g2, np.stack([-g[:, 1], g[:, 0]], axis=1) / np.sqrt(g2)


def camera_planes_from_lidar(T_lidar_cam: np.ndarray, nL: np.ndarray, dL: np.ndarray):
    """Camera-frame planes (n, d) of lidar-frame planes ``nL . x = dL``."""
    R, t = T_lidar_cam[:3, :3], T_lidar_cam[:3, 3]
    nL = nL / np.linalg.norm(nL, axis=1, keepdims=True)
    return nL @ R, dL - nL @ t


def random_scene(rng: np.random.Generator):
    """(T_lidar_cam, n, d, p, u): three boards 2-6 m in front of the camera, tilted up to 60 degrees.

    Scenes are redrawn until well conditioned (``MIN_SV``, ``MIN_SIN``).
    """
    T = random_T(rng)
    while True:
        centre = np.column_stack([rng.uniform(-1, 1, size=(3, 2)), rng.uniform(2, 6, size=3)])
        tilt = np.radians(60) * np.sqrt(rng.uniform(size=3))
        az = rng.uniform(0, 2 * np.pi, size=3)
        n = np.column_stack([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), -np.cos(tilt)])
        d = np.einsum("ij,ij->i", n, centre)
        p, u = scan_lines(T, n, d)
        sines = [abs(u[i, 0] * u[j, 1] - u[i, 1] * u[j, 0]) for i, j in ((0, 1), (0, 2), (1, 2))]
        if np.linalg.svd(n, compute_uv=False)[-1] >= MIN_SV and min(sines) >= MIN_SIN:
            return T, n, d, p, u


def scan_triangle(p: np.ndarray, u: np.ndarray) -> np.ndarray:
    """q_12, q_13, q_23 (3,2): meeting points of the scan lines."""
    q = []
    for i, j in ((0, 1), (0, 2), (1, 2)):
        s, _ = np.linalg.solve(np.column_stack([u[i], -u[j]]), p[j] - p[i])
        q.append(p[i] + s * u[i])
    return np.array(q)


def pose_distance(T: np.ndarray, T_ref: np.ndarray) -> np.ndarray:
    """max(|R - R_ref|_F, |t - t_ref|) per candidate of T (...,4,4)."""
    dR = np.linalg.norm(T[..., :3, :3] - T_ref[:3, :3], axis=(-2, -1))
    dt = np.linalg.norm(T[..., :3, 3] - T_ref[:3, 3], axis=-1)
    return np.maximum(dR, dt)


def same_set(A: list[np.ndarray] | np.ndarray, B: list[np.ndarray] | np.ndarray, tol: float) -> bool:
    """Equal multisets of transforms, up to ``tol`` relative to the translation size."""
    A, B = np.asarray(A).reshape(-1, 4, 4), np.asarray(B).reshape(-1, 4, 4)
    if len(A) != len(B):
        return False
    used = np.zeros(len(B), dtype=bool)
    for T in A:
        dist = pose_distance(B, T) / (1.0 + np.linalg.norm(T[:3, 3]))
        dist[used] = np.inf
        k = int(np.argmin(dist))
        if not dist[k] <= tol:
            return False
        used[k] = True
    return True


# ------------------------------------------------------------------------------------------------


def test_truth_among_solutions_and_constraints_hold():
    rng = rng_for("test_truth_among_solutions_and_constraints_hold")
    worst = 0.0
    counts = []
    for _ in range(N_SEEDS):
        T, n, d, p, u = random_scene(rng)
        sols = solve_triple(n, d, p, u)
        assert 1 <= len(sols) <= MAX_SOLUTIONS
        assert len(sols) % 2 == 0  # every root with its mirror through O
        counts.append(len(sols))
        err = pose_distance(np.array(sols), T).min()
        worst = max(worst, err)
        assert err < TOL, err
        # Every candidate is a proper rigid transform mapping q_ij onto planes i and j.
        q = scan_triangle(p, u)
        qL = np.column_stack([q, np.zeros(3)])
        for S in sols:
            R = S[:3, :3]
            assert np.allclose(R.T @ R, np.eye(3), atol=1e-12) and np.linalg.det(R) > 0
            x = (qL - S[:3, 3]) @ R  # camera-frame points
            scale = 1.0 + np.linalg.norm(x, axis=1)
            for a, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):
                assert abs(n[i] @ x[a] - d[i]) < TOL * scale[a]
                assert abs(n[j] @ x[a] - d[j]) < TOL * scale[a]
    assert worst < TOL
    assert max(counts) <= MAX_SOLUTIONS


def test_batched_equals_single_and_eig_equals_closed():
    rng = rng_for("test_batched_equals_single_and_eig_equals_closed")
    scenes = [random_scene(rng) for _ in range(60)]
    T, n, d, p, u = (np.array(x) for x in zip(*scenes, strict=True))
    batch = solve_triples(n, d, p, u)
    eig = solve_triples(n, d, p, u, quartic="eig")
    assert isinstance(batch, MinimalSolutions)
    assert batch.T_lidar_cam.shape == (len(batch), 4, 4) and batch.triple.shape == (len(batch),)
    assert batch.reasons.shape == (60,) and all(r is None for r in batch.reasons)
    assert np.all(np.diff(batch.triple) >= 0)
    assert not batch.near_real.any()
    for b in range(60):
        single = solve_triple(n[b], d[b], p[b], u[b])
        assert same_set(batch.of_triple(b), single, 1e-12)
        assert same_set(batch.of_triple(b), eig.of_triple(b), 1e-9)
        assert pose_distance(batch.of_triple(b), T[b]).min() < TOL


@pytest.mark.parametrize("order", list(itertools.permutations(range(3)))[1:])
def test_relabelling_boards_gives_same_solutions(order):
    rng = rng_for(f"test_relabelling_boards_gives_same_solutions{order}")
    order = list(order)
    for _ in range(40):
        _, n, d, p, u = random_scene(rng)
        assert same_set(solve_triple(n, d, p, u), solve_triple(n[order], d[order], p[order], u[order]), 1e-9)


def test_rigid_change_of_camera_frame_moves_solutions():
    rng = rng_for("test_rigid_change_of_camera_frame_moves_solutions")
    for _ in range(60):
        _, n, d, p, u = random_scene(rng)
        G = random_T(rng)  # T_new_cam
        n2 = n @ G[:3, :3].T
        d2 = d + n2 @ G[:3, 3]
        expected = [S @ invert_T(G) for S in solve_triple(n, d, p, u)]
        assert same_set(solve_triple(n2, d2, p, u), expected, 1e-9)


def test_rigid_change_of_lidar_frame_within_scan_plane():
    rng = rng_for("test_rigid_change_of_lidar_frame_within_scan_plane")
    for _ in range(60):
        _, n, d, p, u = random_scene(rng)
        a = rng.uniform(-np.pi, np.pi)
        Rz = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        t2 = rng.normal(size=2)
        H = make_T(np.block([[Rz, np.zeros((2, 1))], [np.zeros((1, 2)), np.ones((1, 1))]]), np.r_[t2, 0.0])
        expected = [H @ S for S in solve_triple(n, d, p, u)]
        assert same_set(solve_triple(n, d, p @ Rz.T + t2, u @ Rz.T), expected, 1e-9)


def test_degenerate_triples_return_no_solution_with_reason():
    rng = rng_for("test_degenerate_triples_return_no_solution_with_reason")
    T, n, d, p, u = random_scene(rng)
    # Two parallel planes (board 1 moved along its normal).
    n_par, d_par = n.copy(), d.copy()
    n_par[1], d_par[1] = n[0], d[0] + 0.5
    p_par, u_par = scan_lines(T, n_par, d_par)
    # Parallel scan lines: lidar-frame normals with the same x, y part, different z part.
    nL = np.array([[1.0, 0.2, 0.3], [1.0, 0.2, -0.6], [0.1, 1.0, 0.2]])
    dL = np.array([4.0, 5.0, 3.0])
    n_sl, d_sl = camera_planes_from_lidar(T, nL, dL)
    p_sl, u_sl = scan_lines(T, n_sl, d_sl)
    # Concurrent scan lines: three planes through one point of the scan plane.
    nL = np.array([[1.0, 0.2, 0.3], [0.3, 1.0, -0.6], [-0.7, 0.8, 0.2]])
    x0 = np.array([3.0, 1.0, 0.0])
    n_cc, d_cc = camera_planes_from_lidar(T, nL, nL @ x0 / np.linalg.norm(nL, axis=1))
    p_cc, u_cc = scan_lines(T, n_cc, d_cc)
    sol = solve_triples(np.array([n_par, n_sl, n_cc, n]), np.array([d_par, d_sl, d_cc, d]),
                        np.array([p_par, p_sl, p_cc, p]), np.array([u_par, u_sl, u_cc, u]))
    assert list(sol.reasons) == [REASON_PLANES, REASON_SCAN_LINES, REASON_TRIANGLE, None]
    assert set(sol.triple.tolist()) == {3}
    assert pose_distance(sol.of_triple(3), T).min() < TOL
    assert solve_triple(n_par, d_par, p_par, u_par) == []
    bad = solve_triples(np.full((1, 3, 3), np.nan), d[None], p[None], u[None])
    assert len(bad) == 0 and bad.reasons[0] is not None


def test_near_real_option_adds_flagged_candidates_only():
    rng = rng_for("test_near_real_option_adds_flagged_candidates_only")
    scenes = [random_scene(rng) for _ in range(500)]
    _, n, d, p, u = (np.array(x) for x in zip(*scenes, strict=True))
    p = p + rng.normal(scale=0.02, size=p.shape)
    n = n + rng.normal(scale=0.01, size=n.shape)
    strict = solve_triples(n, d, p, u)
    loose = solve_triples(n, d, p, u, near_real_tol=1e-2)
    assert loose.near_real.any() and not strict.near_real.any()
    assert np.bincount(loose.triple).max() <= MAX_SOLUTIONS
    kept = loose.T_lidar_cam[~loose.near_real]
    assert np.array_equal(loose.triple[~loose.near_real], strict.triple)
    assert np.allclose(kept, strict.T_lidar_cam)


def test_closed_form_orientation_matches_kabsch():
    from calib_core.solvers.orientation import abs_orientation_3pt

    rng = rng_for("test_closed_form_orientation_matches_kabsch")
    K = 200
    q = rng.normal(scale=2.0, size=(K, 3, 2))
    Q = np.concatenate([q, np.zeros((K, 3, 1))], axis=2)
    R_true = rotvec_to_matrix(rng.normal(size=(K, 3)))
    t_true = rng.normal(size=(K, 3))
    P = np.einsum("kji,knj->kni", R_true, Q - t_true[:, None])  # Q = R P + t
    R, t = abs_orientation_3pt(P, q)
    assert np.allclose(R, R_true, atol=1e-12) and np.allclose(t, t_true, atol=1e-12)
    P_noisy = P + rng.normal(scale=1e-3, size=P.shape)
    R, t = abs_orientation_3pt(P_noisy, q)
    Rk, tk = kabsch(P_noisy, Q)
    assert np.allclose(R, Rk, atol=1e-5) and np.allclose(t, tk, atol=1e-4)


def test_board_triples():
    tr = board_triples(6)
    assert tr.shape == (20, 3)
    assert len({tuple(r) for r in tr}) == 20 and np.all(np.diff(tr, axis=1) > 0)
    assert board_triples(2).shape == (0, 3)
    assert board_triples(3).tolist() == [[0, 1, 2]]
