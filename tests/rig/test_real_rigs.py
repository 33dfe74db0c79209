"""docs/real-rigs.md's commands, run as written on the five shared data sets (skipped, one line each, where
``../shared/real-data`` or ``$REAL_DATA`` lacks the set), and the boards they give against ``make real-data``'s
(``lidarcam.rig.public_sets``)."""

from __future__ import annotations

import json
import os
import re
import shlex
from pathlib import Path

import numpy as np
import pytest

from calib_core import calibrate
from calib_core.data.io import load_observations
from lidarcam.cli import main as cli

ROOT = Path(__file__).resolve().parents[2]
REAL = Path(os.environ.get("REAL_DATA", ROOT.parent / "shared" / "real-data"))
DOC = ROOT / "docs" / "real-rigs.md"
DOC_DATA = "../shared/real-data"
"""The data root the documented commands name (a clone beside ``shared/``); the test reads ``REAL`` instead."""


def doc_blocks() -> dict[str, list[str]]:
    """Data-set name -> the command lines of its ``# real-rig: NAME`` block in docs/real-rigs.md."""
    out = {}
    for block in re.findall(r"```bash\n(.*?)```", DOC.read_text(), flags=re.S):
        lines = [ln.strip() for ln in block.splitlines() if ln.strip()]
        if lines and lines[0].startswith("# real-rig: "):
            out[lines[0].removeprefix("# real-rig: ")] = lines[1:]
    return out


BLOCKS = doc_blocks()


def run_block(lines: list[str], cwd: Path, monkeypatch) -> dict[str, int]:
    """Run a block's lines in ``cwd``: ``VAR=value`` assignments, then ``lidarcam ...`` commands in-process (the
    same argv as the shell gives). Returns verb -> exit code."""
    monkeypatch.chdir(cwd)
    env, codes = {}, {}
    for line in lines:
        m = re.fullmatch(r"([A-Z_]+)=(\S+)", line)
        if m:
            env[m.group(1)] = m.group(2).replace(DOC_DATA, str(REAL), 1)
            continue
        argv = shlex.split(re.sub(r"\$([A-Z_]+)", lambda v: env[v.group(1)], line))
        assert argv[0] == "lidarcam", line
        codes[argv[1]] = cli(argv[1:])
    return codes


def test_every_shared_set_has_a_block():
    assert set(BLOCKS) == {"rplidar-a1-tx2-edenshin", "hokuyo-usbcam-kazmierczak", "hokuyo-utm30lx-lifecam-nowicki",
                           "turtlebot3-acfr-wall-examples", "rplidar-realsense-d415-yongkgu"}
    for name, lines in BLOCKS.items():
        verbs = [ln.split()[1] for ln in lines if ln.startswith("lidarcam ")]
        assert verbs[0] == "import" and verbs[-2:] == ["calibrate", "report"], name


def _rows_sorted(a: np.ndarray) -> np.ndarray:
    r = np.round(a, 6)
    return a[np.lexsort(r.T[::-1])]


def _public(name: str):
    """The observations ``make real-data`` calibrates for data set ``name``."""
    from lidarcam.rig import public_sets as ps
    from lidarcam.rig.extract import extract
    from lidarcam.rig.intrinsics import refit_camera

    load = {ps.EDENSHIN: ps.load_edenshin, ps.KAZMIERCZAK: ps.load_kazmierczak, ps.NOWICKI: ps.load_nowicki,
            ps.ACFR: ps.load_acfr, ps.YONGKGU: ps.load_yongkgu}[name]
    rs = load(REAL / name)
    if rs.observations is not None:
        return rs.observations
    ds = refit_camera(rs.dataset)[0] if rs.refit_intrinsics else rs.dataset
    return extract(ds, rs.options)[0]


HEAVY = ("hokuyo-usbcam-kazmierczak", "hokuyo-utm30lx-lifecam-nowicki")
"""Sets whose blocks detect boards in 14-31 images and refit a camera (about a minute each): ``make test-slow``."""


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in HEAVY else n for n in sorted(BLOCKS)])
def test_documented_commands_calibrate_and_report_with_make_real_data_boards(name, tmp_path, monkeypatch):
    if not (REAL / name).is_dir():
        pytest.skip(f"{REAL / name} not present (the data sets are not part of the project)")
    codes = run_block(BLOCKS[name], tmp_path, monkeypatch)
    assert set(codes.values()) == {0}, codes
    short = name.split("-")[-1] if "acfr" not in name else "acfr"
    obs = load_observations(tmp_path / "work" / f"{short}.json")
    ref = _public(name)
    assert obs.n_boards == ref.n_boards
    assert obs.meta.get("poses") == ref.meta.get("poses")
    for a, b in zip(obs.boards, ref.boards, strict=True):
        assert a.outline_kind == b.outline_kind == "lower_bound"
        np.testing.assert_allclose(_rows_sorted(a.scan), _rows_sorted(b.scan), atol=1e-6)  # merged poses interleave
        # the same detection up to the sector detector's run-to-run variation (it may fall back to the classic one)
        np.testing.assert_allclose(a.T_cam_board, b.T_cam_board, atol=0.01)
    res = json.loads((tmp_path / "work" / f"{short}-result.json").read_text())
    assert res["ok"], res["reason"]
    assert (tmp_path / "work" / f"{short}-report" / "report.md").is_file()
    if name == "turtlebot3-acfr-wall-examples":       # the planar calibration: yaw, x, y with their 1-sigma
        assert sorted(res["mounting_sigma"]) == ["x_m", "y_m", "yaw_deg"]
        assert all(0 < v < 1 for v in res["mounting_sigma"].values())
    if name == "rplidar-a1-tx2-edenshin":              # corners and camera from the Bouguet file: the joint model
        # Bouguet's fc/cc/kc errors (three sigma) give the intrinsics' 1-sigma: the joint model holds their error
        assert obs.has_corners and res["covariance_model"] == "joint, intrinsics uncertain"
        assert obs.camera.std_intrinsics is not None and len(obs.camera.std_intrinsics) == 9
        # every point is hand-segmented on its board: at most 3% may be read as outliers
        left = calibrate(obs).info["points_trimmed"]
        assert left["total"] + left["in_fit"] <= 0.03 * sum(len(b.scan) for b in obs.boards)
    if name == "hokuyo-utm30lx-lifecam-nowicki":      # every pose used, each segment the width of the plate
        assert obs.n_boards == 14
        widths = [np.linalg.norm(b.scan[-1] - b.scan[0]) for b in obs.boards]
        assert min(widths) > 0.95 and max(widths) < 1.25
