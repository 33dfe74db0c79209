"""``lidarcam extract`` on a small simulated dataset folder: a board.yaml square off by a unit factor ends with a
hint naming square_m and the factor, an all-NaN scan is skipped as "no returns", no usable pose is exit 1 (no
answer, as docs/usage.md and --help say), and the capture plan speaks the command line's ``--fix`` words."""

from __future__ import annotations

import re
import shutil

import pytest

from lidarcam.cli import main
from simulate import SimOptions
from simulate.dataset import write_dataset

SIM = SimOptions(n_boards=4, cam_width=320, cam_height=240, focal_px=320.0, lidar_res_deg=0.5, noise_mm=5.0,
                 render_supersample=1, dist_min_m=2.0, dist_max_m=3.5, max_tilt_deg=45.0)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return write_dataset(SIM, 3, tmp_path_factory.mktemp("ds") / "ds")


def _copy(dataset, tmp_path):
    out = tmp_path / "ds"
    shutil.copytree(dataset, out)
    return out


def _scale_square(folder, factor):
    p = folder / "board.yaml"
    text = p.read_text()
    m = re.search(r"square_m: ([0-9.eE+-]+)", text)
    p.write_text(text.replace(m.group(0), f"square_m: {float(m.group(1)) * factor!r}"))
    return float(m.group(1))


def test_the_dataset_extracts_without_a_hint(dataset, tmp_path, capsys):
    assert main(["extract", str(dataset), "--out", str(tmp_path / "o.json")]) == 0
    assert "hint:" not in capsys.readouterr().out


@pytest.mark.parametrize("factor", [10.0, 0.1])
def test_a_square_off_by_ten_is_named_with_its_factor(dataset, tmp_path, capsys, factor):
    ds = _copy(dataset, tmp_path)
    square = _scale_square(ds, factor)
    code = main(["extract", str(ds), "--out", str(tmp_path / "o.json")])
    out, err = capsys.readouterr()
    hint = [ln for ln in out.splitlines() if ln.startswith("hint:")]
    assert len(hint) == 1 and "square_m" in hint[0], out[-1500:]
    assert f"= {square:g} m would match" in hint[0], hint[0]
    if code == 1:   # no pose passed: no answer, exit 1 and one line, no file
        assert "no usable pose" in err and len(err.strip().splitlines()) == 1
        assert not (tmp_path / "o.json").exists()
    else:
        assert code == 0


def test_an_all_nan_scan_is_no_returns(dataset, tmp_path, capsys):
    ds = _copy(dataset, tmp_path)
    scan = sorted(ds.glob("[0-9]*.csv"))[0]
    (scan).write_text("bearing_rad,range_m\n" + "".join(f"{-1 + 0.01 * i},nan\n" for i in range(200)))
    assert main(["extract", str(ds), "--out", str(tmp_path / "o.json")]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith(f"skipped {scan.stem}"))
    assert "no returns" in line and "background" not in line, line


def test_no_usable_pose_is_exit_1(dataset, tmp_path, capsys):
    ds = _copy(dataset, tmp_path)
    for scan in ds.glob("[0-9]*.csv"):
        scan.write_text("bearing_rad,range_m\n" + "".join(f"{-1 + 0.01 * i},nan\n" for i in range(200)))
    assert main(["extract", str(ds), "--out", str(tmp_path / "o.json")]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no usable pose" in err and str(ds) in err


def test_the_capture_plan_of_extract_speaks_fix(dataset, tmp_path, capsys, monkeypatch):
    import lidarcam.rig.report

    monkeypatch.setattr(lidarcam.rig.report, "capture_advice", lambda obs: "vertical boards: calibrate the rest with "
                        "fixed={'roll_deg': ..., 'z_m': ...}")
    assert main(["extract", str(dataset), "--out", str(tmp_path / "o.json")]) == 0
    plan = next(ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("capture plan:"))
    assert "--fix roll=VALUE,z=VALUE" in plan and "fixed={" not in plan, plan
