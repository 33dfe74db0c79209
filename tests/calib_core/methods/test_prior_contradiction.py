"""A mounting prior that contradicts the boards is named (``methods.last_steps.prior_contradiction``): a tight
prior far from the truth gives a warning that names the prior; honest priors drawn at their stated sigmas around
the truth give none (the test's false-alarm rate is 1e-3)."""

from __future__ import annotations

import numpy as np
import pytest

from calib_core import calibrate
from calib_core.geometry.mounting import MountingPrior
from calib_core.model.residuals import perturb
from simulate import SimOptions, generate


@pytest.mark.parametrize("mode", ["exact", "pixel"])
def test_a_tight_prior_far_from_the_boards_is_named(mode):
    named = 0
    for trial in range(4):
        obs = generate(SimOptions(n_boards=6, pose_mode=mode), seed=33, trial=trial)
        guess = perturb(obs.T_lidar_cam_true, np.r_[np.radians([30.0, 0.0, 0.0]), 0.0, 0.0, 0.0])
        r = calibrate(obs, "lidarcam", prior=MountingPrior(guess, np.radians(1.0), 0.001))
        text = " ".join(r.warnings) + (r.reason or "")
        named += "mounting prior contradicts the boards" in text
    assert named == 4


def test_honest_priors_raise_no_alarm():
    alarms = 0
    for trial in range(12):
        obs = generate(SimOptions(n_boards=5, pose_mode="pixel" if trial % 2 else "exact"), seed=34, trial=trial)
        rng = np.random.default_rng(trial)
        s_rot, s_t = np.radians(rng.uniform(1, 10)), rng.uniform(0.01, 0.1)
        guess = perturb(obs.T_lidar_cam_true, np.r_[rng.normal(scale=s_rot, size=3), rng.normal(scale=s_t, size=3)])
        r = calibrate(obs, "lidarcam", prior=MountingPrior(guess, s_rot, s_t))
        alarms += any("mounting prior contradicts" in w for w in r.warnings)
    assert alarms == 0
