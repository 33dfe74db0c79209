"""``lidarcam import`` on synthetic sources: board poses + segmented points round trip, range-only logs and MATLAB
intrinsics, and one-line errors naming the file, line or flag."""

from __future__ import annotations

import numpy as np
import pytest

from calib_core.data.io import load_observations
from lidarcam.cli import main as cli
from lidarcam.rig.dataset import DatasetError
from lidarcam.rig.importers.camera_yaml import read_camera_file
from lidarcam.rig.importers.ranges import read_range_log
from lidarcam.rig.importing import POSE_COLUMNS
from simulate import SimOptions, generate


def _write_segmented(tmp_path, obs):
    pts = ["pose,x_m,y_m"] + [f"{i + 1},{x!r},{y!r}" for i, b in enumerate(obs.boards) for x, y in b.scan.tolist()]
    rows = ["pose," + ",".join(POSE_COLUMNS)]
    for i, b in enumerate(obs.boards):
        T = b.T_cam_board
        rows.append(f"{i + 1}," + ",".join(repr(float(v)) for v in [*T[:3, :3].ravel(), *(1000 * T[:3, 3])]))
    (tmp_path / "points.csv").write_text("\n".join(pts) + "\n")
    (tmp_path / "poses.csv").write_text("\n".join(rows) + "\n")


def test_segmented_import_round_trips_the_boards(tmp_path, capsys):
    obs = generate(SimOptions(n_boards=6), seed=3, trial=0)
    _write_segmented(tmp_path, obs)
    out = tmp_path / "sub" / "obs.json"
    assert cli(["import", "segmented", str(tmp_path / "points.csv"), "--poses", str(tmp_path / "poses.csv"),
                "--board-grid", "7x6", "--square", "0.1", "--out", str(out)]) == 0
    got = load_observations(out)
    assert got.n_boards == 6 and got.meta["poses"] == [str(i + 1) for i in range(6)]
    for a, b in zip(got.boards, obs.boards, strict=True):
        np.testing.assert_allclose(a.T_cam_board, b.T_cam_board, atol=1e-12)
        np.testing.assert_allclose(a.scan, b.scan, atol=1e-12)
        assert a.outline_kind == "lower_bound"
    assert "outline lower_bound" in capsys.readouterr().out
    assert cli(["import", "segmented", str(tmp_path / "points.csv"), "--poses", str(tmp_path / "poses.csv"),
                "--outline-kind", "none", "--out", str(out)]) == 0
    assert load_observations(out).boards[0].outline is None


def test_import_errors_are_one_line(tmp_path, capsys):
    obs = generate(SimOptions(n_boards=4), seed=3, trial=0)
    _write_segmented(tmp_path, obs)
    assert cli(["import", "segmented", str(tmp_path / "points.csv"), "--out", str(tmp_path / "o.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--poses" in err
    text = (tmp_path / "poses.csv").read_text().splitlines()
    text[2] = text[2].replace(",", ",x", 1)
    (tmp_path / "poses.csv").write_text("\n".join(text) + "\n")
    assert cli(["import", "segmented", str(tmp_path / "points.csv"), "--poses", str(tmp_path / "poses.csv"),
                "--board-grid", "7x6", "--square", "0.1", "--out", str(tmp_path / "o.json")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "poses.csv" in err and "line 3" in err
    assert cli(["import", "ranges", str(tmp_path), "--images", str(tmp_path), "--board-grid", "7x6", "--square",
                "0.1", "--out", str(tmp_path / "ds")]) == 2
    assert "needs --start-deg, --step-deg" in capsys.readouterr().err
    assert cli(["import", "ranges", str(tmp_path), "--images", str(tmp_path), "--start-deg", "0", "--step-deg", "0.25",
                "--board-grid", "7x6", "--square", "0.1", "--out", str(tmp_path / "ds")]) == 2
    assert "no .log files" in capsys.readouterr().err


def test_range_log_and_matlab_intrinsics(tmp_path):
    r_mm = np.array([1000, 0, 2000, 1500])
    (tmp_path / "000.log").write_text("\n".join(map(str, r_mm)) + "\n")
    scan = read_range_log(tmp_path / "000.log", 0.0, np.radians(90.0), "mm")
    assert len(scan) == 3 and scan.n_dropped == 1                       # a 0 is no return
    np.testing.assert_allclose(sorted(scan.range), [1.0, 1.5, 2.0])
    np.testing.assert_allclose(scan.points[np.argmin(np.abs(scan.bearing))], [1.0, 0.0], atol=1e-12)
    (tmp_path / "001.log").write_text("1000\n12 34\n")
    with pytest.raises(DatasetError, match=r"001\.log.*line 2.*not one range"):
        read_range_log(tmp_path / "001.log", 0.0, 0.01)
    (tmp_path / "cam.txt").write_text("K = [ 600.5 0 320.25;\n 0 601 240.5;\n 0 0 1];\n\n"
                                      "kc = [ -0.1 ; 0.02 ; 0 ; 0 ; 0 ]';")
    cam = read_camera_file(tmp_path / "cam.txt", size=(640, 480))
    np.testing.assert_allclose(cam.K, [[600.5, 0, 320.25], [0, 601, 240.5], [0, 0, 1]])
    np.testing.assert_allclose(cam.dist, [-0.1, 0.02, 0, 0, 0])
    assert (cam.width, cam.height) == (640, 480)
    (tmp_path / "bad.txt").write_text("K = [1 2 3];")
    with pytest.raises(DatasetError, match=r"bad\.txt.*field K.*9 numbers"):
        read_camera_file(tmp_path / "bad.txt", size=(640, 480))
