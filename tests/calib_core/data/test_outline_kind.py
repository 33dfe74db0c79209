"""Outline certainty (``outline_kind``: exact, lower_bound, none) in the data model, the file format and every
reader of the outline: lidarcam's endpoint and outline terms, the consensus test, the verdict and peng2022."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calib_core import calibrate
from calib_core.data.io import load_observations, observations_to_dict, save_observations
from calib_core.data.observations import BoardObservation, Observations
from calib_core.errors import ObservationError
from calib_core.geometry.metrics import pose_errors
from calib_core.model.score import evidence_cost
from calib_core.robust.consensus import board_statistics
from simulate import SimOptions, generate


def with_kind(obs: Observations, kind: str, outline=None, keep_outline: bool = False) -> Observations:
    """``obs`` with every board's outline kind set to ``kind`` and its outline replaced by ``outline`` (None:
    omitted, unless ``keep_outline``)."""
    boards = tuple(BoardObservation(b.T_cam_board, b.outline if keep_outline else outline, b.scan, b.corners_px,
                                    b.corners_board, outline_kind=kind) for b in obs.boards)
    return Observations(boards, obs.T_lidar_cam_true, dict(obs.meta), obs.camera, obs.board_range_sigma_m)


def shrunk(outline: np.ndarray, factor: float) -> np.ndarray:
    c = outline.mean(axis=0)
    return c + factor * (outline - c)


def test_kinds_round_trip_and_outline_may_be_omitted_only_for_none(tmp_path):
    obs = generate(SimOptions(n_boards=4), seed=1, trial=0)
    for kind, outline in (("none", None), ("lower_bound", obs.boards[0].outline), ("exact", obs.boards[0].outline)):
        o = with_kind(obs, kind, outline)
        save_observations(o, tmp_path / "o.json")
        d = json.loads((tmp_path / "o.json").read_text())
        assert ("outline" in d["boards"][0]) == (outline is not None)
        assert d["boards"][0].get("outline_kind", "exact") == kind
        back = load_observations(tmp_path / "o.json")
        assert [b.outline_kind for b in back.boards] == [kind] * 4
        assert observations_to_dict(back) == observations_to_dict(o)
    d = observations_to_dict(obs)
    del d["boards"][2]["outline"]
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(ObservationError, match=r"bad\.json.*board 2.*outline.*missing"):
        load_observations(tmp_path / "bad.json")
    d["boards"][2]["outline_kind"] = "approximate"
    (tmp_path / "bad.json").write_text(json.dumps(d))
    with pytest.raises(ObservationError, match=r"board 2.*outline_kind.*'approximate'"):
        load_observations(tmp_path / "bad.json")


def test_no_outline_wrong_boards_named_by_lidarcam_and_peng2022_refuses(tmp_path):
    """The target: boards with outline_kind 'none' and no outline, some of them wrong."""
    for trial in range(3):
        obs = generate(SimOptions(n_boards=8, wrong_segments=1), seed=2, trial=trial)
        save_observations(with_kind(obs, "none"), tmp_path / "none.json")
        none = load_observations(tmp_path / "none.json")
        res = calibrate(none)
        assert res.ok, res.reason
        assert [r["index"] for r in res.boards_rejected] == obs.meta["wrong_boards"]
        e_R, e_t = pose_errors(res.T_lidar_cam, obs.T_lidar_cam_true)
        assert e_R < 1.5 and e_t < 0.08
        peng = calibrate(none, "peng2022")
        assert not peng.ok and "outline_kind 'none'" in peng.reason and "[0, 1, 2" in peng.reason
        assert calibrate(none, "peng2022/plane").ok          # the point-plane ablation needs no edges


def test_lower_bound_outline_lets_the_scan_run_past_it():
    """A pattern smaller than the board the lidar hits: read as exact, its outline contradicts the truth; as a
    lower bound it does not, lidarcam solves, and peng2022 keeps the paper's model with a warning."""
    obs = generate(SimOptions(n_boards=6), seed=3, trial=1)
    small = shrunk(obs.boards[0].outline, 0.4)
    exact, low = with_kind(obs, "exact", small), with_kind(obs, "lower_bound", small)
    q_exact = board_statistics(exact, obs.T_lidar_cam_true[None], 0.02, 0.03)[0]
    q_low = board_statistics(low, obs.T_lidar_cam_true[None], 0.02, 0.03)[0]
    assert q_exact.min() > 100 and q_low.max() < 30
    res = calibrate(low)
    assert res.ok, res.reason
    e_R, e_t = pose_errors(res.T_lidar_cam, obs.T_lidar_cam_true)
    assert e_R < 1.5 and e_t < 0.08
    assert not any("off the board outline" in w for w in res.warnings)
    truth_exact = calibrate(exact, "zhang_pless")   # the verdict reads an exact small outline as contradicted
    assert any("off the board outline" in w for w in truth_exact.warnings)
    peng = calibrate(low, "peng2022")
    assert peng.ok and any("outline_kind 'lower_bound'" in w for w in peng.warnings)
    assert not any("lower_bound" in w for w in calibrate(obs, "peng2022").warnings)


def test_evidence_cost_reads_lower_bounds_one_sided_and_missing_outlines_not_at_all():
    """Only exact outlines enter the endpoint and outline terms; a lower-bound outline enters only the one-sided
    chord and margin term (``refine.lower_bound``), and a missing one nothing: without that term every kind
    scores alike, and a pattern well inside the board (its chord covered) costs only the margin prior."""
    obs = generate(SimOptions(n_boards=5), seed=4, trial=0)
    rng = np.random.default_rng(4)
    C = np.repeat(obs.T_lidar_cam_true[None], 20, axis=0)
    C[:, :3, 3] += rng.normal(scale=0.1, size=(20, 3))
    costs = [evidence_cost(with_kind(obs, k, o), C, return_details=True)
             for k, o in (("none", None), ("lower_bound", obs.boards[0].outline),
                          ("lower_bound", shrunk(obs.boards[0].outline, 0.3)))]
    assert np.all(costs[0][1]["lower_bound"] == 0) and np.all(costs[2][1]["lower_bound"] > 0)
    for cost, parts in costs:
        assert np.all(parts["edge"] == 0) and np.all(parts["outline"] == 0)
        np.testing.assert_allclose(cost - parts["lower_bound"], costs[0][0], rtol=1e-12)
    cost_exact, parts_exact = evidence_cost(obs, C, return_details=True)
    assert np.all(parts_exact["edge"] > 0) and np.all(cost_exact > costs[0][0])
    assert np.all(parts_exact["lower_bound"] == 0)
