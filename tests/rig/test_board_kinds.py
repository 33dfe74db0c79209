"""Boards in three kinds (checkerboard, Kalibr targets, ChArUco): board.yaml's forms, detection with identities
through cv2.aruco, the corner error on a rendered board, partial views and the PnP's spread rule."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from calib_core.geometry.transforms import make_T, rotvec_to_matrix, transform_points
from lidarcam.rig.dataset import CameraModel, DatasetError, board_from_dict, load_board
from lidarcam.rig.detect import MIN_HULL_SHARE, check_spread, detect_board, find_identified
from lidarcam.rig.extract_options import ExtractionError
from simulate.camera import BoardSpec as SimBoard
from simulate.camera import camera_matrix, render_board_image
from simulate.patterns import Pattern, pattern_texture

W, H, F = 400, 300, 400.0
K = camera_matrix(F, W, H)
SIM_BOARD = SimBoard(0.6, 5, 4, 0.1)
CHARUCO = Pattern("charuco", 5, 4, 0.1, 0.075, dictionary="DICT_4X4_50")
APRILGRID = Pattern("aprilgrid", 4, 3, 0.08, spacing_ratio=0.3)
CORNER_RMS_BOUND_PX = 0.15
"""Bound on the detected corners' RMS error against the rendered truth (docs/dataset.md measures ~0.1 px)."""

FORMS = {
    "charuco": {"type": "charuco", "squares_x": 5, "squares_y": 4, "square_m": 0.1, "marker_m": 0.075,
                "dictionary": "DICT_4X4_50"},
    "aprilgrid": {"target_type": "aprilgrid", "tagCols": 4, "tagRows": 3, "tagSize": 0.08, "tagSpacing": 0.3},
    "kalibr-checkerboard": {"target_type": "checkerboard", "targetCols": 6, "targetRows": 5,
                            "rowSpacingMeters": 0.05, "colSpacingMeters": 0.05},
    "checkerboard": {"cols": 6, "rows": 5, "square_m": 0.05},
}


def _render(pattern: Pattern, T_cam_sim: np.ndarray, blur: float = 0.7) -> np.ndarray:
    import cv2

    img = render_board_image(K, T_cam_sim, SIM_BOARD, W, H, 2,
                             texture=lambda q: pattern_texture(pattern, SIM_BOARD.size_m, float(min(q, 4000.0))))
    return np.clip(np.rint(cv2.GaussianBlur(img.astype(np.float32), (0, 0), blur)), 0, 255).astype(np.uint8)


def _pose(x: float = 0.0, rot=(0.25, -0.3, 0.05), z: float = 1.0) -> np.ndarray:
    """T_cam_sim: the simulator's board (origin at its corner) with its centre at (x, 0, z) in the camera."""
    R = rotvec_to_matrix(np.array(rot))
    return make_T(R, np.array([x, 0.0, z]) - R @ np.array([0.3, 0.3, 0.0]))


def _truth(pattern: Pattern, T_cam_sim: np.ndarray) -> np.ndarray:
    P = transform_points(T_cam_sim, pattern.corners() + np.r_[pattern.offset(SIM_BOARD.size_m), 0.0])
    uvw = P @ K.T
    return uvw[:, :2] / uvw[:, 2:3]


def _spec(kind: str, path: Path = Path("board.yaml")):
    return board_from_dict(dict(FORMS[kind]), path)


CAMERA = CameraModel(W, H, K, np.zeros(0))


@pytest.mark.parametrize("kind", list(FORMS))
def test_each_board_yaml_form_reads_as_its_kind(kind):
    spec = _spec(kind)
    want = {"charuco": ("charuco", 12), "aprilgrid": ("aprilgrid", 48), "kalibr-checkerboard": ("checkerboard", 30),
            "checkerboard": ("checkerboard", 30)}[kind]
    assert (spec.kind, len(spec.corners)) == want
    # without outline_m the outline is the pattern's extent: every corner lies inside it
    lo, hi = spec.outline.min(axis=0), spec.outline.max(axis=0)
    assert np.all(spec.corners[:, :2] > lo) and np.all(spec.corners[:, :2] < hi)


@pytest.mark.parametrize("kind", list(FORMS))
def test_a_bad_board_yaml_key_is_one_line_naming_file_and_key(tmp_path, kind):
    path = tmp_path / "board.yaml"
    import yaml

    path.write_text(yaml.safe_dump({**FORMS[kind], "sqaure_size": 0.1}))
    with pytest.raises(DatasetError) as err:
        load_board(path)
    msg = str(err.value)
    assert "\n" not in msg and str(path) in msg and "'sqaure_size'" in msg


def test_bad_board_values_name_the_key(tmp_path):
    cases = [({**FORMS["charuco"], "dictionary": "DICT_9X9_1"}, "'dictionary'"),
             ({**FORMS["charuco"], "marker_m": 0.2}, "'marker_m'"),
             ({**FORMS["aprilgrid"], "tagCols": 0}, "'tagCols'"),
             ({**FORMS["aprilgrid"], "target_type": "circles"}, "'target_type'"),
             ({k: v for k, v in FORMS["charuco"].items() if k != "marker_m"}, "'marker_m'")]
    for data, key in cases:
        with pytest.raises(DatasetError, match=key):
            board_from_dict(data, tmp_path / "board.yaml")


@pytest.mark.parametrize("pattern,kind", [(CHARUCO, "charuco"), (APRILGRID, "aprilgrid")])
def test_detection_finds_each_kind_with_identities_within_the_bound(pattern, kind):
    spec = _spec(kind)
    assert np.allclose(spec.corners, pattern.corners())      # the simulator draws what board.yaml describes
    T = _pose()
    ids, px = find_identified(_render(pattern, T), spec)
    truth = _truth(pattern, T)
    assert len(ids) >= 0.9 * len(spec.corners) and len(np.unique(ids)) == len(ids)
    err = np.linalg.norm(px - truth[ids], axis=1)
    assert np.sqrt(np.mean(err ** 2)) < CORNER_RMS_BOUND_PX, err
    det = detect_board(_render(pattern, T), CAMERA, spec)
    T_ds = T @ make_T(np.eye(3), np.r_[pattern.offset(SIM_BOARD.size_m), 0.0])
    assert np.linalg.norm(det.T_cam_board[:3, 3] - T_ds[:3, 3]) < 0.005
    assert np.allclose(det.corners_board(spec), spec.corners[det.ids])


@pytest.mark.parametrize("pattern,kind", [(CHARUCO, "charuco"), (APRILGRID, "aprilgrid")])
def test_a_board_cut_by_the_image_edge_is_used_with_the_corners_in_view(pattern, kind):
    spec = _spec(kind)
    T = _pose(x=-0.35, rot=(0.1, 0.2, 0.0), z=0.8)
    truth = _truth(pattern, T)
    in_view = (truth[:, 0] > 0) & (truth[:, 0] < W - 1)
    assert 0.2 < 1 - in_view.mean() < 0.6                     # the board is cut
    det = detect_board(_render(pattern, T), CAMERA, spec)
    assert MIN_HULL_SHARE < 1 and set(det.ids) <= set(np.flatnonzero(in_view))
    assert len(det.ids) >= 0.6 * in_view.sum()
    T_ds = T @ make_T(np.eye(3), np.r_[pattern.offset(SIM_BOARD.size_m), 0.0])
    assert np.linalg.norm(det.T_cam_board[:3, 3] - T_ds[:3, 3]) < 0.01


def test_too_few_or_bunched_corners_make_no_pose():
    spec = board_from_dict({**FORMS["charuco"], "squares_x": 9, "squares_y": 7}, Path("board.yaml"))
    with pytest.raises(ExtractionError, match="corners found"):
        check_spread(spec, np.arange(4))
    with pytest.raises(ExtractionError, match="span"):
        check_spread(spec, np.arange(spec.cols))                  # one row of corners
    with pytest.raises(ExtractionError, match="span"):
        check_spread(spec, np.array([0, 1, 2, 8, 9, 10]))                       # a corner of the board
    check_spread(spec, np.arange(len(spec.corners)).reshape(spec.rows, spec.cols)[:, 3:].ravel())  # 5 of 8 columns


def test_a_kalibr_checkerboard_target_is_the_checkerboard():
    a, b = _spec("kalibr-checkerboard"), _spec("checkerboard")
    assert np.allclose(a.corners, b.corners) and np.allclose(a.outline, b.outline) and not a.identified


def test_extract_uses_cut_charuco_boards_and_refits_the_pinhole_from_them(tmp_path, capsys):
    from lidarcam.cli import main
    from lidarcam.rig.dataset import load_dataset
    from lidarcam.rig.intrinsics import refit_camera
    from simulate import SimOptions
    from simulate.dataset import write_dataset

    sim = SimOptions(n_boards=6, cam_width=400, cam_height=300, focal_px=380.0, dist_min_m=1.0, dist_max_m=1.8,
                     render_supersample=1, lidar_res_deg=0.5)
    folder = write_dataset(sim, 2, tmp_path / "ds", pattern=Pattern("charuco", 6, 5, 0.15, 0.11), cut_every=2)
    ds = load_dataset(folder)
    gt = ds.ground_truth["poses"]
    n_in_view = {}
    for pose in ds.poses:
        uv = _truth_px(ds, np.asarray(gt[pose.name]["T_cam_board"], float))
        n_in_view[pose.name] = int(np.sum((uv[:, 0] >= 0) & (uv[:, 0] < 400) & (uv[:, 1] >= 0) & (uv[:, 1] < 300)))
    cut = [n for n, k in n_in_view.items() if k < len(ds.board.corners)]
    assert cut
    assert main(["extract", str(folder), "--out", str(tmp_path / "obs.json")]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split()[:3] == ["pose", "board", "corners"]
    rows = {ln.split()[0]: ln.split() for ln in table[1:] if ln.split() and ln.split()[0] in n_in_view}
    used_cut = [n for n in cut if "SKIPPED" not in rows[n]]
    assert len(used_cut) >= len(cut) - 1 and all(int(rows[n][2]) <= n_in_view[n] for n in used_cut)
    _, fit = refit_camera(ds)
    assert abs(fit.camera.K[0, 0] - 380.0) < 5 * fit.sigma["fx"] + 1.0


def _truth_px(ds, T: np.ndarray) -> np.ndarray:
    import cv2

    X = transform_points(T, ds.board.corners)
    return cv2.projectPoints(X, np.zeros(3), np.zeros(3), ds.camera.K, ds.camera.dist)[0].reshape(-1, 2)


def test_every_board_example_of_docs_dataset_md_reads(tmp_path):
    import re

    text = (Path(__file__).resolve().parents[2] / "docs" / "dataset.md").read_text()
    section = text[text.index("## board.yaml"):text.index("## Scans")]
    blocks = re.findall(r"```yaml\n(.*?)```", section, flags=re.S)
    kinds = set()
    for k, block in enumerate(blocks):
        path = tmp_path / f"board{k}.yaml"
        path.write_text(block)
        spec = load_board(path)
        kinds.add((spec.kind, spec.source))
    assert kinds == {("checkerboard", "lidarcam"), ("checkerboard", "kalibr"), ("aprilgrid", "kalibr"),
                     ("charuco", "charuco")}


def test_extract_names_the_bad_board_key_in_one_line(tmp_path, capsys):
    from lidarcam.cli import main

    (tmp_path / "camera.yaml").write_text("image_width: 400\nimage_height: 300\n"
                                          "camera_matrix: [[400, 0, 199.5], [0, 400, 149.5], [0, 0, 1]]\n")
    (tmp_path / "board.yaml").write_text("target_type: 'aprilgrid'\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\n"
                                         "tagSpacing: 0.3\ntagSpace: 0.3\n")
    assert main(["extract", str(tmp_path), "--out", str(tmp_path / "obs.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "board.yaml" in err and "'tagSpace'" in err


def test_formats_lists_every_board_kind_and_camera_model(capsys):
    from calib_core.data.cameras import CAMERA_MODELS
    from lidarcam.cli import main
    from lidarcam.rig.dataset.boards import FORMS

    assert main(["formats"]) == 0
    out = capsys.readouterr().out
    assert all(form in out for form in FORMS) and all(f"{c}/{d}" in out for c, d in CAMERA_MODELS)
