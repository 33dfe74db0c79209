"""``lidarcam import`` into a dataset folder: a re-import replaces the earlier import whole (fewer ``--lines``
leave no old pose for ``extract``), a folder holding other files is refused untouched, a source inside ``--out``
is refused, and a unit mistake (``--unit m`` on millimetre ranges, ``--square 100``) is one line naming the likely
unit."""

from __future__ import annotations

import pytest
from cli_fuzz_corpus import make_sources

from lidarcam.cli import main


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    return make_sources(tmp_path_factory.mktemp("src"))


def _radlocc(src, out, *extra):
    return ["import", "radlocc", str(src / "laser.txt"), "--images", str(src / "img"), "--camera",
            str(src / "camera.yaml"), "--board-grid", "7x6", "--square", "0.1", "--out", str(out), *extra]


def _poses(folder):
    return sorted(p.stem for p in folder.glob("*.csv"))


def _one_error(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "error:" in err, err
    return err


def test_a_reimport_with_fewer_lines_keeps_no_old_pose(sources, tmp_path, capsys):
    out = tmp_path / "ds"
    assert main(_radlocc(sources, out)) == 0
    assert _poses(out) == ["1", "2", "3"]
    assert main(_radlocc(sources, out, "--lines", "2-3")) == 0
    assert _poses(out) == ["2", "3"] and sorted(p.stem for p in out.glob("*.png")) == ["2", "3"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]


def test_a_folder_holding_other_files_is_refused_untouched(sources, tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert main(_radlocc(sources, out)) == 2
    assert "notes.txt" in _one_error(capsys) and [p.name for p in out.iterdir()] == ["notes.txt"]


def test_a_source_inside_out_is_refused(sources, tmp_path, capsys):
    assert main(_radlocc(sources, sources)) == 2
    assert "--out" in _one_error(capsys)


@pytest.mark.parametrize("unit,values,expect", [("m", [2500.0] * 50, "--unit mm"), ("mm", [2.5] * 50, "--unit m"),
                                                ("mm", [2500.0] * 50, None)])
def test_range_units_are_checked(sources, tmp_path, capsys, unit, values, expect):
    import shutil

    scans = tmp_path / "scans"
    scans.mkdir()
    images = tmp_path / "images"
    shutil.copytree(sources / "img", images)
    for k in range(3):
        (scans / f"{k:03d}.log").write_text("\n".join(str(v) for v in values) + "\n")
    code = main(["import", "ranges", str(scans), "--images", str(images), "--start-deg", "-45", "--step-deg", "1",
                 "--unit", unit, "--camera", str(sources / "camera.yaml"), "--board-grid", "7x6", "--square", "0.1",
                 "--out", str(tmp_path / "ds")])
    if expect is None:
        assert code == 0
        return
    assert code == 2
    err = _one_error(capsys)
    assert f"--unit {unit}" in err and expect in err, err


def test_a_square_in_millimetres_is_named(sources, tmp_path, capsys):
    argv = _radlocc(sources, tmp_path / "ds")
    argv[argv.index("--square") + 1] = "100"
    assert main(argv) == 2
    err = _one_error(capsys)
    assert "--square" in err and "100 mm would be 0.1 m" in err, err
