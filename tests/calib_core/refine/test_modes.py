"""The covariance of the modes the data leave nearly tied (``refine.modes``): the mixture's formula on a constructed
case, never smaller than the answer's own covariance, the answer's own without runners-up, and ``lidarcam``'s answer
unchanged by it (runners-up carried through the final tests: tests/calib_core/robust)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import calib_core.methods.lidarcam as lidarcam_method
from calib_core import calibrate
from calib_core.data.io import load_observations
from calib_core.refine.modes import mixture_covariance, mode_weights

REPO = Path(__file__).resolve().parents[3]
NOWICKI = REPO / "tests" / "fixtures" / "nowicki" / "observations.json"


def _case(seed: int, n_runners: int):
    rng = np.random.default_rng(seed)
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=seed).as_matrix()
    T[:3, 3] = rng.normal(0, 0.3, 3)
    A = rng.normal(size=(6, 6)) * np.r_[[0.02] * 3, [0.01] * 3]
    cov = A @ A.T + 1e-8 * np.eye(6)
    runners = []
    for _ in range(n_runners):
        Ti = np.eye(4)
        Ti[:3, :3] = (Rotation.from_rotvec(rng.normal(0, 0.5, 3)) * Rotation.from_matrix(T[:3, :3])).as_matrix()
        Ti[:3, 3] = T[:3, 3] + rng.normal(0, 0.2, 3)
        runners.append((Ti, 100.0 + rng.uniform(0.1, 3.0)))
    return T, cov, 100.0, runners


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_mixture_is_the_likelihood_weighted_second_moment_of_the_modes_about_the_answer(seed):
    T, cov, cost, runners = _case(seed, 2)
    P, info = mixture_covariance(T, cov, cost, runners)
    like = np.exp(-np.array([0.0, *(c - cost for _, c in runners)]))   # the cost is a negative log-likelihood
    w = like / like.sum()
    want = w[0] * cov
    for wi, (Ti, _) in zip(w[1:], runners, strict=True):
        d = np.r_[(Rotation.from_matrix(Ti[:3, :3]) * Rotation.from_matrix(T[:3, :3]).inv()).as_rotvec(),
                  Ti[:3, 3] - T[:3, 3]]
        want = want + wi * (cov + np.outer(d, d))
    np.testing.assert_allclose(P, want, rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(info["weights"], w)
    assert info["n_modes"] == 3 and info["offsets_deg"][0] == 0.0
    assert info["sigma_rot_deg"] > info["sigma_rot_deg_mode"]


@pytest.mark.parametrize("seed", range(5))
def test_the_mixture_is_never_smaller_than_the_answers_covariance(seed):
    T, cov, cost, runners = _case(10 + seed, 1 + seed % 3)
    P, _ = mixture_covariance(T, cov, cost, runners)
    assert np.linalg.eigvalsh(P - cov).min() >= -1e-12 * np.abs(cov).max()


def test_without_runners_up_the_covariance_is_the_answers():
    T, cov, cost, _ = _case(3, 0)
    P, info = mixture_covariance(T, cov, cost, ())
    assert P is cov or np.array_equal(P, cov)
    assert info == {}


def test_weights_follow_the_likelihood():
    w = mode_weights(np.array([5.0, 5.0 + np.log(2.0)]))
    np.testing.assert_allclose(w, [2 / 3, 1 / 3])


def test_lidarcam_reports_the_mixture_without_changing_its_answer(monkeypatch):
    """On a weakly decided three-board subset of Nowicki (0 1 3: two runners-up within 3 in log-likelihood) the
    result's covariance is the mixture about the same answer the mode's covariance belongs to."""
    sub = load_observations(NOWICKI).subset([0, 1, 3])
    res = calibrate(sub)
    assert res.ok and len(res.info["alternatives"]) >= 2
    modes = res.info["covariance_modes"]
    assert modes["n_modes"] == len(res.info["alternatives"])
    monkeypatch.setattr(lidarcam_method, "mixture_covariance", lambda T, cov, cost, runners: (cov, {}))
    alone = calibrate(sub)
    np.testing.assert_array_equal(alone.T_lidar_cam, res.T_lidar_cam)
    assert "covariance_modes" not in alone.info
    P, _ = mixture_covariance(res.T_lidar_cam, alone.covariance, res.info["cost"],
                              [(np.array(a["T_lidar_cam"]), a["cost"]) for a in res.info["alternatives"][1:]])
    np.testing.assert_allclose(res.covariance, P, rtol=1e-9)
    assert modes["sigma_rot_deg_mode"] == pytest.approx(alone.sigma_rot_deg)
    weak = [w for w in res.warnings if w.startswith("weakly decided")]
    assert len(weak) == 1 and "the 1-sigma holds them" in weak[0]
    assert res.to_dict()["covariance_modes"] == modes

