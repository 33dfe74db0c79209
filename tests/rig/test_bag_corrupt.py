"""A ROS 2 bag whose sqlite3 file is damaged mid-way (random bytes over a page range): ``lidarcam bag`` ends in one
line naming the bag (exit 2) or a normal run, never a traceback, and leaves no half-written dataset folder."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from lidarcam.cli import main
from simulate import SimOptions
from simulate.recording import RecordingOptions, write_recording_bag

SIM = SimOptions(n_boards=3, cam_width=320, cam_height=240, focal_px=320.0, lidar_res_deg=0.5, noise_mm=10.0,
                 render_supersample=1, dist_min_m=2.0, dist_max_m=3.0)


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    root = tmp_path_factory.mktemp("bag")
    rec = RecordingOptions(fps=10.0, scan_hz=10.0, still_s=0.6, move_s=0.4, eased=False, ros=2, storage="sqlite3",
                           image_format="png")
    write_recording_bag(SIM, 1, root / "rec", rec)
    return root


@pytest.mark.parametrize("seed", range(6))
def test_a_damaged_db3_is_one_line_or_a_run(bag, tmp_path, capsys, seed):
    src = tmp_path / "rec"
    shutil.copytree(bag / "rec", src)
    db3 = next(src.glob("*.db3"))
    b = bytearray(db3.read_bytes())
    rng = np.random.default_rng(seed)
    a, n = int(rng.integers(4096, len(b) - 5000)), int(rng.integers(100, 4000))
    b[a:a + n] = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
    db3.write_bytes(bytes(b))
    out = tmp_path / "ds"
    code = main(["bag", str(src), "--image-topic", "/camera/image_raw", "--scan-topic", "/scan",
                 "--camera-info-topic", "/camera/camera_info", "--board", str(bag / "rec.board.yaml"),
                 "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code in (0, 1, 2)
    if code == 2:
        assert len(err.splitlines()) == 1 and "error:" in err and str(src) in err, err
        assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["rec"]
