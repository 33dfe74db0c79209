"""Hostile inputs for the command line's verbs (``import``, ``plan``, ``bag``, ``calibrate``'s priors and
intrinsics' sigmas, ``demo``, ``simulate``): each a ``CliCase`` whose argv may name files of a small source tree
that ``make_sources`` writes (a RADLOCC log with its images, a camera file, an observation file with corners, a
rig description, a board file, a ROS 2 bag).

Every case of ``expect="error"`` must end in exit 2 with one line ``lidarcam VERB: error: ...`` naming ``names`` (a
file, flag or field); a case of ``expect="answer"`` (hostile values the verb can use) in exit 0 or 1, with no
``nan`` in what it prints. Never a traceback, a hang or a RuntimeWarning on stderr. ``tests/cli/test_cli_fuzz.py``
runs them."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

LASER_HEAD = "1.0 -1.5707963 0.0174533 1.5707963 3 181"
"""A RADLOCC laser line header: timestamp, 180 deg at 1 deg, metres, 181 ranges."""


@dataclass(frozen=True)
class CliCase:
    name: str
    argv: tuple[str, ...]     # "{S}" stands for the source folder
    names: str                # what the error line must name
    prepare: str = ""         # a key of PREPARE: writes the hostile file into the source folder
    expect: str = "error"     # "error": exit 2, one line; "answer": exit 0 or 1, no nan printed


def _laser_line(head: str = LASER_HEAD) -> str:
    return head + " " + " ".join(["2.5"] * 181)


def make_sources(root: Path) -> Path:
    """A small source tree under ``root``: ``laser.txt`` (3 lines) + ``img/RGB{1,2,3}.png``, ``camera.yaml``,
    ``obs.json`` (simulated, with corners and camera) and ``res.json`` (its calibration), ``rig.yaml`` (a copy of
    the plan template), ``board.yaml``."""
    import cv2

    from calib_core import calibrate, observations_to_dict
    from simulate import SimOptions, generate

    root.mkdir(parents=True, exist_ok=True)
    (root / "img").mkdir(exist_ok=True)
    for n in (1, 2, 3):
        cv2.imwrite(str(root / "img" / f"RGB{n}.png"), np.zeros((48, 64), np.uint8))
    (root / "laser.txt").write_text("\n".join(_laser_line() for _ in range(3)) + "\n")
    (root / "camera.yaml").write_text("image_width: 64\nimage_height: 48\ncamera_matrix: {rows: 3, cols: 3, "
                                      "data: [50, 0, 32, 0, 50, 24, 0, 0, 1]}\ndistortion_coefficients: "
                                      "{rows: 1, cols: 5, data: [0, 0, 0, 0, 0]}\n")
    obs = generate(SimOptions(n_boards=5, pose_mode="pixel"), seed=2, trial=0)
    (root / "obs.json").write_text(json.dumps(observations_to_dict(obs)))
    calibrate(obs).save(root / "res.json")
    (root / "board.yaml").write_text("cols: 7\nrows: 6\nsquare_m: 0.1\n")
    _bouguet(root / "calib.mat")
    (root / "points.csv").write_text("pose,x_m,y_m\n" + "".join(f"{k},{2.0 + 0.01 * i},{-0.2 + 0.02 * i}\n"
                                                                 for k in (1, 2) for i in range(20)))
    from lidarcam.rig.plan_rig import template_text

    (root / "rig.yaml").write_text(template_text())
    return root


def _bouguet(path: Path, **edit) -> None:
    """A two-image Bouguet ``Calib_Results.mat`` (``edit``: fields replaced)."""
    from scipy.io import savemat

    X = np.array([[0, 23, 0, 23], [0, 0, 23, 23], [0, 0, 0, 0]], float)
    d = {"fc": [[500.0], [600.0]], "cc": [[320.0], [240.0]], "alpha_c": [[0.0]],
         "kc": [[0.1], [-0.2], [0.001], [0.002], [0.0]], "nx": [[640]], "ny": [[480]], "n_ima": [[2]],
         "active_images": [[1, 1]], "dX": [[23.0]]}
    for k in (1, 2):
        d[f"Rc_{k}"], d[f"Tc_{k}"] = np.eye(3), np.array([[0.0], [0.0], [2000.0 + 100 * k]])
        d[f"x_{k}"], d[f"X_{k}"] = np.arange(8.0).reshape(2, 4), X
    d.update(edit)
    savemat(path, d)


def _mat(**edit):
    return lambda root: _bouguet(root / "calib.mat", **edit)


def _radlocc(*extra: str) -> tuple[str, ...]:
    return ("import", "radlocc", "{S}/laser.txt", "--images", "{S}/img", "--camera", "{S}/camera.yaml",
            "--board-grid", "7x6", "--square", "0.1", "--out", "{S}/ds", *extra)


def _write(name: str, data: bytes | str):
    def prep(root: Path) -> None:
        p = root / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data.encode() if isinstance(data, str) else data)
    return prep


def _rig_edit(old: str, new: str):
    def prep(root: Path) -> None:
        p = root / "rig.yaml"
        text = p.read_text()
        assert old in text
        p.write_text(text.replace(old, new))
    return prep


def _json_edit(name: str, edit, out: str | None = None):
    """Edit the JSON file ``name`` of the source folder (``edit(d)`` returns the new document or None: ``d``
    edited in place), written to ``out`` (default: in place)."""
    def prep(root: Path) -> None:
        d = json.loads((root / name).read_text())
        new = edit(d)
        (root / (out or name)).write_text(json.dumps(d if new is None else new))
    return prep


def _at(path: tuple, value):
    def edit(d):
        node = d
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value
    return edit


def _board_at_zero(d: dict) -> None:
    for row in d["boards"][1]["T_cam_board"][:3]:
        row[3] = 0.0


def _other_rig(root: Path) -> None:
    (root / "rig").mkdir()
    (root / "rig" / "007.png").write_bytes(b"x")
    (root / "rig" / "007.csv").write_text("bearing_rad,range_m\n")


PREPARE = {
    "mat_nx_nan": _mat(nx=[[np.nan]]),
    "mat_ny_inf": _mat(ny=[[np.inf]]),
    "mat_n_ima_inf": _mat(n_ima=[[np.inf]]),
    "mat_n_ima_huge": _mat(n_ima=[[1e12]]),
    "mat_no_active": _mat(active_images=[[0, 0]]),
    "mat_fc_nan": _mat(fc=[[np.nan], [600.0]]),
    "mat_dx_nan": _mat(dX=[[np.nan]]),
    "rig_huge_grid": _rig_edit("steps: {distance_m: 3, bearing_deg: 7, height_m: 1, turn_deg: 5, lean_deg: 5, "
                               "roll_deg: 1}", "steps: {distance_m: 30, bearing_deg: 70, height_m: 10, turn_deg: 50, "
                               "lean_deg: 50, roll_deg: 10}"),
    "rig_huge_beams": _rig_edit("resolution_deg: 0.25", "resolution_deg: 0.0000001"),
    "rig_fov_1e6": _rig_edit("fov_deg: 180.0", "fov_deg: 1000000.0"),
    "laser_inf": _write("laser.txt", _laser_line(LASER_HEAD.replace(" 181", " inf")) + "\n"),
    "laser_nan": _write("laser.txt", _laser_line(LASER_HEAD.replace(" 181", " nan")) + "\n"),
    "laser_nan_start": _write("laser.txt", _laser_line(LASER_HEAD.replace("-1.5707963", "nan")) + "\n"),
    "xml_junk": _write("cam.xml", "<?xml version='1.0'?><opencv_storage><camera_matrix>junk</camera_matrix>"
                                  "</opencv_storage>"),
    "xml_nan": _write("cam.xml", "<?xml version='1.0'?><opencv_storage><image_width>64</image_width>"
                                 "<image_height>48</image_height><camera_matrix type_id='opencv-matrix'><rows>3</rows>"
                                 "<cols>3</cols><dt>d</dt><data>nan 0 32 0 50 24 0 0 1</data></camera_matrix>"
                                 "</opencv_storage>"),
    "xml_binary": _write("cam.xml", b"<?xml\x00\xff\xfe" + bytes(range(256))),
    "pcd_text_count": _write("pcd/000.pcd", "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT a b c\n"
                                            "WIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n1 0 0\n2 0 0\n"),
    "binary_rig": _write("bin.yaml", bytes(range(256)) * 4),
    "binary_board": _write("binboard.yaml", b"\x00\xff" * 300),
    "bad_db3": _write("badbag/badbag.db3", b"SQLite format 3\x00" + b"\x00" * 200),
    "res_list": _json_edit("res.json", lambda d: [d], "bad_res.json"),
    "res_nan": _json_edit("res.json", _at(("T_lidar_cam", 1, 2), float("nan")), "bad_res.json"),
    "res_3x3": _json_edit("res.json", _at(("T_lidar_cam",), np.eye(3).tolist()), "bad_res.json"),
    "res_board_x": _json_edit("res.json", _at(("boards_rejected",), [{"index": "x", "reason": "r"}]),
                              "bad_res.json"),
    "obs_std_intrinsics_tiny": _json_edit("obs.json", _at(("camera", "std_intrinsics"), [1e-300] * 4)),
    "obs_board_at_zero": _json_edit("obs.json", _board_at_zero),
    "obs_pose_1e300": _json_edit("obs.json", _at(("boards", 1, "T_cam_board", 0, 3), 1e300)),
    "obs_scan_1e300": _json_edit("obs.json", _at(("boards", 2, "scan", 0), [1e300, 1e300])),
    "other_rig": _other_rig,
}


def _bag(*extra: str, board: str = "{S}/board.yaml", bag: str = "{S}/badbag") -> tuple[str, ...]:
    return ("bag", bag, "--image-topic", "/camera/image_raw", "--scan-topic", "/scan", "--camera-info-topic",
            "/camera/camera_info", "--board", board, "--out", "{S}/bagds", *extra)


def _cal(*extra: str, obs: str = "{S}/obs.json") -> tuple[str, ...]:
    return ("calibrate", obs, *extra)


PRIOR = ("--prior", "x=0,y=0,z=0.1,roll=0,pitch=-3,yaw=0")

CASES = [
    # import radlocc: the laser header, the image name, the grid, the square, the camera file
    CliCase("radlocc_count_inf", _radlocc(), "field N", "laser_inf"),
    CliCase("radlocc_count_nan", _radlocc(), "field N", "laser_nan"),
    CliCase("radlocc_start_nan", _radlocc(), "field StartAngleRad", "laser_nan_start"),
    CliCase("radlocc_image_name_unknown_brace", _radlocc("--image-name", "RGB{m}.png"), "--image-name"),
    CliCase("radlocc_image_name_unclosed_brace", _radlocc("--image-name", "RGB{n.png"), "--image-name"),
    CliCase("radlocc_image_name_no_brace", _radlocc("--image-name", "RGB.png"), "--image-name"),
    CliCase("radlocc_grid_0x6", _radlocc()[:-6] + ("--board-grid", "0x6", "--square", "0.1", "--out", "{S}/ds"),
            "--board-grid"),
    CliCase("radlocc_square_in_mm", _radlocc()[:-4] + ("--square", "100", "--out", "{S}/ds"), "mm"),
    CliCase("radlocc_square_nan", _radlocc()[:-4] + ("--square", "nan", "--out", "{S}/ds"), "--square"),
    CliCase("radlocc_camera_xml_junk", _radlocc()[:5] + ("--camera", "{S}/cam.xml") + _radlocc()[7:], "cam.xml",
            "xml_junk"),
    CliCase("radlocc_camera_xml_nan", _radlocc()[:5] + ("--camera", "{S}/cam.xml") + _radlocc()[7:], "cam.xml",
            "xml_nan"),
    CliCase("radlocc_camera_xml_binary", _radlocc()[:5] + ("--camera", "{S}/cam.xml") + _radlocc()[7:], "cam.xml",
            "xml_binary"),
    CliCase("pcd_text_count", ("import", "pcd", "{S}/pcd", "--images", "{S}/img", "--camera", "{S}/camera.yaml",
                               "--board-grid", "7x6", "--square", "0.1", "--out", "{S}/ds"), "000.pcd",
            "pcd_text_count"),
    # import bouguet: NaN sizes, no active image, counts that are no counts
    *[CliCase(f"bouguet_{k}", ("import", "bouguet", "{S}/calib.mat", "--points", "{S}/points.csv", "--out",
                               "{S}/b.json"), field, f"mat_{k}")
      for k, field in (("nx_nan", "nx"), ("ny_inf", "ny"), ("n_ima_inf", "n_ima"), ("n_ima_huge", "n_ima"),
                       ("no_active", "no active image"), ("fc_nan", "fc"), ("dx_nan", "dX"))],
    CliCase("bouguet_out_is_points", ("import", "bouguet", "{S}/calib.mat", "--points", "{S}/points.csv", "--out",
                                      "{S}/points.csv"), "is the input file"),
    # plan on a binary file
    CliCase("plan_binary_rig", ("plan", "{S}/bin.yaml"), "bin.yaml", "binary_rig"),
    CliCase("plan_rig_huge_grid", ("plan", "{S}/rig.yaml"), "workspace.steps", "rig_huge_grid"),
    CliCase("plan_rig_huge_beams", ("plan", "{S}/rig.yaml"), "resolution_deg", "rig_huge_beams"),
    CliCase("plan_rig_fov_1e6", ("plan", "{S}/rig.yaml"), "fov_deg", "rig_fov_1e6"),
    CliCase("plan_next_huge", ("plan", "{S}/rig.yaml", "--next", "100000000"), "--next"),
    # bag: a corrupt db3, a binary board file, a NaN time offset
    CliCase("bag_corrupt_db3", _bag(), "badbag", "bad_db3"),
    CliCase("bag_binary_board", _bag(board="{S}/binboard.yaml"), "binboard.yaml", "binary_board"),
    CliCase("bag_time_offset_nan", _bag("--time-offset", "nan"), "--time-offset"),
    CliCase("bag_time_offset_inf", _bag("--time-offset", "inf"), "--time-offset"),
    # calibrate: intrinsics' sigmas, priors, fixed values
    CliCase("std_intrinsics_1e9", _cal("--std-intrinsics", "1e9,1e9,1e9,1e9"), "std_intrinsics"),
    CliCase("std_intrinsics_dist_1e9", _cal("--std-intrinsics", "1,1,1,1,1e9,0,0,0,0"), "std_intrinsics"),
    CliCase("prior_sigma_1e-300", _cal(*PRIOR, "--prior-sigma", "1e-300mm,1e-300deg"), "--prior-sigma"),
    CliCase("prior_sigma_1e300", _cal(*PRIOR, "--prior-sigma", "1e300mm,1e300deg"), "--prior-sigma"),
    CliCase("prior_sigma_negative", _cal(*PRIOR, "--prior-sigma", "-50mm,10deg"), "--prior-sigma"),
    CliCase("prior_sigma_no_unit", _cal(*PRIOR, "--prior-sigma", "50,10deg"), "--prior-sigma"),
    CliCase("fix_roll_400", _cal("--fix", "roll=400"), "roll"),
    CliCase("fix_z_in_degrees", _cal("--fix", "z=11deg"), "z"),
    CliCase("fix_x_1e9", _cal("--fix", "x=1e9"), "x_m"),
    CliCase("fix_nan", _cal("--fix", "pitch=nan"), "pitch"),
    CliCase("calibrate_out_is_input", _cal("--out", "{S}/obs.json"), "obs.json"),
    CliCase("std_intrinsics_1e-300", _cal("--std-intrinsics", "1e-300,1e-300,1e-300,1e-300"), "", expect="answer"),
    CliCase("file_std_intrinsics_1e-300", _cal(), "", "obs_std_intrinsics_tiny", expect="answer"),
    # calibrate: a board at the camera centre, a pose or a scan point at 1e300 m (peng2022 too)
    CliCase("calibrate_board_at_zero", _cal(), "", "obs_board_at_zero", expect="answer"),
    CliCase("calibrate_pose_1e300", _cal(), "T_cam_board", "obs_pose_1e300"),
    CliCase("calibrate_scan_1e300_peng2022", _cal("--method", "peng2022"), "scan", "obs_scan_1e300"),
    # report: a result that is a list, holds NaN, a 3x3 T, or names board 'x'
    *[CliCase(f"report_{k}", ("report", "{S}/obs.json", "{S}/bad_res.json", "--out", "{S}/rep"), field, f"res_{k}")
      for k, field in (("list", "expected a JSON object"), ("nan", "T_lidar_cam"), ("3x3", "T_lidar_cam"),
                       ("board_x", "boards_rejected[0].index"))],
    # extract, report, bag, simulate: numbers that are no value of their option
    *[CliCase(f"{verb}_{flag[2:]}_{value}", (verb, *args, flag, value), flag)
      for verb, args in (("extract", ("{S}/ds", "--out", "{S}/o.json")),
                         ("report", ("{S}/ds", "{S}/r.json", "--out", "{S}/rep")))
      for flag, value in (("--max-offset", "inf"), ("--max-offset", "nan"), ("--max-board", "-2"),
                          ("--max-reproj", "nan"), ("--max-reproj", "0"))],
    # (--range-sigma and --max-curvature-chi2: extract's own check, tests/rig/test_scan_noise.py)
    CliCase("bag_min_move_negative", _bag("--min-move", "-1"), "--min-move"),
    CliCase("simulate_noise_nan", ("simulate", "--noise-mm", "nan", "--out", "{S}/sim.json"), "--noise-mm"),
    CliCase("import_step_nan", ("import", "ranges", "{S}/img", "--images", "{S}/img", "--start-deg", "0",
                                "--step-deg", "nan", "--out", "{S}/ds"), "--step-deg"),
    # demo, simulate
    CliCase("demo_seed_negative", ("demo", "{S}/demo", "--seed", "-1"), "--seed"),
    CliCase("demo_into_another_rigs_folder", ("demo", "{S}/rig"), "007.csv", "other_rig"),
    CliCase("simulate_noise_negative", ("simulate", "--noise-mm", "-5", "--out", "{S}/sim.json"), "--noise-mm"),
]
"""Each case: exit 2, one line ``lidarcam VERB: error: ...`` naming ``names``; or, ``expect="answer"``, exit 0 or 1
with no ``nan`` printed."""
