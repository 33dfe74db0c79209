"""The search for the paper's settings: common random numbers, the objective, interval verdicts, the preset."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from experiments.engine.cell import Cell
from experiments.paper.claim_stats import claim_values, term_name
from experiments.paper.claims import Claim, claim_holds, paper_claims
from experiments.paper.objective import load_search_conf, miss, score
from simulate import SimOptions, generate

ROOT = Path(__file__).resolve().parents[2]


def test_common_random_numbers_share_draws_across_settings():
    a, b = SimOptions(noise_mm=20.0), SimOptions(noise_mm=30.0)
    # Without a stream the settings seed the draws: a different truth per setting.
    assert not np.allclose(generate(a, 0, 3).T_lidar_cam_true, generate(b, 0, 3).T_lidar_cam_true)
    ga, gb = generate(a, 0, 3, stream=1), generate(b, 0, 3, stream=1)
    np.testing.assert_allclose(ga.T_lidar_cam_true, gb.T_lidar_cam_true)
    for ba, bb in zip(ga.boards, gb.boards, strict=True):  # the same noise draws, scaled by the noise level
        np.testing.assert_allclose(ba.T_cam_board, bb.T_cam_board)
        assert ba.scan.shape == bb.scan.shape
    # stream=None is the old seeding, bit for bit.
    np.testing.assert_array_equal(generate(a, 0, 3).boards[0].scan, generate(a, 0, 3, stream=None).boards[0].scan)
    assert not np.allclose(generate(a, 0, 3, stream=2).T_lidar_cam_true, ga.T_lidar_cam_true)


def test_cell_key_unchanged_without_crn():
    sim = SimOptions().to_dict()
    plain, crn = Cell("s", sim), Cell("s", sim, crn_stream=1)
    assert plain.key == Cell("s", sim, crn_stream=None).key
    assert crn.key != plain.key


def test_every_claim_has_a_weight():
    conf = load_search_conf()
    names = {term_name(c) for c in paper_claims()}
    assert names == set(conf.objective.weights)


def test_miss_reads_the_band_in_scale_units():
    obj = load_search_conf().objective
    pts = Claim("boards", "t", "s", "points", "vasconcelos", 2, 20)
    np.testing.assert_allclose(miss(pts, np.array([10.0, 30.0, -8.0, 200.0, np.nan]), obj),
                               [0.0, 1.0, 1.0, obj.cap, obj.missing])
    rel = Claim("boards", "t", "s", "relative", "zhang_pless", 30, 260)
    # (1 + 160%) / (1 + 30%) = 2: below the band by a factor 2 -> one unit; 2.6 x 2 above -> one unit
    np.testing.assert_allclose(miss(rel, np.array([-35.0, 100.0, 620.0]), obj), [1.0, 0.0, 1.0])
    floor = Claim("noise", "t", "s", "at_least", None, 90, 100)
    np.testing.assert_allclose(miss(floor, np.array([95.0, 80.0]), obj), [0.0, 1.0])


def test_interval_verdicts():
    c = Claim("boards", "t", "s", "points", "vasconcelos", 2, 20)
    assert claim_holds(c, [10, 0], [5, -1], [15, 1]) == "holds"          # a tie does not spoil it
    assert claim_holds(c, [40, 30], [35, 25], [45, 35]) == "direction only"
    assert claim_holds(c, [40, 0], [35, -1], [45, 1]) == "holds"  # our range 0..40 overlaps 2..20
    assert claim_holds(c, [10, -3], [5, -5], [15, -1]) == "mixed"
    assert claim_holds(c, [1, -1], [-1, -3], [3, 1]) == "does not hold"  # better nowhere for sure
    assert claim_holds(c, [10, np.nan], [5, np.nan], [15, np.nan]) == "mixed"
    floor = Claim("noise", "t", "s", "at_least", None, 90, 100)
    assert claim_holds(floor, [89], [85], [93]) == "holds"
    assert claim_holds(floor, [80], [75], [85]) == "does not hold"
    assert claim_holds(c, [10, 5]) == "holds"


def _trials(n=400, p_other=0.5, seed=0):
    rng = np.random.default_rng(seed)
    rows = []
    for t in range(n):
        ok_other = rng.random() < p_other
        rows.append({"n_boards": 6, "trial": t, "method": "peng2022", "ok": True, "valid": True,
                     "e_R_deg": 1.0, "e_t_m": 0.05})
        rows.append({"n_boards": 6, "trial": t, "method": "vasconcelos", "ok": True, "valid": ok_other,
                     "e_R_deg": 1.0 if ok_other else 21.0, "e_t_m": 0.05})
    return pd.DataFrame(rows)


def test_claim_values_paired_bootstrap():
    df = _trials()
    share = df[df["method"] == "vasconcelos"]["valid"].mean()
    gap = Claim("boards", "t", "s", "points", "vasconcelos", 2, 20)
    v = claim_values(df, gap, "n_boards", n_boot=500).iloc[0]
    assert v["value"] == pytest.approx(100 * (1 - share))
    se = 100 * np.sqrt(share * (1 - share) / len(df) * 2)
    assert v["lo95"] < v["value"] < v["hi95"] and v["hi95"] - v["lo95"] == pytest.approx(4 * se, rel=0.3)
    err = Claim("boards", "t", "s", "err_deg", "vasconcelos", 2, 42)
    assert claim_values(df, err, "n_boards").iloc[0]["value"] == pytest.approx(20 * (1 - share))


def test_objective_scores_both_zhang_variants():
    df = _trials(50)
    rows = []
    for m in ("zhang_pless_linear", "zhang_pless"):
        z = df[df["method"] == "vasconcelos"].assign(method=m)
        rows.append(z)
    boards = pd.concat([df, *rows], ignore_index=True)
    noise = boards.drop(columns="n_boards").assign(noise_mm=30.0)
    sc = score({"boards": boards, "noise": noise}, load_search_conf().objective)
    assert list(sc["zhang"]) == ["zhang_pless_linear", "zhang_pless"]
    assert np.isfinite(sc["objective"]).all() and (sc["objective"] >= 0).all()


def test_preset_is_the_searched_winner():
    best = ROOT / "results" / "search" / "best.json"
    preset = ROOT / "conf" / "preset" / "paper-matched.yaml"
    assert best.exists(), "the committed preset comes with the search result it was written from"
    from experiments.config.sweeps import experiment_cells
    from experiments.paper.settings_search import sim_fields

    point = json.loads(best.read_text())
    assert f"point {point['point']}" in preset.read_text()
    cell = experiment_cells("noise", ["preset=paper-matched", "n_trials=1"])[0]
    for k, v in sim_fields(point, load_search_conf()).items():
        assert cell.sim[k] == v, k


def test_tiny_search_and_matched_run(tmp_path):
    from experiments.paper import settings_search as s
    from experiments.paper.matched import run_preset
    from experiments.paper.matched_report import write_matched_report

    conf = load_search_conf()
    points = s.design(conf)[:1]
    per = s.run_points(points, conf, 1, str(tmp_path), 1, "test")
    table, verdicts = s.evaluate_points(points, per, conf, "coarse")
    assert table["point"].tolist() == ["default"] and len(verdicts) == len(paper_claims())
    out = tmp_path / "paper-matched"
    run_preset(None, 1, str(tmp_path), out, 1, figures=False)
    run_preset(None, 1, str(tmp_path), out / "default", 1, figures=False)
    text = write_matched_report(out, "paper-matched", tmp_path / "search").read_text()
    assert text.count("\n| ") >= len(paper_claims())
    assert (out / "claims.csv").exists()


@pytest.mark.parametrize("p_other", [0.5, 0.8, 0.97])
def test_needed_trials_brings_every_interval_within_five_points(p_other):
    """Sized on a pilot, a rerun at the suggested count has every valid rate's Wilson interval and the paired
    gap's interval within +-5 points; a setting that is already narrow keeps its count."""
    from experiments.paper.matched import TARGET_HALF_WIDTH_PTS, needed_trials
    from experiments.summary.intervals import wilson_interval

    pilot = _trials(100, p_other, seed=1)
    n = needed_trials(pilot)
    assert n >= 100
    full = _trials(n, p_other, seed=2)
    v = full.pivot(index="trial", columns="method", values="valid").astype(float)
    lo, hi = wilson_interval(v.sum().to_numpy(), n)
    gap = v["peng2022"] - v["vasconcelos"]
    half = max(100 * np.max(hi - lo) / 2, 100 * 1.96 * gap.std(ddof=1) / np.sqrt(n))
    assert half <= TARGET_HALF_WIDTH_PTS * 1.08  # sampling noise of the pilot's estimate
    assert needed_trials(full) <= max(n, 1.25 * n)
    assert needed_trials(_trials(3000, 1.0)) == 3000


def test_sensitivity_lines_vary_one_setting_through_the_centre():
    from experiments.paper.settings_search import SPACE_KEYS, sensitivity_points, sensitivity_ranges

    conf = load_search_conf()
    centre = {"max_tilt_deg": 35.0, "board_size_m": 0.85, "bearing_spread_deg": 55.0, "corner_noise_px": 0.75}
    pts = sensitivity_points(conf, centre)
    assert pts[0]["point"] == "centre" and len({p["point"] for p in pts}) == len(pts)
    for p in pts[1:]:
        moved = [k for k in SPACE_KEYS if not np.isclose(p[k], centre[k])]
        assert len(moved) == 1 and p["point"].startswith(moved[0] + "=")
        lo, hi = conf.space[moved[0]]
        assert lo - 1e-9 <= p[moved[0]] <= hi + 1e-9
    # a claim that holds below 0.9 m boards only, and everywhere along the other settings
    rows = [{"point": p["point"], **{k: p[k] for k in SPACE_KEYS}, "claim": 1,
             "verdict": "holds" if p["board_size_m"] < 0.9 else "mixed"} for p in pts]
    r = sensitivity_ranges(pd.DataFrame(rows)).set_index("setting")
    board = r.loc["board_size_m"]
    assert board["holds_at"] == [v for v in board["tried"] if v < 0.9] and len(board["tried"]) >= 5
    assert r.loc["max_tilt_deg", "holds_at"] == r.loc["max_tilt_deg", "tried"]
