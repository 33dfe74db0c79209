"""Hostile inputs for the command line's verbs (``import``, ``plan``, ``bag``, ``calibrate``'s priors and
intrinsics' sigmas, ``demo``, ``simulate``): each a ``CliCase`` whose argv may name files of a small source tree
that ``make_sources`` writes (a RADLOCC log with its images, a camera file, an observation file with corners, a
rig description, a board file, a ROS 2 bag).

Every case must end in exit 2 with one line ``lidarcam VERB: error: ...`` naming ``names`` (a file, flag or field),
never a traceback, a hang or a RuntimeWarning on stderr. ``tests/cli/test_cli_fuzz.py`` runs them."""

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


def _laser_line(head: str = LASER_HEAD) -> str:
    return head + " " + " ".join(["2.5"] * 181)


def make_sources(root: Path) -> Path:
    """A small source tree under ``root``: ``laser.txt`` (3 lines) + ``img/RGB{1,2,3}.png``, ``camera.yaml``,
    ``obs.json`` (simulated, with corners and camera), ``rig.yaml`` (a copy of the plan template), ``board.yaml``."""
    import cv2

    from calib_core import observations_to_dict
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
    (root / "board.yaml").write_text("cols: 7\nrows: 6\nsquare_m: 0.1\n")
    return root


def _radlocc(*extra: str) -> tuple[str, ...]:
    return ("import", "radlocc", "{S}/laser.txt", "--images", "{S}/img", "--camera", "{S}/camera.yaml",
            "--board-grid", "7x6", "--square", "0.1", "--out", "{S}/ds", *extra)


def _write(name: str, data: bytes | str):
    def prep(root: Path) -> None:
        p = root / name
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data.encode() if isinstance(data, str) else data)
    return prep


PREPARE = {
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
}
