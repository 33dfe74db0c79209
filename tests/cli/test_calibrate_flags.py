"""``lidarcam calibrate``'s mounting flags read through one parser (``calib_core.geometry.mounting.parse_text``):
units, ``height``, ranges; ``--out`` never the input; ``--std-intrinsics`` on a file stating its own says which
it used; a 1-sigma of 1e-300 in a file holds that intrinsic exact instead of overflowing."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calib_core import CalibrationError, calibrate, load_observations, observations_to_dict
from calib_core.geometry.mounting import MountingPrior, parse_text
from lidarcam.cli import main
from simulate import SimOptions, generate


@pytest.fixture(scope="module")
def obs_file(tmp_path_factory):
    obs = generate(SimOptions(n_boards=5, pose_mode="pixel"), seed=2, trial=0)
    path = tmp_path_factory.mktemp("cal") / "obs.json"
    path.write_text(json.dumps(observations_to_dict(obs)))
    return path


@pytest.mark.parametrize("text,expect", [
    ("z=11cm", {"z_m": 0.11}), ("height=110mm", {"z_m": 0.11}), ("z_m=0.11", {"z_m": 0.11}),
    ("roll=0.01rad,pitch=-3", {"roll_deg": np.degrees(0.01), "pitch_deg": -3.0}),
    ("yaw=-180,x=1m", {"yaw_deg": -180.0, "x_m": 1.0})])
def test_fix_text_reads_units_and_height(text, expect):
    got = parse_text(text)
    assert set(got) == set(expect) and all(got[k] == pytest.approx(v, rel=1e-12) for k, v in expect.items())


@pytest.mark.parametrize("text,names", [("roll=400", "roll"), ("pitch=91", "pitch"), ("z=11deg", "z"),
                                        ("roll=3cm", "roll"), ("z=1,z=2", "z"), ("depth=1", "depth"),
                                        ("x=inf", "x")])
def test_fix_text_refuses_with_the_item_named(text, names):
    with pytest.raises(CalibrationError, match=names):
        parse_text(text)


def test_the_library_refuses_an_out_of_range_fixed_value(obs_file):
    with pytest.raises(CalibrationError, match="roll_deg"):
        calibrate(load_observations(obs_file), fixed={"roll_deg": 400.0})
    with pytest.raises(CalibrationError, match="sigma_rot_rad"):
        MountingPrior(np.eye(4), 1e-300, 0.05)


def test_fix_in_centimetres_is_fix_in_metres(obs_file, tmp_path, capsys):
    for name, text in (("a", "z=11cm,roll=0.3"), ("b", "height=0.11,roll=0.3deg")):
        assert main(["calibrate", str(obs_file), "--fix", text, "--out", str(tmp_path / f"{name}.json")]) in (0, 1)
    a, b = (json.loads((tmp_path / f"{n}.json").read_text()) for n in "ab")
    assert a["fixed"] == pytest.approx({"z_m": 0.11, "roll_deg": 0.3}) and a["fixed"] == pytest.approx(b["fixed"])
    assert np.allclose(a["T_lidar_cam"], b["T_lidar_cam"], atol=1e-9)


def test_out_is_never_the_input(obs_file, tmp_path, capsys):
    before = obs_file.read_bytes()
    assert main(["calibrate", str(obs_file), "--out", str(obs_file)]) == 2
    assert main(["calibrate", str(obs_file), "--yaml", str(obs_file)]) == 2
    assert obs_file.read_bytes() == before
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("is the input file" in ln for ln in err)


def test_std_intrinsics_on_a_file_that_states_its_own_says_which(obs_file, tmp_path, capsys):
    d = json.loads(obs_file.read_text())
    d["camera"]["std_intrinsics"] = [1.5, 1.5, 2.0, 2.0]
    stated = tmp_path / "stated.json"
    stated.write_text(json.dumps(d))
    main(["calibrate", str(stated), "--std-intrinsics", "0.3%,2px"])
    lines = [ln for ln in capsys.readouterr().out.splitlines() if "not the file" in ln]
    assert len(lines) == 1 and "--std-intrinsics 0.3%,2px used" in lines[0] and "fx 1.5" in lines[0], lines
    main(["calibrate", str(obs_file), "--std-intrinsics", "0.3%,2px"])  # a file stating none: nothing to say
    assert "not the file's" not in capsys.readouterr().out


def test_a_file_sigma_of_1e_300_holds_the_intrinsics_exact(obs_file, tmp_path):
    d = json.loads(obs_file.read_text())
    d["camera"]["std_intrinsics"] = [1e-300] * 4
    tiny = tmp_path / "tiny.json"
    tiny.write_text(json.dumps(d))
    res, exact = calibrate(load_observations(tiny)), calibrate(load_observations(obs_file))
    assert res.ok == exact.ok and np.allclose(res.T_lidar_cam, exact.T_lidar_cam, atol=1e-9)


@pytest.mark.parametrize("pose,sigma", [("x=1000,y=-1000,z=1000,roll=180,pitch=90,yaw=-180", "1000000mm,180deg"),
                                        ("x=0,y=0,z=0.1,roll=0,pitch=-3,yaw=0", "0.001mm,0.0000573deg"),
                                        ("x=0,y=0,z=0.1,roll=0,pitch=90,yaw=0", "0.001mm,180deg")])
def test_extreme_priors_give_no_warning_and_no_nan(obs_file, tmp_path, capsys, pose, sigma):
    import warnings

    out = tmp_path / "r.json"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        code = main(["calibrate", str(obs_file), "--prior", pose, "--prior-sigma", sigma, "--out", str(out)])
    assert code in (0, 1)
    text = out.read_text()
    assert "NaN" not in text and "Infinity" not in text
    assert "nan" not in capsys.readouterr().out.lower().replace("nanoseconds", "")


@pytest.mark.parametrize("flag,value,says", [("--prior-sigma", "-50mm,10deg", "translation 1-sigma -50 mm"),
                                             ("--std-intrinsics", "-1,1,1,1", "negative standard deviation"),
                                             ("--fix", "-3", "bad item '-3'")])
def test_a_value_starting_with_a_minus_reaches_its_own_check(obs_file, capsys, flag, value, says):
    extra = ["--prior", "x=0,y=0,z=0.1,roll=0,pitch=-3,yaw=0"] if flag == "--prior-sigma" else []
    assert main(["calibrate", str(obs_file), *extra, flag, value]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and says in err, err
