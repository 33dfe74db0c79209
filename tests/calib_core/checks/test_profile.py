"""The profile likelihood along one direction of the extrinsic (calib_core.checks.profile) and its use by the
degeneracy analysis: a fold of three boards' solutions is weak with its profile sigma, a direction the boards
leave free at every order stays undetermined."""

from pathlib import Path

import numpy as np
import pytest
from rigs import VERTICAL_OPTIONS, facing_board, general_rig, rig_from_boards

from calib_core import calibrate
from calib_core.checks.degeneracy import (
    FOLD_SPAN,
    FOLD_WORDS,
    NULL_CONDITIONING,
    origin_jacobian,
    undetermined_directions,
)
from calib_core.checks.profile import PROFILE_ONE_SIGMA, profile_rise, profile_sigma
from calib_core.data.io import load_observations
from calib_core.geometry.transforms import make_T
from calib_core.methods.lidarcam import search_and_refine
from calib_core.methods.options import LidarcamOptions
from calib_core.model.residuals import range_linearised
from calib_core.refine.uncertainty import typical_range

SEEDS = range(12)
NOWICKI = Path(__file__).resolve().parents[3] / "tests" / "fixtures" / "nowicki" / "observations.json"


def _scaled_information(obs, T):
    _, J = range_linearised(T, obs.scan_data)
    Js = origin_jacobian(J, T) * np.r_[np.ones(3), np.full(3, typical_range(obs))]
    return np.linalg.eigh(Js.T @ Js)


@pytest.mark.parametrize("seed", SEEDS)
def test_profile_sigma_is_the_linear_sigma_where_the_information_is_regular(seed):
    """Noise-free boards at the truth: the profile along an eigen-direction of the information rises as the
    quadratic of its linear sigma (within a few percent where that sigma is small: 0.001 scaled, 0.06 deg)."""
    obs = general_rig(seed, noise_mm=0.0)
    T = obs.T_lidar_cam_true
    L = typical_range(obs)
    lam, V = _scaled_information(obs, T)
    for j in (0, 5):
        sigma_m = 0.001 * np.sqrt(lam[j])                                 # linear 1-sigma 0.001 (scaled)
        s = profile_sigma(obs.scan_data, T, V[:, j], 0.01, L, sigma_m)
        assert s == pytest.approx(0.001, rel=0.05)
        assert profile_rise(obs.scan_data, T, V[:, j], -0.0005, L, sigma_m) == pytest.approx(0.125, rel=0.05)


def _y_invariant_rig(seed):
    """Boards ahead of the lidar (along its x) whose normals are all perpendicular to the lidar y axis (tilted by
    different amounts about it): a translation along y leaves every residual unchanged at every order."""
    rng = np.random.default_rng(seed)
    R = np.column_stack([[0, -1.0, 0], [0, 0, -1.0], [1.0, 0, 0]])      # camera looking along the lidar's x
    T = make_T(R, rng.uniform(-0.1, 0.1, 3))
    boards = []
    for k, tilt in enumerate(np.radians([-30.0, -8.0, 12.0, 33.0]) + rng.uniform(-0.05, 0.05, 4)):
        n = np.array([np.cos(tilt), 0.0, np.sin(tilt)])
        boards.append(facing_board(np.array([1.5 + 0.4 * k, rng.uniform(-0.6, 0.6), 0.0]), n, 0.8))
    return rig_from_boards(T, boards, VERTICAL_OPTIONS, rng)


@pytest.mark.parametrize("seed", SEEDS)
def test_a_direction_the_boards_leave_free_stays_undetermined(seed):
    obs = _y_invariant_rig(seed)
    assert obs.n_boards == 4
    T = obs.T_lidar_cam_true
    lam, V = _scaled_information(obs, T)
    assert lam[0] <= NULL_CONDITIONING**2 * lam[-1]
    assert abs(V[4, 0]) > 0.99                                           # the null direction is y
    assert np.isinf(profile_sigma(obs.scan_data, T, V[:, 0], FOLD_SPAN, typical_range(obs), 0.005))
    d = undetermined_directions(obs, T, 0.005)
    assert d.geometric and not d.determined and "y" in d.axes and not d.profile.any()


def _fold(boards):
    obs = load_observations(NOWICKI).subset(list(boards))
    found = search_and_refine(obs, LidarcamOptions())
    return found.tests.obs_used, found.best.T


@pytest.mark.skipif(not NOWICKI.exists(), reason="the committed Nowicki observations are not in this checkout")
@pytest.mark.parametrize("boards", [(4, 5, 10), (1, 6, 12), (0, 1, 11)])
def test_a_fold_of_three_boards_is_weak_with_its_profile_sigma(boards):
    """Three real boards (Nowicki's Hokuyo) whose range optimum sits where two minimal solutions meet, or next to
    it: no first-order information along one direction (or a linear sigma beyond a radian), yet the likelihood
    rises there; the answer stands with that direction named and its profile sigma, and the covariance holds
    that sigma (degrees, not the thousands of the linearisation)."""
    obs, T = _fold(boards)
    lam, _ = _scaled_information(obs, T)
    d = undetermined_directions(obs, T, None)
    assert lam[0] <= NULL_CONDITIONING**2 * lam[-1] or d.range_sigma_m / np.sqrt(lam[0]) > FOLD_SPAN
    assert d.determined and d.profile.sum() == 1
    v, s = d.directions[d.profile][0], d.sigmas[d.profile][0]
    assert 0.0 < s < FOLD_SPAN
    for sign in (1, -1):
        assert profile_rise(obs.scan_data, T, v, sign * s, d.scale_m, d.range_sigma_m) >= PROFILE_ONE_SIGMA * 0.99
    assert FOLD_WORDS in d.message()
    res = calibrate(load_observations(NOWICKI).subset(list(boards)), "lidarcam")
    assert res.ok and any(FOLD_WORDS in w for w in res.warnings)
    assert res.sigma_rot_deg is not None and 0.5 < res.sigma_rot_deg < 20.0
