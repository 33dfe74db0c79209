"""The simulator's ChArUco and AprilGrid boards (simulate.patterns) and datasets written with them: exact textures,
board.yaml as lidarcam reads it, lens cameras and boards cut by the image edge."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from lidarcam.rig.dataset import load_board, load_dataset
from simulate import SimOptions
from simulate.camera import BLACK, WHITE
from simulate.dataset import CUT_SHARE, write_dataset
from simulate.patterns import Pattern, pattern_texture

PATTERNS = [Pattern("charuco", 5, 4, 0.1, 0.075, dictionary="DICT_4X4_50"),
            Pattern("charuco", 4, 4, 0.1, 0.07, dictionary="DICT_4X4_50", legacy=True),
            Pattern("aprilgrid", 4, 3, 0.08, spacing_ratio=0.3)]


@pytest.mark.parametrize("pattern", PATTERNS)
def test_the_texture_holds_each_black_rectangle_by_its_exact_area(pattern):
    tex, ppm = pattern_texture(pattern, 0.6, 731.3)          # texels not aligned with any edge
    dark = (WHITE - tex.astype(float)) / (WHITE - BLACK)
    r = pattern.dark_rects()
    area = np.sum((r[:, 2] - r[:, 0]) * (r[:, 3] - r[:, 1]))
    assert dark.sum() / ppm ** 2 == pytest.approx(area, rel=1e-6)
    assert dark.min() >= -1e-6 and dark.max() <= 1 + 1e-6


@pytest.mark.parametrize("pattern", PATTERNS)
def test_board_yaml_reads_back_as_the_pattern(tmp_path, pattern):
    path = tmp_path / "board.yaml"
    outline = np.array([[-0.05, -0.05], [0.6, -0.05], [0.6, 0.5], [-0.05, 0.5]])
    path.write_text(pattern.board_yaml(outline))
    spec = load_board(path)
    assert spec.kind == pattern.kind and np.allclose(spec.corners, pattern.corners())
    assert np.allclose(spec.outline, outline) and spec.legacy_pattern == pattern.legacy


def test_a_fisheye_dataset_with_cut_boards(tmp_path):
    sim = SimOptions(n_boards=4, cam_model="pinhole-equidistant", cam_params="-0.01,0.02,-0.01,0.002", focal_px=120.0,
                     cam_width=320, cam_height=240, dist_min_m=0.8, dist_max_m=1.6, render_supersample=1,
                     lidar_res_deg=0.5)
    pattern = Pattern("charuco", 5, 4, 0.14, 0.1, dictionary="DICT_4X4_50")
    ds = load_dataset(write_dataset(sim, 3, tmp_path / "ds", pattern=pattern, cut_every=2))
    assert ds.camera.lens is not None and ds.camera.lens.name == "pinhole-equidistant"
    assert ds.board.kind == "charuco"
    gt = yaml.safe_load((tmp_path / "ds" / "ground_truth.yaml").read_text())["poses"]
    shares = []
    for name in sorted(gt):
        T = np.asarray(gt[name]["T_cam_board"], float)
        uv = ds.camera.lens.project(ds.board.corners @ T[:3, :3].T + T[:3, 3])
        shares.append(1 - np.mean((uv[:, 0] >= 0) & (uv[:, 0] <= 319) & (uv[:, 1] >= 0) & (uv[:, 1] <= 239)))
    cut = [s for s in shares if s > 0]
    assert cut and all(CUT_SHARE[0] <= s <= CUT_SHARE[1] for s in cut)
