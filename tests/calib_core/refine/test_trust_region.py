"""The batched trust-region solver (``refine.trust_region``) against ``scipy.optimize.least_squares`` from the same
starts: on seeded random curve fits and on the ``lidarcam`` polish, with and without a stop rule."""

from __future__ import annotations

import numpy as np
import pytest
from scenes import make_observations
from scipy.optimize import least_squares

from calib_core.geometry.transforms import so3_left_jacobian
from calib_core.model.linearised import lidarcam_linearised
from calib_core.model.residuals import perturb
from calib_core.model.score import ScoreOptions
from calib_core.refine.trust_region import least_squares_many
from calib_core.robust.choose import GIVE_UP_ITERATIONS, polish_many


def _curve(rng):
    """A random sum-of-exponentials fit: residuals and Jacobian of (k,3) parameter rows, and the data."""
    t = np.linspace(0, 3, 40)
    truth = np.array([rng.uniform(0.5, 2), rng.uniform(-1.5, -0.2), rng.uniform(-1, 1)])
    y = truth[0] * np.exp(truth[1] * t) + truth[2] * t + rng.normal(0, 0.05, t.size)

    def one(x):
        e = np.exp(x[1] * t)
        return x[0] * e + x[2] * t - y, np.stack([e, x[0] * t * e, t], axis=1)

    return one


def _halt_after(limit):
    return lambda _, nit, cost: nit >= 3 and cost > limit


@pytest.mark.parametrize("seed", range(12))
def test_equal_to_least_squares_on_random_curve_fits(seed):
    """From 6 random starts at once, every answer is ``least_squares``' from that start (no stop rule, and a
    stop after iteration 3 above a cost), to 1e-12."""
    rng = np.random.default_rng(seed)
    one = _curve(rng)
    X0 = rng.normal(0, 1.5, (6, 3))
    limit = rng.uniform(0.05, 2.0)

    def fun(idx, X):
        out = [one(x) for x in X]
        return np.array([f for f, _ in out]), np.array([J for _, J in out])

    def stop_after(intermediate_result):
        if intermediate_result.nit >= 3 and intermediate_result.cost > limit:
            raise StopIteration

    for halt, callback in ((None, None), (_halt_after(limit), stop_after)):
        got = least_squares_many(fun, X0, 50, halt)
        for x0, x in zip(X0, got, strict=True):
            ref = least_squares(lambda x: one(x)[0], x0, jac=lambda x: one(x)[1], method="trf", max_nfev=50,
                                callback=callback)
            np.testing.assert_allclose(x, ref.x, rtol=1e-12, atol=1e-12)


def _polish_ref(obs, T0, max_nfev, sigma, give_up_above=np.inf, after=GIVE_UP_ITERATIONS):
    """The polish as ``least_squares`` runs it (analytic Jacobian, left Jacobian of SO(3) at the step)."""
    kw = {"range_sigma_m": sigma, **ScoreOptions().kwargs()}

    def f_and_J(x):
        f, J = lidarcam_linearised(obs, perturb(T0, x), **kw)
        J[:, :3] = J[:, :3] @ so3_left_jacobian(x[:3])
        return f, J

    def hopeless(intermediate_result):
        if intermediate_result.nit >= after and intermediate_result.cost > give_up_above:
            raise StopIteration

    sol = least_squares(lambda x: f_and_J(x)[0], np.zeros(6), jac=lambda x: f_and_J(x)[1], method="trf",
                        max_nfev=max_nfev, callback=hopeless if np.isfinite(give_up_above) else None)
    return perturb(T0, sol.x)


STOP_AFTER = 2
"""The stop rule of the polish test: after this many iterations, above the best final cost of the starts before."""


def _scene(seed):
    """The polish test's problem and its 4 starts (the odd seeds far off)."""
    rng = np.random.default_rng(300 + seed)
    obs = make_observations(rng, 3 + seed % 3, 0.02)
    spread = np.array([0.02] * 3 + [0.05] * 3) * (1 + 10 * (seed % 2))
    return obs, np.array([perturb(obs.T_lidar_cam_true, rng.normal(0, spread)) for _ in range(4)])


def _deferred_stops(obs):
    """A stop rule as ``choose_and_refine``'s give-up: after ``STOP_AFTER`` iterations, above the best final cost
    of the starts before (unknown while they run); its ``done``, the cost function and counts of its answers."""
    kw = {"range_sigma_m": 0.02, **ScoreOptions().kwargs()}
    ends: dict[int, float] = {}
    count = {"later": 0, "stop": 0}

    def cost(T):
        return 0.5 * float(np.sum(lidarcam_linearised(obs, T, **kw)[0] ** 2))

    def halt(i, nit, c):
        if any(j not in ends for j in range(i)):
            count["later"] += 1
            return None
        stop = bool(nit >= STOP_AFTER and c > min((ends[j] for j in range(i)), default=np.inf))
        count["stop"] += stop
        return stop

    return halt, lambda i, T: ends.__setitem__(i, cost(T)), cost, count


@pytest.mark.parametrize("seed", range(10))
def test_polish_many_equal_to_least_squares_from_the_same_starts(seed):
    """The polish of 4 starts at once (some far off) is ``least_squares``' from each start, to 1e-10; with a stop
    rule whose bound for each start is known only once the starts before it end (as the give-up of
    ``choose_and_refine``) too."""
    obs, T0 = _scene(seed)
    np.testing.assert_allclose(polish_many(obs, T0, 100, ScoreOptions(), 0.02),
                               [_polish_ref(obs, T, 100, 0.02) for T in T0], atol=1e-10)
    halt, done, cost, count = _deferred_stops(obs)
    got = polish_many(obs, T0, 100, ScoreOptions(), 0.02, halt, done)
    ref = []
    for T in T0:
        ref.append(_polish_ref(obs, T, 100, 0.02, min((cost(R) for R in ref), default=np.inf), STOP_AFTER))
    np.testing.assert_allclose(got, ref, atol=1e-10)
    assert count["later"] > 0                                # some stops were decided after the start ran on


def test_the_deferred_stop_rule_stops_some_polishes():
    """Across the polish test's seeds the deferred stop rule does stop polishes (the comparison exercises it)."""
    stops = 0
    for seed in range(10):
        obs, T0 = _scene(seed)
        halt, done, _, count = _deferred_stops(obs)
        polish_many(obs, T0, 100, ScoreOptions(), 0.02, halt, done)
        stops += count["stop"]
    assert stops > 0


def test_a_start_already_at_the_optimum_is_returned_as_least_squares_returns_it():
    rng = np.random.default_rng(5)
    A = rng.normal(size=(12, 3))
    x_opt = rng.normal(size=3)
    b = A @ x_opt                                   # zero residual at x_opt: zero gradient, no step taken

    def fun(idx, X):
        return X @ A.T - b, np.repeat(A[None], len(X), axis=0)

    X0 = np.array([x_opt, x_opt + 1.0, x_opt])      # optimal, not, optimal: all three answered
    X = least_squares_many(fun, X0, 100)
    ref = [least_squares(lambda x: A @ x - b, x0, jac=lambda x: A, method="trf").x for x0 in X0]
    np.testing.assert_array_equal(X[[0, 2]], X0[[0, 2]])
    np.testing.assert_allclose(X, ref, atol=1e-12)
