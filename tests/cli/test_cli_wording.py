"""The CLI speaks its own interface: the library's ``fixed={...}`` hint reaches CLI users as ``--fix``, and
``lidarcam report`` prints each warning once."""

from __future__ import annotations

import re

from rigs import vertical_rig

import calib_core
from calib_core.data.io import save_observations
from lidarcam.cli import main, parse_fix
from simulate import SimOptions, generate


def test_the_undetermined_hint_is_the_fix_option_for_cli_users(tmp_path, capsys):
    obs = vertical_rig(11)  # boards exactly vertical: z's profile is flat, so roll, pitch and z are refused together
    res = calib_core.calibrate(obs)
    assert not res.ok and "fixed={" in res.reason  # the library's users get calibrate()'s keyword
    save_observations(obs, tmp_path / "vert.json")
    assert main(["calibrate", str(tmp_path / "vert.json")]) == 1
    text = capsys.readouterr().out
    assert "fixed={" not in text
    m = re.search(r"--fix (\S+)", text)
    assert m, text
    held = parse_fix(m.group(1).replace("VALUE", "0"))  # the suggested option parses as written
    assert set(held) == set(re.findall(r"'([a-z_]+)': \.\.\.", res.reason))


def test_report_prints_each_warning_once(tmp_path, capsys):
    obs = generate(SimOptions(n_boards=6, max_tilt_deg=8.0), seed=0)  # normals nearly in one plane
    res = calib_core.calibrate(obs)
    assert res.ok and res.warnings
    save_observations(obs, tmp_path / "obs.json")
    res.save(tmp_path / "r.json")
    assert main(["report", str(tmp_path / "obs.json"), str(tmp_path / "r.json"), "--out", str(tmp_path / "rep")]) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("warning: ")]
    assert lines and len(lines) == len(set(lines)), lines
    for w in res.warnings:
        assert lines.count(f"warning: {w}") == 1
    md = (tmp_path / "rep" / "report.md").read_text()
    for w in res.warnings:
        assert md.count(f"- {w}") == 1
