"""The hot paths' lazy Jacobians against the eager ones: the residual functions that give their Jacobian (or
gradient) as a function to call later (``jacobian="later"``) give the same numbers, bit for bit, as when asked at
once, and ``least_squares_many`` given such functions answers as with the Jacobians given at once, computing fewer
of them. The polish's batched linearisation (every start of a round in one call) gives each row as the call on its
extrinsic alone, bit for bit, and so a polish of many starts answers as each start polished alone."""

from __future__ import annotations

import numpy as np
import pytest

from calib_core.geometry.mounting import MountingPrior
from calib_core.geometry.transforms import skew, so3_left_jacobian
from calib_core.model.linearised import lidarcam_linearised, lidarcam_linearised_many
from calib_core.model.residuals import (
    outside_outlines,
    perturb,
    plane_residuals,
    point_line_errors,
    range_residuals,
)
from calib_core.model.score import ScoreOptions
from calib_core.refine.trust_region import jacobian, least_squares_many
from calib_core.robust.choose import polish_many
from simulate import SimOptions, generate

SCENES = {
    "exact": SimOptions(n_boards=3),
    "lower_bound": SimOptions(n_boards=4, board_margin_min_m=0.02, board_margin_max_m=0.07),
    "mixed": SimOptions(n_boards=5, board_margin_min_m=0.0, board_margin_max_m=0.07, outline_known=True),
}


def _poses(obs, rng, k=5):
    """``k`` extrinsics around the truth (a few degrees, a few centimetres off)."""
    return np.array([perturb(obs.T_lidar_cam_true, rng.normal(0, [0.03] * 3 + [0.05] * 3)) for _ in range(k)])


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_lazy_residual_jacobians_equal_the_eager_ones(scene, rng):
    """Range and plane residuals, endpoint errors and outline distances: the same residuals, and the Jacobians or
    gradients given later equal those given at once, bitwise (one extrinsic and a batch)."""
    obs = generate(SCENES[scene], seed=8, trial=int(rng.integers(100)))
    C = _poses(obs, rng)
    for T in (C[0], C):
        e, J = range_residuals(T, obs.scan_data, jacobian=True)
        e_later, J_later = range_residuals(T, obs.scan_data, jacobian="later")
        assert np.array_equal(e, e_later) and np.array_equal(J, J_later())
    e, J = plane_residuals(C[0], obs.scan_data, jacobian=True)
    e_later, J_later = plane_residuals(C[0], obs.scan_data, jacobian="later")
    assert np.array_equal(e, e_later) and np.array_equal(J, J_later())
    for fn in (point_line_errors, outside_outlines):
        d, g = fn(obs, C, gradient=True)
        d_later, g_later = fn(obs, C, gradient="later")
        assert np.array_equal(d, d_later) and np.array_equal(g, g_later())
        assert np.array_equal(d, fn(obs, C))


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_lazy_lidarcam_linearisation_equals_the_eager_one(scene, rng):
    """``lidarcam_linearised(..., jacobian="later")``: the residuals and Jacobian of the eager call, bitwise, with
    and without a mounting prior."""
    obs = generate(SCENES[scene], seed=9, trial=int(rng.integers(100)))
    prior = MountingPrior(perturb(obs.T_lidar_cam_true, rng.normal(0, [0.05] * 3 + [0.05] * 3)), 0.1, 0.05)
    for p in (None, prior):
        kw = {"range_sigma_m": 0.02, **ScoreOptions(prior=p).kwargs()}
        for T in _poses(obs, rng, 3):
            f, J = lidarcam_linearised(obs, T, **kw)
            f_later, J_later = lidarcam_linearised(obs, T, **kw, jacobian="later")
            assert np.array_equal(f, f_later) and np.array_equal(J, J_later())


def _curve_problem(rng):
    """A sum-of-exponentials fit: one start's residuals and Jacobian, and the data."""
    t = np.linspace(0, 3, 40)
    y = rng.uniform(0.5, 2) * np.exp(rng.uniform(-1.5, -0.2) * t) + rng.uniform(-1, 1) * t + rng.normal(0, .05, 40)

    def one(x):
        e = np.exp(x[1] * t)
        return x[0] * e + x[2] * t - y, np.stack([e, x[0] * t * e, t], axis=1)

    return one


@pytest.mark.parametrize("seed", range(6))
def test_least_squares_many_with_lazy_jacobians_answers_as_with_eager_ones(seed):
    """The same answers, bitwise, whether ``fun`` gives its Jacobians at once or as a function of the rows asked;
    the lazy run computes fewer Jacobians than it evaluates residuals (rejected steps and final steps need none)."""
    rng = np.random.default_rng(seed)
    one = _curve_problem(rng)
    X0 = rng.normal(0, 1.5, (6, 3))
    counts = {"points": 0, "jacobians": 0}

    def eager(idx, X):
        out = [one(x) for x in X]
        return np.array([f for f, _ in out]), np.array([J for _, J in out])

    def lazy(idx, X):
        counts["points"] += len(X)

        def jac(rows):
            counts["jacobians"] += len(rows)
            return np.array([one(X[r])[1] for r in rows])

        return np.array([one(x)[0] for x in X]), jac

    assert np.array_equal(least_squares_many(eager, X0, 50), least_squares_many(lazy, X0, 50))
    assert counts["jacobians"] < counts["points"]


def test_jacobian_takes_rows_of_an_array_or_asks_a_function(rng):
    J = rng.normal(size=(4, 5, 3))
    assert np.array_equal(jacobian(J, np.array([2, 0])), J[[2, 0]])
    assert np.array_equal(jacobian(lambda rows: J[rows], np.array([1, 3])), J[[1, 3]])


def test_so3_left_jacobian_equals_its_formula_in_numpy(rng):
    """The left Jacobian with Python-float coefficients: ``I + (1 - cos t)/t^2 W + (t - sin t)/t^3 W^2``, bitwise
    as numpy evaluates it, from tiny angles to large ones."""
    for w in np.concatenate([rng.normal(0, 1, (200, 3)), rng.normal(0, 1, (50, 3)) * 10.0 ** rng.uniform(-9, -3,
                                                                                                        (50, 1))]):
        th = np.linalg.norm(w)
        W = skew(w)
        ref = np.eye(3) + 0.5 * W if th < 1e-8 else \
            np.eye(3) + (1 - np.cos(th)) / th**2 * W + (th - np.sin(th)) / th**3 * (W @ W)
        assert np.array_equal(so3_left_jacobian(w), ref)


def _bits(a) -> np.ndarray:
    """The bit patterns of a float array (signed zeros and NaN payloads told apart)."""
    return np.ascontiguousarray(a, float).view(np.int64)


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_batched_linearisation_equals_each_extrinsic_alone(scene, rng):
    """``lidarcam_linearised_many`` of (M,4,4) extrinsics: each row's residuals and Jacobian (asked for any subset of
    rows, in any order) are those of ``lidarcam_linearised`` at that extrinsic alone, bitwise, with and without a
    mounting prior."""
    obs = generate(SCENES[scene], seed=10, trial=int(rng.integers(100)))
    prior = MountingPrior(perturb(obs.T_lidar_cam_true, rng.normal(0, [0.05] * 3 + [0.05] * 3)), 0.1, 0.05)
    for p in (None, prior):
        kw = {"range_sigma_m": 0.02, **ScoreOptions(prior=p).kwargs()}
        for M in (1, 2, 5):
            C = _poses(obs, rng, M)
            F, jac = lidarcam_linearised_many(obs, C, **kw)
            rows = rng.permutation(M)[:int(rng.integers(1, M + 1))]
            J = jac(rows)
            for r in range(M):
                assert np.array_equal(_bits(F[r]), _bits(lidarcam_linearised(obs, C[r], **kw)[0]))
            for i, r in enumerate(rows):
                assert np.array_equal(_bits(J[i]), _bits(lidarcam_linearised(obs, C[r], **kw)[1]))


@pytest.mark.parametrize("scene", ["exact", "lower_bound"])
def test_polish_of_many_starts_answers_as_each_start_alone(scene, rng):
    """``polish_many`` from several starts (their residuals evaluated in one call per round) gives each start the
    answer of its polish alone, bitwise."""
    obs = generate(SCENES[scene], seed=11, trial=int(rng.integers(100)))
    T0 = np.array([perturb(obs.T_lidar_cam_true, rng.normal(0, [0.05] * 3 + [0.08] * 3)) for _ in range(4)])
    together = polish_many(obs, T0, 40, ScoreOptions(), 0.02)
    for T, alone in zip(T0, together, strict=True):
        assert np.array_equal(_bits(polish_many(obs, T[None], 40, ScoreOptions(), 0.02)[0]), _bits(alone))
