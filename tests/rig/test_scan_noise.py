"""The range noise and the arc test estimated from the boards' own segments (lidarcam.rig.scan_noise): the simulator's
noise recovered across seeds and noise levels, a colour-biased board (black squares read centimetres further than white
ones, as a Hokuyo does) not refused as an arc while a pillar still is, options given kept, and extraction recording what
it used."""

from __future__ import annotations

import numpy as np
import pytest

from calib_core.geometry.transforms import invert_T, transform_points
from lidarcam.rig.extract_options import CURVATURE_CHI2, DEFAULT_RANGE_SIGMA, ExtractionError, ExtractOptions
from lidarcam.rig.scan_noise import MIN_SEGMENTS, estimate_noise, segment_range_sigma
from lidarcam.rig.segment import curvature_statistic
from simulate import SimOptions, generate


@pytest.mark.parametrize("noise_mm", [3.0, 10.0, 20.0, 40.0])
def test_the_noise_of_simulated_scans_is_recovered_within_20_percent(noise_mm):
    for seed in range(8):
        obs = generate(SimOptions(n_boards=8, noise_mm=noise_mm), seed=seed, trial=0)
        est = estimate_noise([b.scan for b in obs.boards])
        assert est.range_source == "estimated" and est.n_segments == 8
        assert est.range_sigma_m == pytest.approx(noise_mm / 1000, rel=0.2), (seed, est.describe())
        # white noise: the fence of chi-square(1) statistics lies below the quantile, which stands
        assert est.max_curvature_chi2 == pytest.approx(CURVATURE_CHI2) or est.max_curvature_chi2 < 2 * CURVATURE_CHI2


def test_one_segment_in_range_units_at_an_oblique_incidence():
    rng = np.random.default_rng(3)
    b = np.radians(np.arange(20, 50, 0.25))
    n, d = np.array([np.cos(np.radians(-20)), np.sin(np.radians(-20))]), 2.0   # line n . p = d, beams 40-70 deg off n
    r = d / (np.c_[np.cos(b), np.sin(b)] @ n)
    got = [segment_range_sigma(np.c_[np.cos(b), np.sin(b)] * (r + rng.normal(0, 0.01, len(b)))[:, None])
           for _ in range(40)]
    assert np.median(got) == pytest.approx(0.01, rel=0.1)


def _colour_biased_boards(seed: int, contrast_m: float) -> list[np.ndarray]:
    """Boards at 1-1.8 m, 0.35 deg beams, 2 mm white noise, and each dark square read ``contrast_m`` further."""
    o = SimOptions(n_boards=10, noise_mm=2.0, dist_min_m=1.0, dist_max_m=1.8, board_size_m=0.9,
                   checker_square_m=0.09, board_squares_x=10, board_squares_y=10, lidar_res_deg=0.35, max_tilt_deg=30)
    obs = generate(o, seed=seed, trial=0)
    T_cl = invert_T(obs.T_lidar_cam_true)
    out = []
    for b in obs.boards:
        Pb = transform_points(invert_T(b.T_cam_board) @ T_cl, np.column_stack([b.scan, np.zeros(len(b.scan))]))
        dark = (np.floor(Pb[:, 0] / o.checker_square_m) + np.floor(Pb[:, 1] / o.checker_square_m)) % 2 == 0
        r = np.linalg.norm(b.scan, axis=1)
        out.append(b.scan * ((r + np.where(dark, contrast_m, 0.0)) / r)[:, None])
    return out


def _pillar(radius_m: float, dist_m: float, rng) -> np.ndarray:
    """A round pillar's returns (0.35 deg beams, 2 mm noise)."""
    b = np.radians(np.arange(-30, 30, 0.35))
    u, c = np.c_[np.cos(b), np.sin(b)], np.array([dist_m, 0.0])
    proj = u @ c
    disc = proj**2 - (c @ c - radius_m**2)
    hit = disc > 0
    return u[hit] * (proj[hit] - np.sqrt(disc[hit]) + rng.normal(0, 0.002, int(hit.sum())))[:, None]


def test_a_colour_biased_board_is_not_refused_as_an_arc_and_a_pillar_still_is():
    rng = np.random.default_rng(0)
    refused_by_white_noise_test = 0
    for seed in range(4):
        boards = _colour_biased_boards(seed, 0.08)
        # the white-noise test of a 20 mm lidar refuses some of these flat boards as arcs
        refused_by_white_noise_test += sum(curvature_statistic(P, DEFAULT_RANGE_SIGMA) > CURVATURE_CHI2
                                           for P in boards)
        est = estimate_noise(boards)
        assert 0.03 < est.range_sigma_m < 0.05, est.describe()     # the colour bias is part of the noise
        stats = [curvature_statistic(P, est.range_sigma_m) for P in boards]
        assert max(stats) <= est.max_curvature_chi2, (seed, stats, est.describe())
        for radius in (0.3, 0.5):
            assert curvature_statistic(_pillar(radius, 1.3, rng), est.range_sigma_m) > est.max_curvature_chi2
    assert refused_by_white_noise_test >= 3


def test_an_overdispersed_population_raises_the_threshold_to_its_fence():
    rng = np.random.default_rng(5)
    boards = _colour_biased_boards(1, 0.08)
    bent = []
    for P in boards:          # every board bowed by 2 cm at its middle, as a systematic range error bends it
        s = np.linspace(-1, 1, len(P))
        r = np.linalg.norm(P, axis=1)
        bent.append(P * ((r + 0.02 * (1 - s**2) + rng.normal(0, 0.002, len(P))) / r)[:, None])
    est = estimate_noise(bent)
    stats = np.array([curvature_statistic(P, est.range_sigma_m) for P in bent])
    q1, q3 = np.percentile(stats, [25, 75])
    assert est.max_curvature_chi2 == pytest.approx(max(CURVATURE_CHI2, q3 + 3 * (q3 - q1)))
    assert est.quartiles == pytest.approx((q1, q3))


def test_given_values_are_kept_and_too_few_segments_keep_the_defaults():
    obs = generate(SimOptions(n_boards=6, noise_mm=10.0), seed=1, trial=0)
    segs = [b.scan for b in obs.boards]
    est = estimate_noise(segs, range_sigma_m=0.05)
    assert (est.range_sigma_m, est.range_source, est.curvature_source) == (0.05, "given", "estimated")
    est = estimate_noise(segs, max_curvature_chi2=60.0)
    assert (est.max_curvature_chi2, est.curvature_source, est.range_source) == (60.0, "given", "estimated")
    est = estimate_noise(segs[:MIN_SEGMENTS - 1])
    assert (est.range_sigma_m, est.max_curvature_chi2) == (DEFAULT_RANGE_SIGMA, CURVATURE_CHI2)
    assert est.range_source == est.curvature_source == "default" and "fewer than" in est.describe()
    with pytest.raises(ExtractionError, match="range_sigma_m"):
        ExtractOptions(range_sigma_m=-0.01)
    with pytest.raises(ExtractionError, match="max_curvature_chi2"):
        ExtractOptions(max_curvature_chi2=float("nan"))


@pytest.fixture(scope="module")
def sim_rig(tmp_path_factory):
    from simulate.dataset import write_dataset

    opts = SimOptions(n_boards=6, cam_width=480, cam_height=360, focal_px=450.0, noise_mm=10.0, dist_max_m=5.0)
    return write_dataset(opts, 3, tmp_path_factory.mktemp("noise") / "ds")


def test_extraction_estimates_the_noise_of_a_rendered_dataset_and_says_so(sim_rig, capsys):
    from lidarcam.cli import main
    from lidarcam.rig.dataset import load_dataset
    from lidarcam.rig.extract import extract, noise_line

    obs, diags = extract(load_dataset(sim_rig))
    noise = obs.meta["extraction_noise"]
    assert obs.n_boards == 6 and noise["range_source"] == "estimated" and noise["n_segments"] == 6
    assert noise["range_sigma_m"] == pytest.approx(0.010, rel=0.2)
    assert "estimated from 6 board segments" in noise_line(obs.meta)
    given, _ = extract(load_dataset(sim_rig), ExtractOptions(range_sigma_m=0.02, max_curvature_chi2=30.0))
    assert given.meta["extraction_noise"]["range_sigma_m"] == 0.02
    assert given.meta["extraction_noise"]["range_source"] == given.meta["extraction_noise"]["curvature_source"] \
        == "given"
    out = sim_rig.parent / "obs.json"
    assert main(["extract", str(sim_rig), "--range-sigma", "0.015", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "range noise 15.0 mm (given)" in printed and "arc test: curvature statistic above" in printed


@pytest.mark.parametrize(("flag", "value"), [("--range-sigma", "nan"), ("--range-sigma", "-0.01"),
                                             ("--max-curvature-chi2", "0")])
def test_a_bad_noise_flag_is_one_line_naming_it(sim_rig, capsys, flag, value):
    from lidarcam.cli import main

    assert main(["extract", str(sim_rig), flag, value, "--out", str(sim_rig.parent / "bad.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{flag} must be a positive number" in err[0]
