"""Robustness of the default method: point trimming, consensus over boards, reporting of rejected boards, the
simulator's contamination options and the extraction's straightness test. Seeded; every test can fail."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from calib_core import calibrate
from calib_core.data.result import load_result
from calib_core.geometry.metrics import pose_errors
from calib_core.robust.consensus import board_statistics
from calib_core.robust.final import point_test
from calib_core.robust.hypotheses import needed_samples
from calib_core.robust.inliers import clipped_sigma, trim_points
from simulate import SimOptions, generate


def _accurate(res, obs, rot_deg=1.5, trans_m=0.08) -> bool:
    e_R, e_t = pose_errors(res.T_lidar_cam, obs.T_lidar_cam_true)
    return bool(e_R < rot_deg and e_t < trans_m)


def test_trim_finds_planted_gross_outliers_and_spares_clean_points():
    for trial in range(4):
        clean = generate(SimOptions(n_boards=6), seed=5, trial=trial)
        dirty = generate(SimOptions(n_boards=6, gross_outlier_frac=0.1), seed=5, trial=trial)
        assert trim_points(clean).n_trimmed <= 1
        rep = trim_points(dirty)
        planted = sum(len(d.scan) - len(c.scan) for c, d in zip(clean.boards, dirty.boards, strict=True))
        # planted returns within 4 sigma of the line (a few cm) are harmless and may stay
        assert planted - 3 <= rep.n_trimmed <= planted + 1
        assert rep.summary()["total"] == rep.n_trimmed


def _with_ranges(scan: np.ndarray, delta_m: np.ndarray) -> np.ndarray:
    """``scan`` (K,2) with each point moved ``delta_m`` (K,) along its beam."""
    r = np.linalg.norm(scan, axis=1)
    return scan * ((r + delta_m) / r)[:, None]


def test_clipped_sigma_is_the_gaussian_std_under_gross_outliers_and_widens_for_heavy_tails():
    rng = np.random.default_rng(0)
    for _ in range(3):
        e = rng.normal(0.0, 0.01, 20000)
        assert clipped_sigma(np.r_[e, rng.uniform(-5.0, 5.0, 2000)]) == pytest.approx(0.01, rel=0.03)
        # heavy-tailed noise (Student t, 3 degrees of freedom): the MAD's 4-std test cuts into the tail
        heavy = 0.01 * rng.standard_t(3, 20000)
        mad = 1.4826 * np.median(np.abs(heavy))
        assert clipped_sigma(heavy) > 1.1 * mad
        assert np.mean(np.abs(heavy) > 4 * clipped_sigma(heavy)) < 0.015 < np.mean(np.abs(heavy) > 4 * mad)
    assert clipped_sigma(np.zeros(10)) > 0


def test_final_point_test_leaves_a_board_offset_to_the_board_test_and_finds_a_stray_point():
    obs = generate(SimOptions(n_boards=6, noise_mm=10.0), seed=7, trial=0)
    sigma = 0.02
    boards = list(obs.boards)
    boards[1] = replace(boards[1], scan=_with_ranges(boards[1].scan, np.full(len(boards[1].scan), 3.5 * sigma)))
    stray = np.zeros(len(boards[3].scan))
    stray[len(stray) // 2] = 10 * sigma
    boards[3] = replace(boards[3], scan=_with_ranges(boards[3].scan, stray))
    kept, n = point_test(replace(obs, boards=tuple(boards)), obs.T_lidar_cam_true, sigma)
    assert n == 1
    assert len(kept.boards[1].scan) == len(boards[1].scan) and len(kept.boards[3].scan) == len(stray) - 1


@pytest.mark.parametrize("kind", [{"gross_outlier_frac": 0.1}, {"mixed_pixel_frac": 0.1}])
def test_lidarcam_survives_outlier_points(kind):
    for trial in range(3):
        obs = generate(SimOptions(n_boards=6, **kind), seed=11, trial=trial)
        res = calibrate(obs)
        assert res.ok, res.reason
        clean = generate(SimOptions(n_boards=6), seed=11, trial=trial)   # same geometry and noise
        e_R0, e_t0 = pose_errors(calibrate(clean).T_lidar_cam, clean.T_lidar_cam_true)
        assert _accurate(res, obs, e_R0 + 1.0, e_t0 + 0.05)
        assert res.info["points_trimmed"]["total"] > 0
        assert any("scan points left out" in w for w in res.warnings)


def test_wrong_board_named_and_left_out():
    for trial in range(3):
        obs = generate(SimOptions(n_boards=8, wrong_segments=1), seed=2, trial=trial)
        res = calibrate(obs)
        assert res.ok, res.reason
        assert [r["index"] for r in res.boards_rejected] == obs.meta["wrong_boards"]
        assert sorted(res.boards_used + obs.meta["wrong_boards"]) == list(range(8))
        assert _accurate(res, obs)
        assert any(w.startswith(f"board {obs.meta['wrong_boards'][0]} left out") for w in res.warnings)


def test_sampled_search_names_two_wrong_boards_among_twenty_and_is_reproducible():
    obs = generate(SimOptions(n_boards=20, wrong_segments=2), seed=4, trial=0)
    a, b = calibrate(obs), calibrate(obs)
    assert a.ok and a.info["consensus"]["exhaustive"] is False
    assert [r["index"] for r in a.boards_rejected] == obs.meta["wrong_boards"]
    assert _accurate(a, obs)
    np.testing.assert_array_equal(a.T_lidar_cam, b.T_lidar_cam)


def test_no_good_board_rejected_on_clean_data():
    for n in (4, 6, 9):
        for trial in range(3):
            obs = generate(SimOptions(n_boards=n), seed=8, trial=trial)
            res = calibrate(obs)
            assert res.ok and res.boards_rejected == [] and res.boards_used == list(range(n))


def test_too_few_consistent_boards_fails_with_reason():
    obs = generate(SimOptions(n_boards=5, wrong_segments=3), seed=1, trial=0)
    res = calibrate(obs)
    assert not res.ok
    assert "agree" in res.reason or "consistent" in res.reason or "contradict" in res.reason


def test_statistic_is_zero_at_the_truth_without_noise_and_large_for_a_wrong_board():
    obs = generate(SimOptions(n_boards=6, noise_mm=0.0), seed=3, trial=0)
    q = board_statistics(obs, obs.T_lidar_cam_true[None], 0.02, 0.03)[0]
    assert np.all(q < 1e-6)
    bad = generate(SimOptions(n_boards=6, wrong_segments=1), seed=3, trial=0)
    q = board_statistics(bad, bad.T_lidar_cam_true[None], 0.02, 0.03)[0]
    w = bad.meta["wrong_boards"][0]
    assert q[w] > 100 and np.all(np.delete(q, w) < 30)


def test_ransac_rule():
    assert needed_samples(1.0) == 1.0
    assert needed_samples(0.0) == np.inf
    # 50% inliers, triples: 1 - (1 - 1/8)^k >= 0.999  ->  k = 51.7
    assert needed_samples(0.5) == pytest.approx(np.log(0.001) / np.log(1 - 0.125))


def test_result_json_carries_boards_and_warnings(tmp_path):
    obs = generate(SimOptions(n_boards=8, wrong_segments=1), seed=2, trial=0)
    res = calibrate(obs)
    path = tmp_path / "r.json"
    res.save(path)
    d = json.loads(path.read_text())
    assert d["boards_used"] == res.boards_used
    assert d["boards_rejected"][0]["index"] == obs.meta["wrong_boards"][0]
    assert d["boards_rejected"][0]["statistic"] > 100 and d["boards_rejected"][0]["reason"]
    assert d["warnings"] == res.warnings and d["warnings"]
    # files written before these fields existed still load
    for k in ("boards_used", "boards_rejected", "warnings"):
        d.pop(k)
    path.write_text(json.dumps(d))
    old = load_result(path)
    assert old["boards_used"] is None and old["boards_rejected"] == [] and old["warnings"] == []


def test_contamination_keeps_the_clean_twin_and_is_off_by_default():
    clean = generate(SimOptions(n_boards=6), seed=9, trial=1)
    dirty = generate(SimOptions(n_boards=6, wrong_segments=1, mixed_pixel_frac=0.1), seed=9, trial=1)
    assert "wrong_boards" not in clean.meta
    w = dirty.meta["wrong_boards"][0]
    for i, (c, d) in enumerate(zip(clean.boards, dirty.boards, strict=True)):
        np.testing.assert_array_equal(c.T_cam_board, d.T_cam_board)
        if i != w:
            assert len(d.scan) == len(c.scan) + int(round(0.1 * len(c.scan)))
    with pytest.raises(ValueError, match="wrong_segments"):
        SimOptions(n_boards=3, wrong_segments=4)


def test_extraction_refuses_an_arc():
    from lidarcam.rig.extract_options import CURVATURE_CHI2
    from lidarcam.rig.segment import curvature_statistic

    rng = np.random.default_rng(0)
    b = np.radians(np.arange(-6, 6, 0.25))
    r = 4 / np.cos(b) + rng.normal(0, 0.02, len(b))
    assert curvature_statistic(np.c_[r * np.cos(b), r * np.sin(b)], 0.02) < CURVATURE_CHI2
    c, rad = np.array([3.0, 0.0]), 0.15
    u = np.c_[np.cos(b), np.sin(b)]
    proj = u @ c
    disc = proj**2 - (c @ c - rad**2)
    u, rr = u[disc > 0], proj[disc > 0] - np.sqrt(disc[disc > 0]) + rng.normal(0, 0.02, int((disc > 0).sum()))
    assert curvature_statistic(u * rr[:, None], 0.02) > CURVATURE_CHI2


def test_cli_prints_rejected_boards(tmp_path, capsys):
    from calib_core.data.io import save_observations
    from lidarcam.cli import main

    obs = generate(SimOptions(n_boards=8, wrong_segments=1), seed=2, trial=0)
    path = tmp_path / "obs.json"
    save_observations(obs, path)
    assert main(["calibrate", str(path), "--out", str(tmp_path / "r.json")]) == 0
    out = capsys.readouterr().out
    assert f"board {obs.meta['wrong_boards'][0]} rejected" in out and "boards used (7 of 8)" in out


def test_report_marks_rejected_boards(tmp_path):
    from lidarcam.rig.report import write_report

    obs = generate(SimOptions(n_boards=8, wrong_segments=1), seed=2, trial=0)
    res = calibrate(obs)
    summary = write_report(None, obs, res, tmp_path)
    text = summary.markdown.read_text()
    w = obs.meta["wrong_boards"][0]
    row = next(ln for ln in text.splitlines() if ln.startswith(f"| {w} |"))
    assert "rejected:" in row
    assert sum("| used |" in ln for ln in text.splitlines()) == 7


def test_overlay_of_a_rejected_pose_is_drawn(tmp_path):
    from lidarcam.rig.dataset import CameraModel
    from lidarcam.rig.overlay import draw_overlay as _overlay

    obs = generate(SimOptions(n_boards=3), seed=2, trial=0)
    cam = CameraModel(800, 600, np.array([[800.0, 0, 399.5], [0, 800.0, 299.5], [0, 0, 1]]), np.zeros(5))
    b = obs.boards[0]
    T_cam_lidar = np.linalg.inv(obs.T_lidar_cam_true)
    gray = np.full((600, 800), 128, np.uint8)
    for name, why in (("used", None), ("rejected", "scan inconsistent with the board plane")):
        _overlay(tmp_path / f"{name}.png", gray, cam, T_cam_lidar, b.T_cam_board, b.outline, None, b.scan, 50.0,
                 "pose", why)
    import matplotlib.image as mpimg

    used, rej = mpimg.imread(tmp_path / "used.png"), mpimg.imread(tmp_path / "rejected.png")
    def red(img):
        return int(((img[..., 0] > 0.9) & (img[..., 1] < 0.2) & (img[..., 2] < 0.2)).sum())

    assert red(rej) > 1000 and red(used) < red(rej) / 10
