"""Residual Jacobians against finite differences; refinement behaviour on exact and noisy data."""

import numpy as np
import pytest

from calib_core.geometry.transforms import make_T, rotvec_to_matrix
from calib_core.model.residuals import RESIDUALS, ScanData, perturb
from calib_core.refine.refine import refine, robust_cost, so3_left_jacobian


def random_problem(rng, n_boards=5, k=40, noise=0.0):
    """Scan points on random planes (camera frame) seen through a random T_lidar_cam (lidar z = 0)."""
    T = make_T(rotvec_to_matrix(rng.normal(size=3)), rng.normal(scale=0.3, size=3))
    R, t = T[:3, :3], T[:3, 3]
    pts, board, normals, offsets = [], [], [], []
    for i in range(n_boards):
        # a plane in the lidar frame crossing z = 0 in a line ahead of the sensor
        ang = rng.uniform(-1.0, 1.0)
        c = np.array([np.cos(ang), np.sin(ang), 0.0]) * rng.uniform(3, 6)
        m = rng.normal(size=3)
        m[:2] += 2 * c[:2] / np.linalg.norm(c[:2])
        m /= np.linalg.norm(m)
        u = np.cross(m, [0, 0, 1.0])
        u /= np.linalg.norm(u)
        P = c + np.outer(np.linspace(-0.4, 0.4, k), u)
        rng_dir = P / np.linalg.norm(P, axis=1, keepdims=True)
        P = P + rng_dir * rng.normal(scale=noise, size=(k, 1))
        n_cam = R.T @ m
        pts.append(P)
        board.append(np.full(k, i))
        normals.append(n_cam)
        offsets.append(n_cam @ (R.T @ (c - t)))
    return T, ScanData(np.concatenate(pts), np.concatenate(board), np.array(normals), np.array(offsets))


@pytest.mark.parametrize("kind", ["plane", "range"])
def test_residual_jacobian_matches_finite_differences(rng, kind):
    fn = RESIDUALS[kind]
    for _ in range(20):
        T_true, data = random_problem(rng, noise=0.01)
        T = perturb(T_true, rng.normal(scale=0.05, size=6))
        e, J = fn(T, data, jacobian=True)
        h = 1e-6
        J_fd = np.column_stack([(fn(perturb(T, h * ei), data) - fn(perturb(T, -h * ei), data)) / (2 * h)
                                for ei in np.eye(6)])
        np.testing.assert_allclose(J, J_fd, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("kind", ["plane", "range"])
def test_batched_residuals_and_range_jacobian_equal_those_of_each_pose(rng, kind):
    """A batch (M,4,4) of extrinsics gives each pose's residuals (and, for the range residual, its Jacobian), and a
    batch of perturbations (M,6) each pose's perturbation."""
    fn = RESIDUALS[kind]
    for _ in range(10):
        T_true, data = random_problem(rng, noise=0.01)
        x = rng.normal(scale=0.05, size=(4, 6))
        C = perturb(np.repeat(T_true[None], 4, axis=0), x)
        np.testing.assert_allclose(C, [perturb(T_true, xi) for xi in x], atol=1e-15)
        np.testing.assert_allclose(fn(C, data), [fn(T, data) for T in C], rtol=1e-12, atol=1e-12)
        if kind == "range":
            e, J = fn(C, data, jacobian=True)
            for m, T in enumerate(C):
                e1, J1 = fn(T, data, jacobian=True)
                np.testing.assert_allclose(e[m], e1, rtol=1e-12, atol=1e-12)
                np.testing.assert_allclose(J[m], J1, rtol=1e-12, atol=1e-12)


def test_so3_left_jacobian_matches_finite_differences(rng):
    for _ in range(20):
        w = rng.normal(size=3)
        dw = 1e-6 * rng.normal(size=3)
        lhs = rotvec_to_matrix(w + dw) @ rotvec_to_matrix(w).T
        rhs = rotvec_to_matrix(so3_left_jacobian(w) @ dw)
        np.testing.assert_allclose(lhs, rhs, atol=1e-11)


@pytest.mark.parametrize("kind", ["plane", "range"])
def test_refinement_stays_at_truth_on_noise_free_data(rng, kind):
    T_true, data = random_problem(rng)
    r = refine(data, T_true, residual=kind)
    np.testing.assert_allclose(r.T_lidar_cam, T_true, atol=1e-9)
    assert r.cost < 1e-20


@pytest.mark.parametrize("kind", ["plane", "range"])
@pytest.mark.parametrize("loss", ["linear", "huber", "cauchy"])
def test_refinement_never_increases_the_cost_and_converges_from_a_perturbed_start(rng, kind, loss):
    for _ in range(5):
        T_true, data = random_problem(rng, noise=0.01)
        T0 = perturb(T_true, np.r_[rng.normal(scale=0.03, size=3), rng.normal(scale=0.05, size=3)])
        r = refine(data, T0, residual=kind, loss=loss, f_scale_m=0.03)
        assert r.cost <= r.initial_cost + 1e-15
        assert robust_cost(RESIDUALS[kind](T0, data), loss, 0.03) == pytest.approx(r.initial_cost)
        # converges to the optimum reached from the truth (the estimator's own error is not the point here)
        r_true = refine(data, T_true, residual=kind, loss=loss, f_scale_m=0.03)
        np.testing.assert_allclose(r.T_lidar_cam, r_true.T_lidar_cam, atol=1e-5)
