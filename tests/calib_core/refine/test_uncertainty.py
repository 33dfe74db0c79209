"""Covariance, Fisher information / CRLB, conditioning and degeneracy warnings (calib_core.refine.uncertainty)."""

import numpy as np
import pytest
from scenes import OUTLINE, error_vector, make_observations, random_extrinsic, vertical_board_poses

from calib_core.checks.degeneracy import degeneracy_warnings
from calib_core.data.io import extrinsic_yaml
from calib_core.data.lines import range_sigma
from calib_core.errors import UncertaintyError
from calib_core.geometry.transforms import make_T, rotvec_to_matrix
from calib_core.model.residuals import outside_outline, perturb, range_residuals
from calib_core.model.score import evidence_cost
from calib_core.refine.refine import refine
from calib_core.refine.uncertainty import (
    conditioning,
    covariance,
    crlb,
    fisher_information,
    normal_spread_deg,
    refinement_covariance,
)


def test_covariance_matches_the_spread_of_linear_least_squares(rng):
    # y = J x + noise: the estimated covariance (sigma from the residuals, K-6 dof) averages to the true one
    K, sigma = 30, 0.02
    J = rng.normal(size=(K, 6)) * [1, 2, 3, 0.5, 1, 4]
    est, covs = [], []
    for _ in range(3000):
        y = rng.normal(scale=sigma, size=K)
        x, *_ = np.linalg.lstsq(J, y, rcond=None)
        est.append(x)
        covs.append(covariance(J, y - J @ x))
    emp = np.cov(np.array(est).T)
    mean_cov = np.mean(covs, axis=0)
    np.testing.assert_allclose(np.diag(mean_cov), np.diag(emp), rtol=0.1)
    np.testing.assert_allclose(mean_cov, sigma**2 * np.linalg.inv(J.T @ J), rtol=0.05, atol=1e-12)
    np.testing.assert_allclose(covariance(J, np.zeros(K), 0.02), sigma**2 * np.linalg.inv(J.T @ J), rtol=1e-10)


def test_covariance_refuses_singular_information_and_no_dof(rng):
    J = rng.normal(size=(20, 6))
    J[:, 5] = J[:, 4]
    with pytest.raises(UncertaintyError, match="singular"):
        covariance(J, rng.normal(size=20), 0.01)
    with pytest.raises(UncertaintyError, match="degrees of freedom"):
        covariance(rng.normal(size=(6, 6)), rng.normal(size=6))


def test_crlb_is_the_inverse_of_a_numerical_fisher_information(rng):
    obs = make_observations(rng, n_boards=6, range_sigma_m=0.02)
    data = obs.scan_data
    T = obs.T_lidar_cam_true
    h = 1e-6
    J_fd = np.column_stack([(range_residuals(perturb(T, h * e), data) - range_residuals(perturb(T, -h * e), data))
                            / (2 * h) for e in np.eye(6)])
    F = J_fd.T @ J_fd / 0.02**2
    np.testing.assert_allclose(fisher_information(obs, T, 0.02), F, rtol=1e-5)
    c = crlb(obs, 0.02)
    np.testing.assert_allclose(c.cov, np.linalg.inv(F), rtol=1e-5)
    assert c.rot_rms_deg == pytest.approx(np.degrees(np.sqrt(np.trace(np.linalg.inv(F)[:3, :3]))), rel=1e-5)
    assert c.trans_rms_m == pytest.approx(np.sqrt(np.trace(np.linalg.inv(F)[3:, 3:])), rel=1e-5)
    # scales as sigma
    assert crlb(obs, 0.04).trans_rms_m == pytest.approx(2 * c.trans_rms_m, rel=1e-9)


def test_ml_estimate_reaches_the_crlb_and_its_nees_is_six(rng):
    # refine (ML on range residuals) from the truth over many noise draws of one scene: RMS error ~ CRLB, NEES ~ 6
    T = random_extrinsic(rng)
    poses = [T @ b.T_cam_board for b in make_observations(rng, 8, 0.0, T_lidar_cam=T).boards]
    errs, nees = [], []
    for _ in range(60):   # one scene, fresh noise
        obs = make_observations(rng, range_sigma_m=0.02, T_lidar_cam=T, poses=poses)
        r = refine(obs.scan_data, T)
        P = refinement_covariance(obs.scan_data, r.T_lidar_cam)
        e = error_vector(r.T_lidar_cam, T)
        nees.append(e @ np.linalg.solve(P, e))
        errs.append(e)
    assert 3.0 < np.mean(nees) < 10.0
    bound = crlb(obs, 0.02)
    errs = np.array(errs)
    assert 0.75 < np.degrees(np.sqrt(np.mean(np.sum(errs[:, :3] ** 2, axis=1)))) / bound.rot_rms_deg < 1.3
    assert 0.75 < np.sqrt(np.mean(np.sum(errs[:, 3:] ** 2, axis=1))) / bound.trans_rms_m < 1.3


def test_plane_refinement_covariance_is_consistent(rng):
    T = random_extrinsic(rng)
    nees = []
    for _ in range(60):   # a new scene each time
        obs = make_observations(rng, 8, 0.02, T_lidar_cam=T)
        data = obs.scan_data
        r = refine(data, T, residual="plane")
        P = refinement_covariance(data, r.T_lidar_cam, "plane", 0.02)
        e = error_vector(r.T_lidar_cam, T)
        nees.append(e @ np.linalg.solve(P, e))
    # the median: the point-to-plane cost has far-off minima that a refinement from the truth can slide into
    # (about 1 draw in 60 here, NEES in the thousands): a local covariance cannot describe those
    assert 3.5 < np.median(nees) < 8.0      # median of chi2(6) is 5.35
    # and the plane residual is not the likelihood: its covariance is no smaller than the ML one
    P_ml = refinement_covariance(data, r.T_lidar_cam, "range", 0.02)
    assert np.trace(P) >= np.trace(P_ml) * (1 - 1e-9)


def test_conditioning_and_warnings_flag_degenerate_sets(rng):
    T = random_extrinsic(rng)
    good = make_observations(rng, 8, 0.0, T_lidar_cam=T)
    flat = make_observations(rng, 6, 0.0, T_lidar_cam=T, poses=vertical_board_poses(6))
    assert normal_spread_deg(flat) < 1e-6
    assert conditioning(flat) < 1e-8 < 1e-3 < conditioning(good) <= 1.0
    w = degeneracy_warnings(flat)
    assert any("normals" in s for s in w) and any("conditioned" in s for s in w)
    three = good.subset([0, 1, 2])
    assert any("only 3 boards" in s for s in degeneracy_warnings(three))
    assert not any("only" in s for s in degeneracy_warnings(good))
    assert degeneracy_warnings(good) == []
    with pytest.raises(UncertaintyError):
        crlb(flat, 0.02)


def test_conditioning_is_scale_free(rng):
    obs = make_observations(rng, 6, 0.0)
    c = conditioning(obs)
    # a rotation of the camera frame and of the whole scene about the lidar does not change it
    Rz = make_T(rotvec_to_matrix(np.array([0, 0, 0.3])), np.zeros(3))
    from calib_core.data.observations import BoardObservation, Observations
    moved = Observations(tuple(BoardObservation(b.T_cam_board, b.outline, b.scan @ Rz[:2, :2].T) for b in obs.boards),
                         Rz @ obs.T_lidar_cam_true)
    assert conditioning(moved) == pytest.approx(c, rel=1e-6)


def test_range_sigma_from_the_scan_lines_or_given(rng):
    obs = make_observations(rng, 8, 0.02)
    assert range_sigma(obs) == pytest.approx(0.02, rel=0.2)
    assert range_sigma(obs, robust=True) == pytest.approx(0.02, rel=0.3)
    assert range_sigma(make_observations(rng, 4, 0.0)) < 1e-5 and range_sigma(obs, 0.005) == 0.005


def test_outside_outline_distances():
    xy = np.array([[0.5, 0.5], [1.5, 0.5], [-0.2, -0.2], [0.5, 1.1], [0.0, 0.5]])
    np.testing.assert_allclose(outside_outline(xy, OUTLINE), [0, 0.5, np.hypot(0.2, 0.2), 0.1, 0], atol=1e-12)


def test_outside_outline_against_a_brute_force_polygon_test(rng):
    """On a random star-shaped (non-convex) polygon, with a vertex repeated (a zero-length edge): 0 exactly where
    matplotlib's point-in-polygon test says inside, else the distance to the densely sampled outline; the gradient
    is the unit vector from the outline's nearest point."""
    from matplotlib.path import Path

    for _ in range(6):
        ang = np.sort(rng.uniform(0, 2 * np.pi, 7))
        poly = np.column_stack([np.cos(ang), np.sin(ang)]) * rng.uniform(0.3, 1.0, (7, 1))
        poly = np.insert(poly, 3, poly[3], axis=0)
        xy = rng.uniform(-1.2, 1.2, (400, 2))
        d, g = outside_outline(xy, poly, gradient=True)
        np.testing.assert_array_equal(d == 0, Path(poly).contains_points(xy))
        t = np.linspace(0, 1, 4001)[:, None]
        dist = np.min([np.min(np.linalg.norm(xy[:, None] - (a + t * (b - a))[None], axis=-1), axis=1)
                       for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True)], axis=0)
        out = d > 0
        np.testing.assert_allclose(d[out], dist[out], atol=1e-3)
        np.testing.assert_allclose(np.linalg.norm(g[out], axis=1), 1.0, atol=1e-12)
        np.testing.assert_allclose(outside_outline(xy[out] + 1e-7 * g[out], poly) - d[out], 1e-7, atol=1e-12)


def test_evidence_costr_prefers_the_truth_and_is_half_k_there(rng):
    obs = make_observations(rng, 6, 0.02)
    T = obs.T_lidar_cam_true
    K = sum(len(b.scan) for b in obs.boards)
    C = np.array([T] + [perturb(T, np.r_[rng.normal(scale=0.05, size=3), rng.normal(scale=0.1, size=3)])
                        for _ in range(30)])
    cost, parts = evidence_cost(obs, C, range_sigma_m=0.02, return_details=True)
    assert np.argmin(cost) == 0
    assert parts["range"][0] == pytest.approx(K / 2, rel=0.3)
    # a candidate that puts the boards behind the camera is never chosen
    flip = C[0].copy()
    flip[:3, :3] = flip[:3, :3] @ np.diag([-1.0, 1.0, -1.0])
    assert not np.isfinite(evidence_cost(obs, flip[None], range_sigma_m=0.02)[0])


def test_yaml_carries_the_one_sigma(rng):
    obs = make_observations(rng, 6, 0.02)
    data = obs.scan_data
    P = refinement_covariance(data, obs.T_lidar_cam_true)
    text = extrinsic_yaml(obs.T_lidar_cam_true, {"method": "x"}, covariance=P)
    assert f"sigma_rot_deg: {np.degrees(np.sqrt(np.trace(P[:3, :3])))}" in text
    assert "sigma_trans_mm:" in text and "covariance:" in text
