"""The covariance widened to the profile likelihood's 1-sigma where it exceeds the linear one
(calib_core.methods.last_steps.profile_floor)."""

from dataclasses import replace

import numpy as np
import pytest
from rigs import vertical_rig

from calib_core.checks.degeneracy import undetermined_directions
from calib_core.methods.last_steps import _origin_axes, profile_floor, range_covariance


def _sigma_along(T, cov, v, scale_m):
    Ai = np.linalg.inv(_origin_axes(T, scale_m))
    return float(np.sqrt(v @ Ai @ cov @ Ai.T @ v))


def test_floor_reaches_the_profile_sigma_and_never_shrinks_the_covariance():
    hits = 0
    for seed in range(4):
        obs = vertical_rig(seed, lean_deg=10.0)
        T = obs.T_lidar_cam_true
        d = undetermined_directions(obs, T, 0.005)
        cov = range_covariance(obs, T, T[None], "test", range_sigma_m=0.005)
        out = profile_floor(T, cov, d)
        assert np.linalg.eigvalsh(out - cov).min() > -1e-12 * np.abs(cov).max()      # never smaller
        for v, s, f in zip(d.directions, d.sigmas, d.floors, strict=True):
            got = _sigma_along(T, out, v, d.scale_m)
            if f:                                 # exactly the profile's sigma, not beyond it
                assert got == pytest.approx(max(s, _sigma_along(T, cov, v, d.scale_m)), rel=1e-6)
            else:
                assert got >= _sigma_along(T, cov, v, d.scale_m) * (1 - 1e-6)
            hits += bool(f)
    assert hits >= 3


def test_no_floor_or_a_refused_set_leaves_the_covariance_as_it_is():
    obs = vertical_rig(0, lean_deg=10.0)
    T = obs.T_lidar_cam_true
    d = undetermined_directions(obs, T, 0.005)
    cov = range_covariance(obs, T, T[None], "test", range_sigma_m=0.005)
    assert d.floors.any() and profile_floor(T, cov, d) is not cov
    assert profile_floor(T, cov, replace(d, floors=np.zeros(len(d.sigmas), bool))) is cov
    assert profile_floor(T, cov, replace(d, geometric=True)) is cov
