"""Issue 7: the peng2022 ablations, the explain experiment files, and a tiny explain run."""

from __future__ import annotations

import pytest

from calib_core import METHODS, calibrate
from calib_core.ablations import ABLATIONS, INVARIANT, SCALE_ONLY
from simulate import SimOptions, generate

N_PROBLEMS = 30


@pytest.fixture(scope="module")
def problems():
    return [generate(SimOptions(n_boards=4 + k % 3, noise_mm=(20.0, 30.0)[k % 2]), seed=11, trial=k)
            for k in range(N_PROBLEMS)]


def test_ablations_registered():
    for name in ABLATIONS:
        assert name in METHODS and METHODS[name].min_boards == METHODS["peng2022"].min_boards
    assert set(INVARIANT) | set(SCALE_ONLY) <= set(ABLATIONS)


def test_invariant_variants_choose_as_peng(problems):
    """nonorm (a per-board constant), betamax/betanone (one positive scale of all exponents) keep the argmax."""
    for obs in problems:
        base = calibrate(obs, "peng2022")
        for name in (*INVARIANT, *SCALE_ONLY):
            r = calibrate(obs, name)
            assert r.ok == base.ok
            if base.ok:
                assert r.info["chosen"] == base.info["chosen"], name


def test_other_variants_run(problems):
    for obs in problems[:6]:
        for name in ABLATIONS:
            r = calibrate(obs, name)
            assert r.ok or r.reason
            if r.ok:
                assert r.T_lidar_cam.shape == (4, 4)
