"""Hostile values the observation files' corpus had not reached: a board pose or a scan point at 1e300 metres is
one line naming the file, board and field (never ``Eigenvalues did not converge``); a board plane through the
camera centre is a degenerate triple for every minimal solver, never a ``LinAlgError``."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fuzz_corpus import base, dump

from calib_core import calibrate, load_observations
from calib_core.errors import ObservationError
from calib_core.registry import METHODS


def _write(tmp_path, edit) -> object:
    d = json.loads(json.dumps(base(6, seed=1)))
    edit(d)
    path = tmp_path / "obs.json"
    path.write_bytes(dump(d))
    return path


@pytest.mark.parametrize("where,field", [("pose", "T_cam_board"), ("scan", "scan")])
def test_garbage_distances_are_one_line_naming_board_and_field(tmp_path, where, field):
    def edit(d):
        if where == "pose":
            d["boards"][1]["T_cam_board"][0][3] = 1e300
        else:
            d["boards"][1]["scan"][0] = [1e300, 1e300]

    with pytest.raises(ObservationError) as err:
        load_observations(_write(tmp_path, edit))
    msg = str(err.value)
    assert "\n" not in msg and "board 1" in msg and f"'{field}'" in msg and "obs.json" in msg


def test_a_plane_through_the_camera_centre_never_crashes_a_method(tmp_path):
    def edit(d):
        d["boards"][0]["T_cam_board"] = np.eye(4).tolist()

    obs = load_observations(_write(tmp_path, edit))
    for name in METHODS:
        r = calibrate(obs, name)   # ok or not, never an exception
        assert r.ok or r.reason
