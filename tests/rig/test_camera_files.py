"""Camera files in their three forms (OpenCV keys, ROS camera_info, Kalibr camchain) read to the same intrinsics
and the right ``calib_core`` model; a model or key the project does not know is one line naming file and key;
an equidistant ``camera.yaml`` is the fisheye model (it was read as a pinhole); ``--refit-intrinsics`` recovers an
equidistant camera from its corners."""

from __future__ import annotations

import numpy as np
import pytest

from calib_core.data.cameras import EUCM, Camera, DoubleSphere, Equidistant, Omni
from lidarcam.rig.dataset import BoardSpec, CameraModel, DatasetError, camera_yaml, read_camera
from lidarcam.rig.dataset.camera_files import camera_formats, lens_camera

K = [[500.0, 0.0, 320.5], [0.0, 510.0, 240.25], [0.0, 0.0, 1.0]]
FISH = [-0.01, 0.02, -0.005, 0.001]


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


def _opencv(dist, extra=""):
    return (f"image_width: 640\nimage_height: 480\ncamera_matrix: {K}\n{extra}"
            f"distortion_coefficients: {list(dist)}\n")


def _ros(model, dist):
    return ("image_width: 640\nimage_height: 480\ncamera_name: front\ncamera_matrix:\n  rows: 3\n  cols: 3\n"
            f"  data: {sum(K, [])}\ndistortion_model: {model}\ndistortion_coefficients:\n  rows: 1\n"
            f"  cols: {len(dist)}\n  data: {list(dist)}\nrectification_matrix:\n  rows: 3\n  cols: 3\n"
            "  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]\nprojection_matrix:\n  rows: 3\n  cols: 4\n"
            "  data: [500, 0, 320, 0, 0, 510, 240, 0, 0, 0, 1, 0]\n")


def _kalibr(model, dmodel, intr, dist, name="cam0"):
    return (f"{name}:\n  camera_model: {model}\n  intrinsics: {list(intr)}\n  distortion_model: {dmodel}\n"
            f"  distortion_coeffs: {list(dist)}\n  resolution: [640, 480]\n  rostopic: /cam/image_raw\n")


def _same(a: CameraModel, b: CameraModel):
    assert (a.name, a.width, a.height) == (b.name, b.width, b.height)
    np.testing.assert_array_equal(a.K, b.K)
    np.testing.assert_array_equal(a.dist, b.dist)
    np.testing.assert_array_equal(a.params, b.params)


def test_pinhole_radtan_reads_the_same_in_every_form(tmp_path):
    radtan = [0.1, -0.2, 0.001, -0.002]
    cams = [read_camera(_write(tmp_path, "o.yaml", _opencv(radtan))),
            read_camera(_write(tmp_path, "r.yaml", _ros("plumb_bob", radtan))),
            read_camera(_write(tmp_path, "k.yaml", _kalibr("pinhole", "radtan", [500, 510, 320.5, 240.25], radtan)))]
    for c in cams:
        _same(c, cams[0])
        assert isinstance(c.core(), Camera) and c.is_opencv_pinhole
    np.testing.assert_array_equal(cams[0].dist, radtan)


def test_equidistant_reads_the_same_in_every_form_and_is_the_fisheye_model(tmp_path):
    cams = [read_camera(_write(tmp_path, "r.yaml", _ros("equidistant", FISH))),
            read_camera(_write(tmp_path, "k.yaml", _kalibr("pinhole", "equidistant", [500, 510, 320.5, 240.25],
                                                            FISH))),
            read_camera(_write(tmp_path, "o.yaml", _opencv(FISH, "fisheye_model: 1\n")))]
    for c in cams:
        _same(c, cams[0])
        lens = c.core()
        assert isinstance(lens, Equidistant) and not c.is_opencv_pinhole
        np.testing.assert_array_equal(lens.dist, FISH)
        np.testing.assert_array_equal(lens.K, K)


def test_a_dataset_camera_yaml_with_equidistant_is_not_read_as_a_pinhole(tmp_path):
    """Before: ``distortion_model: equidistant`` was passed over and k1..k4 read as OpenCV's k1, k2, p1, p2."""
    from lidarcam.rig.dataset import load_camera

    cam = load_camera(_write(tmp_path, "camera.yaml", _ros("equidistant", FISH)))
    assert (cam.camera_model, cam.distortion_model) == ("pinhole", "equidistant")
    P = np.array([[0.3, -0.2, 1.0]])
    ref = Equidistant(np.array(K), FISH, 640, 480).project(P)
    np.testing.assert_allclose(cam.core().project(P), ref)


@pytest.mark.parametrize("model, dmodel, intr, dist, cls, params", [
    ("ds", "none", [-0.2, 0.6, 340, 341, 320, 240], [], DoubleSphere, {"xi": -0.2, "alpha": 0.6}),
    ("omni", "radtan", [0.9, 700, 701, 320, 240], [-0.1, 0.02, 0.001, 0.0005], Omni, {"xi": 0.9}),
    ("eucm", "none", [0.6, 1.1, 350, 351, 320, 240], [], EUCM, {"alpha": 0.6, "beta": 1.1}),
    ("pinhole", "equidistant", [400, 401, 320, 240], FISH, Equidistant, {}),
    ("pinhole", "radtan", [400, 401, 320, 240], [0.1, -0.05, 0.001, 0.002], Camera, {}),
])
def test_kalibr_camchains_map_to_the_right_model_and_parameters(tmp_path, model, dmodel, intr, dist, cls, params):
    cam = read_camera(_write(tmp_path, "camchain.yaml", _kalibr(model, dmodel, intr, dist)))
    lens = cam.core()
    assert type(lens) is cls
    fu, fv, pu, pv = intr[-4:]
    np.testing.assert_array_equal(lens.K, [[fu, 0, pu], [0, fv, pv], [0, 0, 1]])
    for name, value in params.items():
        assert getattr(lens, name) == value
    np.testing.assert_array_equal(lens.dist[:len(dist)], dist)
    assert not np.any(lens.dist[len(dist):])
    back = read_camera(_write(tmp_path, "camera.yaml", camera_yaml(cam)))   # the writer keeps every model
    _same(back, cam)


@pytest.mark.parametrize("model, dmodel, intr, dist", [
    ("ds", "none", [-0.2, 0.6, 340, 341, 320, 240], []),
    ("omni", "radtan", [0.9, 700, 701, 320, 240], [-0.1, 0.02, 0.001, 0.0005]),
    ("eucm", "none", [0.6, 1.1, 350, 351, 320, 240], []),
    ("pinhole", "equidistant", [400, 401, 320, 240], FISH),
])
def test_opencv_keys_with_kalibr_model_names_read_as_the_camchain(tmp_path, model, dmodel, intr, dist):
    """The OpenCV keys with Kalibr's ``camera_model``, ``distortion_model`` and the model's parameters beside them
    (as the simulator writes a lens's camera.yaml) read to the same camera as the camchain."""
    fu, fv, pu, pv = intr[-4:]
    names = {"omni": ["xi"], "ds": ["xi", "alpha"], "eucm": ["alpha", "beta"]}.get(model, [])
    params = "".join(f"{n}: {v}\n" for n, v in zip(names, intr, strict=False))
    text = (f"image_width: 640\nimage_height: 480\ncamera_model: {model}\ndistortion_model: {dmodel}\n{params}"
            f"camera_matrix: [[{fu}, 0, {pu}], [0, {fv}, {pv}], [0, 0, 1]]\ndistortion_coefficients: {dist}\n")
    a = read_camera(_write(tmp_path, "camera.yaml", text))
    b = read_camera(_write(tmp_path, "camchain.yaml", _kalibr(model, dmodel, intr, dist)))
    _same(a, b)


def test_ds_camchain_projects_as_the_double_sphere_formula(tmp_path):
    xi, alpha, fu, fv, pu, pv = -0.2, 0.6, 340.0, 341.0, 320.0, 240.0
    cam = read_camera(_write(tmp_path, "c.yaml", _kalibr("ds", "none", [xi, alpha, fu, fv, pu, pv], [])))
    P = np.array([0.4, -0.3, 0.5])
    d1 = np.linalg.norm(P)
    w = xi * d1 + P[2]
    den = alpha * np.sqrt(P[0] ** 2 + P[1] ** 2 + w ** 2) + (1 - alpha) * w
    np.testing.assert_allclose(cam.core().project(P[None])[0], [fu * P[0] / den + pu, fv * P[1] / den + pv])


def test_a_camchain_of_several_cameras_reads_cam0_with_a_note_or_the_one_named(tmp_path):
    text = _kalibr("pinhole", "radtan", [500, 510, 320, 240], []) + \
        _kalibr("ds", "none", [-0.2, 0.6, 340, 341, 320, 240], [], name="cam1")
    p = _write(tmp_path, "camchain.yaml", text)
    c0 = read_camera(p)
    assert c0.name == "pinhole-radtan" and "cam0 read" in c0.note and "cam1" in c0.note
    c1 = read_camera(f"{p}:cam1")
    assert c1.name == "ds" and c1.note == ""
    with pytest.raises(DatasetError, match="no camera 'cam2' \\(has cam0, cam1\\)"):
        read_camera(f"{p}:cam2")


@pytest.mark.parametrize("text, words", [
    (_ros("fisheye", FISH), ["distortion_model", "'fisheye'", "plumb_bob, rational_polynomial, equidistant"]),
    (_ros("equidistant", [0.1, 0.2, 0.0, 0.0, 0.1]), ["distortion_coefficients", "takes 4"]),
    (_opencv([0.1, 0.2, 0, 0]) + "xi: 0.8\n", ["key 'xi'", "needs camera_model"]),
    (_opencv([]) + "camera_model: ds\nxi: -0.2\n", ["key 'alpha'", "missing"]),
    (_opencv([]) + "camera_model: eucm\nalpha: 0.6\nbeta: 1.1\nxi: 0.1\n", ["key 'xi'", "accepted: alpha, beta"]),
    (_opencv([]) + "model_type: MEI\n", ["key 'model_type'", "Kalibr camchain"]),
    (_kalibr("fov", "none", [1, 2, 3, 4], []), ["cam0.camera_model", "'fov'", "pinhole, omni, ds, eucm"]),
    (_kalibr("ds", "radtan", [-0.2, 0.6, 1, 2, 3, 4], []), ["cam0.distortion_model", "accepted: none"]),
    (_kalibr("omni", "radtan", [500, 510, 320, 240], []), ["cam0.intrinsics", "xi, fu, fv, pu, pv"]),
    (_kalibr("ds", "none", [-0.2, 1.5, 300, 300, 320, 240], []), ["cam0.intrinsics", "alpha"]),
    (_kalibr("pinhole", "radtan", [500, 510, 320, 240], []).replace("  rostopic", "  focal_mm: 4\n  rostopic"),
     ["cam0.focal_mm", "accepted: camera_model"]),
])
def test_an_unknown_model_or_key_is_one_line_naming_file_and_key(tmp_path, text, words):
    p = _write(tmp_path, "camera.yaml", text)
    with pytest.raises(DatasetError) as err:
        read_camera(p)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(str(p))
    for w in words:
        assert w in msg


def test_extract_on_a_folder_with_an_unknown_lens_model_exits_2_in_one_line(tmp_path, capsys):
    from lidarcam.cli import main

    root = tmp_path / "ds"
    root.mkdir()
    _write(root, "camera.yaml", _ros("kannala_brandt", FISH))
    _write(root, "board.yaml", "cols: 6\nrows: 5\nsquare_m: 0.1\n")
    assert main(["extract", str(root), "--out", str(tmp_path / "o.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "camera.yaml" in err and "distortion_model" in err
    assert "Traceback" not in err


def test_camera_formats_lists_every_model_and_form():
    text = "\n".join(camera_formats())
    for w in ("pinhole/equidistant", "ds/none", "eucm/none", "omni/radtan", "ROS", "Kalibr", "OpenCV keys"):
        assert w in text


def _corners(lens, board, n, rng, noise_px=0.2):
    """Corners (name -> (N,2) pixels, 0.2 px noise) of ``n`` board poses that ``lens`` sees whole, 0.35-0.8 m away."""
    from calib_core.geometry.transforms import make_T, rotvec_to_matrix

    corners = {}
    while len(corners) < n:
        T = make_T(rotvec_to_matrix(rng.uniform(-0.6, 0.6, 3)), [rng.uniform(-0.6, 0.6), rng.uniform(-0.4, 0.4),
                                                                  rng.uniform(0.35, 0.8)])
        P = board.corners @ T[:3, :3].T + T[:3, 3]
        if not lens.valid(P).all():
            continue
        uv = lens.project(P) + rng.normal(0, noise_px, (len(P), 2))
        if np.all((uv > 0) & (uv < [lens.width - 1, lens.height - 1])):
            corners[f"{len(corners):03d}"] = uv
    return corners


def test_refit_recovers_an_equidistant_camera_from_its_corners():
    from lidarcam.rig.intrinsics import calibrate_equidistant, format_intrinsics

    true = Equidistant(np.array([[380.0, 0, 512.0], [0, 381.0, 384.0], [0, 0, 1]]), FISH, 1024, 768)
    board = BoardSpec(8, 6, 0.05, np.array([[-0.05, -0.05], [0.4, -0.05], [0.4, 0.3], [-0.05, 0.3]]))
    corners = _corners(true, board, 12, np.random.default_rng(4))
    corners["003"] = np.column_stack([corners["003"][5:], np.arange(5, len(board.corners))])   # identified subset
    start = lens_camera("pinhole", "equidistant", np.array([[360.0, 0, 500.0], [0, 360.0, 390.0], [0, 0, 1]]),
                        np.zeros(4), 1024, 768)
    fit = calibrate_equidistant(corners, board, start)
    assert fit.camera.name == "pinhole-equidistant" and 0.15 < fit.rms_px < 0.35
    truth = np.r_[380.0, 381.0, 512.0, 384.0, FISH]
    got = fit.camera.core().intrinsics
    sigma = np.array(list(fit.sigma.values()))
    assert np.all(sigma > 0) and np.all(np.abs(got - truth) < 5 * sigma), (got - truth) / sigma
    assert "cv2.fisheye.calibrate" in format_intrinsics(fit)[0]


def _info_bag(path, model, D, ros=1):
    """A bag holding one CameraInfo of ``model`` with coefficients ``D``."""
    from simulate.recording import RecordingOptions, _BagOut

    out = _BagOut(path, RecordingOptions(ros=ros))
    T = out.ts.types
    names = ("D", "K", "R", "P") if out.ros1 else ("d", "k", "r", "p")
    vals = (np.asarray(D, float), np.ravel(K), np.eye(3).ravel(), np.hstack([K, np.zeros((3, 1))]).ravel())
    roi = T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    msg = T["sensor_msgs/msg/CameraInfo"](header=out.header(10**9, "camera"), height=480, width=640,
                                          distortion_model=model, binning_x=0, binning_y=0, roi=roi,
                                          **{n: np.asarray(v, np.float64) for n, v in zip(names, vals, strict=True)})
    out.write("/cam/camera_info", msg, 10**9)
    out.close()
    return path


@pytest.mark.parametrize("ros", [1, 2])
def test_a_bag_camera_info_with_equidistant_is_the_fisheye_model(tmp_path, ros):
    from lidarcam.rig.bag import BagSource, read_camera_info

    bag = _info_bag(tmp_path / ("b.bag" if ros == 1 else "b"), "equidistant", FISH, ros)
    with BagSource(bag) as src:
        cam = read_camera_info(src, "/cam/camera_info")
    assert cam.name == "pinhole-equidistant"
    np.testing.assert_array_equal(cam.dist, FISH)
    _same(read_camera(_write(tmp_path, "camera.yaml", camera_yaml(cam))), cam)   # as frombag writes it


@pytest.mark.parametrize("model, D, words", [("fisheye", FISH, ["'fisheye'", "equidistant"]),
                                             ("equidistant", [0.1, 0.2, 0.0, 0.0, 0.1], ["takes 4"])])
def test_a_bag_camera_info_of_an_unknown_model_is_one_line(tmp_path, model, D, words):
    from lidarcam.rig.bag import BagError, BagSource, read_camera_info

    bag = _info_bag(tmp_path / "b.bag", model, D)
    with BagSource(bag) as src, pytest.raises(BagError) as err:
        read_camera_info(src, "/cam/camera_info")
    msg = str(err.value)
    assert "\n" not in msg and "/cam/camera_info" in msg and all(w in msg for w in words)


def test_a_board_seen_through_a_fisheye_gets_its_pose_through_the_lens():
    """Rendered through an equidistant lens (150 deg across), off-axis: the corners' positions from
    ``detect_board_lens`` lie within 3 mm of the truth; read through the pinhole of the same K they would not."""
    from calib_core.geometry.transforms import make_T, rotvec_to_matrix
    from lidarcam.rig.detect import detect_board
    from lidarcam.rig.lens_detect import detect_board_lens
    from simulate.camera import BoardSpec as SimBoard
    from simulate.camera import checkerboard_corners
    from simulate.lens_render import render_board_lens

    lens = Equidistant(np.array([[388.0, 0, 511.5], [0, 388.0, 383.5], [0, 0, 1]]), [-0.01, 0.02, -0.01, 0.002],
                       1024, 768)
    sim = SimBoard(1.0, 7, 6, 0.12)
    T = make_T(rotvec_to_matrix([0.1, -0.5, 0.05]), [0.0, -0.2, 0.5])
    gray = render_board_lens(lens, T, sim, supersample=3)
    cam = CameraModel(1024, 768, lens.K, np.asarray(lens.dist), None, lens)
    board = BoardSpec(6, 5, 0.12, np.array([[-0.12, -0.12], [0.72, -0.12], [0.72, 0.6], [-0.12, 0.6]]))
    truth = checkerboard_corners(sim) @ T[:3, :3].T + T[:3, 3]

    def error_m(det):
        P = board.corners @ det.T_cam_board[:3, :3].T + det.T_cam_board[:3, 3]
        return np.linalg.norm(P[:, None] - truth[None], axis=2).min(axis=1).max()

    det = detect_board_lens(gray, cam, board)
    assert error_m(det) < 0.003 and det.reproj_rms_px < 0.3
    pinhole = detect_board(gray, CameraModel(1024, 768, lens.K, np.zeros(0)), board)
    assert error_m(pinhole) > 0.03


def test_every_camera_file_example_of_the_docs_reads():
    """docs/dataset.md's camera.yaml section: each YAML example is a camera file the reader takes."""
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "dataset.md").read_text()
    section = text[text.index("## camera.yaml"):text.index("## board.yaml")]
    blocks = re.findall(r"```yaml\n(.*?)```", section, re.S)
    assert len(blocks) >= 5
    names = set()
    for k, block in enumerate(blocks):
        p = Path(__file__).parent / f"_doc_camera_{k}.yaml"
        try:
            p.write_text(block)
            names.add(read_camera(p).name)
        finally:
            p.unlink()
    assert {"pinhole-radtan", "pinhole-equidistant", "ds"} <= names


@pytest.mark.parametrize("lens", [
    DoubleSphere(np.array([[340.0, 0, 640.0], [0, 341.0, 512.0], [0, 0, 1]]), [], 1280, 1024, xi=-0.2, alpha=0.6),
    EUCM(np.array([[350.0, 0, 640.0], [0, 351.0, 512.0], [0, 0, 1]]), [], 1280, 1024, alpha=0.6, beta=1.1),
    Omni(np.array([[700.0, 0, 640.0], [0, 701.0, 512.0], [0, 0, 1]]), [-0.1, 0.02, 0.001, 0.0005], 1280, 1024, xi=0.9),
], ids=lambda c: c.name)
def test_refit_recovers_omni_ds_and_eucm_cameras_by_least_squares(lens):
    from lidarcam.rig.intrinsics import calibrate_lens, format_intrinsics

    board = BoardSpec(8, 6, 0.05, np.array([[-0.05, -0.05], [0.4, -0.05], [0.4, 0.3], [-0.05, 0.3]]))
    corners = _corners(lens, board, 12, np.random.default_rng(5))
    k = lens.intrinsics.copy()
    k[:4] *= [0.95, 1.05, 1.01, 0.99]            # a rough start: focal lengths 5% off, the centre 5 px off
    n_fit = lens.n_core + (4 if lens.camera_model == "omni" else 0)
    start = CameraModel.from_core(lens.with_intrinsics(k))
    keep = np.random.default_rng(6).random(len(board.corners)) < 0.8     # views with identified corners: a subset
    corners = {n: np.column_stack([c[keep], np.flatnonzero(keep)]) if i % 2 else c
               for i, (n, c) in enumerate(corners.items())}
    fit = calibrate_lens(corners, board, start)
    got = fit.camera.core().intrinsics[:n_fit]
    sigma = np.array(list(fit.sigma.values()))
    assert fit.camera.name == lens.name and len(sigma) == n_fit and 0.15 < fit.rms_px < 0.35
    assert np.all(sigma > 0) and np.all(np.abs(got - lens.intrinsics[:n_fit]) < 5 * sigma), \
        (got - lens.intrinsics[:n_fit]) / sigma
    assert "least squares" in format_intrinsics(fit)[0]


def test_a_fisheye_dataset_extracts_and_calibrates_through_its_ros_camera_yaml(tmp_path, capsys):
    """A simulated rig whose images are rendered through an equidistant lens and whose camera.yaml is ROS's
    ``distortion_model: equidistant``: ``lidarcam extract`` then ``lidarcam calibrate`` with no option beyond the
    folder land within 0.5 deg / 20 mm of the truth; the observations carry the fisheye model."""
    import json

    import cv2
    import yaml

    from calib_core.geometry.metrics import pose_errors
    from calib_core.geometry.transforms import make_T
    from lidarcam.cli import main
    from simulate import SimOptions
    from simulate.camera import BoardSpec as SimBoard
    from simulate.camera import checkerboard_corners
    from simulate.dataset import write_dataset
    from simulate.lens_render import render_board_lens

    o = SimOptions(n_boards=6, cam_width=800, cam_height=600, focal_px=300.0, lidar_res_deg=0.25, noise_mm=10.0,
                   render_supersample=1, dist_min_m=1.5, dist_max_m=3.0, max_tilt_deg=40.0)
    root = write_dataset(o, 11, tmp_path / "ds")
    lens = Equidistant(np.array([[300.0, 0, 399.5], [0, 300.0, 299.5], [0, 0, 1]]), [0.02, -0.01, 0.004, -0.001],
                       800, 600)
    gt = yaml.safe_load((root / "ground_truth.yaml").read_text())
    sim = SimBoard.of(o)
    T_sim_ds = make_T(np.eye(3), checkerboard_corners(sim)[0])
    for name, pose in gt["poses"].items():
        T_cam_sim = np.asarray(pose["T_cam_board"], float) @ np.linalg.inv(T_sim_ds)
        img = cv2.GaussianBlur(render_board_lens(lens, T_cam_sim, sim, 2).astype(np.float32), (0, 0), 0.7)
        cv2.imwrite(str(root / f"{name}.png"), np.clip(np.rint(img), 0, 255).astype(np.uint8))
    (root / "camera.yaml").write_text(_ros("equidistant", lens.dist.tolist()).replace("640", "800").replace(
        "480", "600").replace(str(sum(K, [])), "[300.0, 0.0, 399.5, 0.0, 300.0, 299.5, 0.0, 0.0, 1.0]"))
    obs, res = tmp_path / "obs.json", tmp_path / "res.json"
    assert main(["extract", str(root), "--out", str(obs)]) == 0
    cam = json.loads(obs.read_text())["camera"]
    assert (cam["camera_model"], cam["distortion_model"]) == ("pinhole", "equidistant")
    assert main(["calibrate", str(obs), "--out", str(res)]) == 0
    T = np.asarray(json.loads(res.read_text())["T_lidar_cam"], float)
    e_R, e_t = pose_errors(T, np.asarray(gt["T_lidar_cam"], float))
    assert e_R < 0.5 and e_t < 0.020, (e_R, e_t)
    print(f"fisheye dataset: e_R {e_R:.3f} deg, e_t {1000 * e_t:.1f} mm")


def test_a_plan_rig_file_takes_every_camera_form(tmp_path):
    """``lidarcam plan`` rig files: the camera section in the ROS form, or ``file:`` naming a Kalibr camchain."""
    from lidarcam.rig.plan_rig import load_plan_rig, template_text

    text = template_text()
    head, rest = text[:text.index("camera:\n")], text[text.index("lidar:\n"):]
    fish = tmp_path / "fish.yaml"
    fish.write_text(head + "camera:\n" + "".join(f"  {ln}\n" for ln in _ros("equidistant", FISH).splitlines())
                    + "  corner_sigma_px: 0.5\n" + rest)
    _write(tmp_path, "camchain.yaml", _kalibr("ds", "none", [-0.2, 0.6, 340, 341, 320, 240], []))
    ds = tmp_path / "ds.yaml"
    ds.write_text(head + "camera:\n  file: camchain.yaml\n  corner_sigma_px: 0.5\n" + rest)
    assert isinstance(load_plan_rig(fish).camera, Equidistant)
    cam = load_plan_rig(ds).camera
    assert isinstance(cam, DoubleSphere) and (cam.xi, cam.alpha) == (-0.2, 0.6)
    bad = tmp_path / "bad.yaml"
    bad.write_text(head + "camera:\n  file: camchain.yaml\n  image_width: 640\n" + rest)
    with pytest.raises(DatasetError, match="'file' names the camera file; drop image_width"):
        load_plan_rig(bad)


def test_opencv_xml_reads_its_fisheye_flag_and_the_ros_model(tmp_path):
    import cv2

    def xml(name, **extra):
        p = tmp_path / name
        fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_WRITE)
        fs.write("image_width", 640)
        fs.write("image_height", 480)
        fs.write("camera_matrix", np.array(K))
        fs.write("distortion_coefficients", np.array(FISH).reshape(1, -1))
        for k, v in extra.items():
            fs.write(k, v)
        fs.release()
        return p

    assert read_camera(xml("plain.xml")).name == "pinhole-radtan"
    for p in (xml("flag.xml", fisheye_model=1), xml("ros.xml", distortion_model="equidistant")):
        cam = read_camera(p)
        assert cam.name == "pinhole-equidistant"
        np.testing.assert_array_equal(cam.dist, FISH)
    with pytest.raises(DatasetError, match="fisheye_model': 1 contradicts distortion_model 'plumb_bob'"):
        read_camera(xml("both.xml", fisheye_model=1, distortion_model="plumb_bob"))


def test_overlays_project_through_the_lens():
    from lidarcam.rig.overlay import project_scan

    lens = DoubleSphere(np.array([[340.0, 0, 640.0], [0, 341.0, 512.0], [0, 0, 1]]), [], 1280, 1024, xi=-0.2,
                        alpha=0.6)
    cam = CameraModel.from_core(lens)
    T_cam_lidar = np.array([[0.0, -1, 0, 0], [0, 0, -1, 0.1], [1, 0, 0, 0], [0, 0, 0, 1]])  # lidar x = camera z
    bearing = np.radians(np.linspace(-85, 85, 35))
    scan = 2.0 * np.column_stack([np.cos(bearing), np.sin(bearing)])
    uv, ok = project_scan(cam, T_cam_lidar, scan)
    P = scan @ np.array([[0.0, 0, 1], [-1, 0, 0]]) + [0, 0.1, 0]
    assert ok.all()                                   # 85 deg off the axis: inside the double sphere's view
    np.testing.assert_allclose(uv, lens.project(P))
