"""``lidarcam demo OUT`` writes its folder whole or not at all: a second run replaces an earlier demo's folder, a
folder holding anything else (another rig's poses) is refused before any work, Ctrl-C leaves OUT as it was, and a
negative seed is one line. The simulator is stood in for by a writer of the demo's entries (the real demo runs in
tests/test_demo.py)."""

from __future__ import annotations

import pytest

import lidarcam.cli.demo as demo
from lidarcam.cli import main


def _fake_writer(marker: str, interrupt: bool = False):
    def write(out, seed=1):
        (out / "dataset").mkdir()
        (out / "dataset" / "000.csv").write_text(marker)
        (out / "recording").mkdir()
        if interrupt:
            raise KeyboardInterrupt
        (out / "truth.json").write_text(f'{{"seed": {seed}}}')
        return {}
    return write


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "error:" in err and "Traceback" not in err, err
    return err


def test_a_second_demo_into_the_same_folder_replaces_the_first(tmp_path, monkeypatch, capsys):
    out = tmp_path / "demo"
    monkeypatch.setattr(demo, "write_demo", _fake_writer("first"))
    assert main(["demo", str(out)]) == 0
    (out / "dataset_obs.json").write_text("{}")  # the printed commands' outputs belong to the demo too
    monkeypatch.setattr(demo, "write_demo", _fake_writer("second"))
    assert main(["demo", str(out)]) == 0
    assert (out / "dataset" / "000.csv").read_text() == "second" and not (out / "dataset_obs.json").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo"]  # no scratch or old copy left beside it


def test_a_folder_holding_another_rigs_poses_is_refused_untouched(tmp_path, monkeypatch, capsys):
    out = tmp_path / "rig"
    out.mkdir()
    (out / "007.png").write_bytes(b"x")
    (out / "007.csv").write_text("bearing_rad,range_m\n")
    monkeypatch.setattr(demo, "write_demo", _fake_writer("demo"))
    assert main(["demo", str(out)]) == 2
    err = _one_error_line(capsys)
    assert str(out) in err and "007.csv" in err
    assert sorted(p.name for p in out.iterdir()) == ["007.csv", "007.png"]


@pytest.mark.parametrize("earlier", [False, True])
def test_ctrl_c_leaves_out_as_it_was(tmp_path, monkeypatch, capsys, earlier):
    out = tmp_path / "demo"
    if earlier:
        monkeypatch.setattr(demo, "write_demo", _fake_writer("first"))
        assert main(["demo", str(out)]) == 0
    monkeypatch.setattr(demo, "write_demo", _fake_writer("cut", interrupt=True))
    assert main(["demo", str(out)]) == 130
    err = capsys.readouterr().err
    assert ("left as it was" if earlier else "not written") in err
    assert sorted(p.name for p in tmp_path.iterdir()) == (["demo"] if earlier else [])
    if earlier:
        assert (out / "dataset" / "000.csv").read_text() == "first" and (out / "truth.json").exists()


@pytest.mark.parametrize("verb", ["demo", "simulate"])
def test_a_negative_seed_is_one_line(tmp_path, capsys, verb):
    argv = [verb, str(tmp_path / "d")] if verb == "demo" else [verb, "--out", str(tmp_path / "o.json")]
    with pytest.raises(SystemExit) as ex:
        main([*argv, "--seed", "-1"])
    assert ex.value.code == 2
    assert "--seed" in _one_error_line(capsys)
