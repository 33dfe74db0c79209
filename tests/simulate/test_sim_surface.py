"""The simulator's per-board systematic range error (simulate.surface): a range offset per board, dark and light
squares reading apart, bowed boards; checked against the flat, clean twin of each problem (common random numbers),
the rendered texture, and the stated scale in the file."""

import json
import subprocess
import sys

import numpy as np
import pytest
from rigs import RIG_LIKE, RIG_SYSTEMATIC

from calib_core.data.io import load_observations
from simulate import SimOptions, generate
from simulate.camera import BLACK, BoardSpec, board_texture
from simulate.options import settings_hash
from simulate.surface import hits_on_board

BASE = dict(n_boards=6, pose_mode="exact", noise_mm=0.0)


def _pair(seed: int, **systematic):
    """The same problem (common random numbers) without and with the systematic options."""
    clean = generate(SimOptions(**BASE), seed=seed, stream=1)
    bent = generate(SimOptions(**BASE, **systematic), seed=seed, stream=1)
    return clean, bent


def _range_change(clean, bent):
    for a, b in zip(clean.boards, bent.boards, strict=True):
        np.testing.assert_allclose(np.arctan2(a.scan[:, 1], a.scan[:, 0]), np.arctan2(b.scan[:, 1], b.scan[:, 0]),
                                   atol=1e-12)
        yield np.linalg.norm(b.scan, axis=1) - np.linalg.norm(a.scan, axis=1)


@pytest.mark.parametrize("seed", range(4))
def test_board_offset_moves_every_beam_of_a_board_by_its_drawn_offset(seed):
    clean, bent = _pair(seed, lidar_board_offset_mm=5.0)
    offsets = bent.meta["board_range_offset_m"]
    for dr, off in zip(_range_change(clean, bent), offsets, strict=True):
        np.testing.assert_allclose(dr, off, atol=1e-12)
    assert bent.board_range_sigma_m == 0.005 and clean.board_range_sigma_m == 0.0


def test_board_offsets_have_the_stated_scale():
    drawn = np.concatenate([generate(SimOptions(**BASE, lidar_board_offset_mm=5.0), seed=s).meta[
        "board_range_offset_m"] for s in range(40)])                         # 240 boards
    assert abs(np.mean(drawn)) < 3 * 0.005 / np.sqrt(len(drawn))
    assert 0.85 < np.std(drawn) / 0.005 < 1.15


@pytest.mark.parametrize("seed", range(3))
def test_dark_squares_read_farther_where_the_rendered_texture_is_dark(seed):
    clean, bent = _pair(seed, lidar_dark_offset_mm=20.0)
    spec = BoardSpec.of(SimOptions(**BASE))
    tex, ppm = board_texture(spec, 2000.0)
    n_dark = 0
    for dr, b, T in zip(_range_change(clean, bent), clean.boards, _true_boards(bent), strict=True):
        xy, _, _ = hits_on_board(b.scan, T)
        u = np.clip((xy * ppm).astype(int), 0, tex.shape[1] - 1)
        dark = tex[u[:, 1], u[:, 0]] == BLACK
        np.testing.assert_allclose(dr, np.where(dark, 0.010, -0.010), atol=1e-9)
        n_dark += dark.sum()
    assert n_dark > 20


def _true_boards(obs):
    from simulate import simulate_trial

    scene = simulate_trial(SimOptions(**obs.meta["options"]), obs.meta["seed"], obs.meta["trial"], stream=1)[0]
    return scene.T_lidar_board


@pytest.mark.parametrize("seed", range(3))
def test_a_bowed_board_bulges_by_its_amplitude_along_the_normal(seed):
    clean, bent = _pair(seed, board_bow_mm=3.0)
    spec = BoardSpec.of(SimOptions(**BASE))
    centre, half_diag = np.full(2, spec.size_m / 2), spec.size_m / np.sqrt(2)
    for b, T, a in zip(bent.boards, _true_boards(bent), bent.meta["board_bow_m"], strict=True):
        p = np.column_stack([b.scan, np.zeros(len(b.scan))])
        height = -(p @ T[:3, 2] - T[:3, 2] @ T[:3, 3])                     # towards the sensors
        xy = (p - T[:3, 3]) @ T[:3, :3][:, :2]
        expect = a * (1 - np.sum((xy - centre) ** 2, axis=1) / half_diag ** 2)
        np.testing.assert_allclose(height, expect, atol=1e-2 * abs(a) + 1e-12)  # first order in a
        assert np.max(np.abs(height)) <= abs(a) + 1e-9


def test_off_by_default_and_the_random_streams_unchanged():
    o = SimOptions(**BASE)
    assert settings_hash(o) == settings_hash(SimOptions(**BASE, lidar_board_offset_mm=0.0, board_bow_mm=0.0))
    obs = generate(o, seed=3)
    assert "board_range_offset_m" not in obs.meta and obs.board_range_sigma_m == 0.0


@pytest.mark.parametrize("bad", [dict(lidar_board_offset_mm=-1.0), dict(board_bow_mm=2000.0),
                                 dict(lidar_dark_offset_mm=float("nan"))])
def test_bad_values_are_refused(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        SimOptions(**BASE, **bad)


def test_cli_flags_write_the_stated_scale(tmp_path):
    out = tmp_path / "o.json"
    cmd = [sys.executable, "-m", "lidarcam.cli", "simulate", "--out", str(out), "--boards", "4",
           "--lidar-board-offset-mm", "4", "--lidar-dark-offset-mm", "15", "--board-bow-mm", "2"]
    subprocess.run(cmd, check=True, capture_output=True)
    assert json.loads(out.read_text())["board_range_sigma_m"] == 0.004
    obs = load_observations(out)
    assert obs.board_range_sigma_m == 0.004 and obs.subset([0, 1]).board_range_sigma_m == 0.004
    assert obs.meta["options"]["lidar_dark_offset_mm"] == 15.0
    bad = subprocess.run(cmd[:-2] + ["--board-bow-mm", "-2"], capture_output=True, text=True)
    assert bad.returncode == 2 and "--board-bow-mm" in bad.stderr and "Traceback" not in bad.stderr


def test_the_rig_like_preset_has_them_and_systematic_none_takes_them_off():
    from experiments.config.sweeps import experiment_cells

    on = experiment_cells("rig_like", ["n_trials=1"])[0].sim
    off = experiment_cells("rig_like", ["n_trials=1", "systematic=none"])[0].sim
    for k, v in (RIG_LIKE | RIG_SYSTEMATIC).items():
        assert on[k] == v, k
    for k, v in RIG_LIKE.items():
        assert off[k] == v, k
    assert all(off[k] == 0 for k in RIG_SYSTEMATIC)
