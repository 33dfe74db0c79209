"""Runners-up carried through ``lidarcam``'s final tests (``robust.choose.carried_runners_up``): refined again on
the boards used, the answer unchanged."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from calib_core.data.io import load_observations
from calib_core.methods.lidarcam import search_and_refine
from calib_core.methods.options import LidarcamOptions
from calib_core.robust.choose import carried_runners_up

REPO = Path(__file__).resolve().parents[3]
NOWICKI = REPO / "tests" / "fixtures" / "nowicki" / "observations.json"


def test_runners_up_carried_through_the_final_tests_are_refined_again_on_the_boards_used():
    """``robust.choose.carried_runners_up``: the runners-up of a weakly decided choice, refined again on the same
    boards, come back at their own optima (cost within the refinement's tolerance) and the answer stays."""
    opts = LidarcamOptions.from_keywords(None)
    found = search_and_refine(load_observations(NOWICKI).subset([0, 1, 3]), opts)
    first = found.first
    assert first.runners_up
    again = carried_runners_up(found.search.obs_used, first, first.runners_up, found.search.sigma_m, opts.score,
                               opts.choose)
    assert again.T is first.T and again.cost == first.cost and again.ties == first.ties
    assert len(again.runners_up) == len(first.runners_up)
    for (T1, c1), (T0, c0) in zip(again.runners_up, first.runners_up, strict=True):
        assert c1 == pytest.approx(c0, abs=0.05)
        assert np.degrees(np.linalg.norm(Rotation.from_matrix(T1[:3, :3] @ T0[:3, :3].T).as_rotvec())) < 1.0
    none = carried_runners_up(found.search.obs_used, first, (), found.search.sigma_m, opts.score, opts.choose)
    assert none.runners_up == ()
