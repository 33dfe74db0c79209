"""The report helpers: one markdown table builder, number cells, and a result's summary lines."""

from __future__ import annotations

import math

import numpy as np
import pytest

from calib_core import calibrate
from calib_core.data.result import CalibrationResult
from lidarcam.rig.markdown import md_table, num, pct
from simulate import SimOptions, generate


def test_md_table_aligns_and_refuses_a_shifted_row():
    lines = md_table(["a", "b", "c"], [[1, "x", 2.5], ["", "y", "-"]], "lrr")
    assert lines == ["| a | b | c |", "|---|---:|---:|", "| 1 | x | 2.5 |", "|  | y | - |"]
    assert md_table(["a"], [])[1] == "|---|"
    with pytest.raises(ValueError, match="2 cells"):
        md_table(["a", "b", "c"], [[1, 2]])
    with pytest.raises(ValueError, match="align"):
        md_table(["a", "b"], [], "lc")


def test_number_cells_never_print_nan():
    assert num(math.nan) == "-" and num(None, missing="n/a") == "n/a" and num(np.inf) == "-"
    assert num(np.float64(1.234), ".1f") == "1.2" and num(3, "+.0f") == "+3" and num(0.256, ".0%") == "26%"
    assert pct(0.256) == "26%" and pct(0.256, 1, sign="") == "25.6" and pct(math.nan) == "-"


def test_summary_lines_state_the_failure_or_the_result():
    failed = CalibrationResult("peng2022", False, reason="needs at least 3 boards")
    assert failed.summary_lines(2) == ["peng2022: failed: needs at least 3 boards"]
    obs = generate(SimOptions(n_boards=6, noise_mm=0.0), seed=3)
    res = calibrate(obs, "lidarcam")
    lines = res.summary_lines(obs.n_boards, obs.T_lidar_cam_true)
    assert lines[0].startswith("lidarcam: ok,") and lines[1].startswith("T_lidar_cam")
    rows = np.array([[float(v) for v in line.split()] for line in lines[2:6]])
    np.testing.assert_allclose(rows, res.T_lidar_cam, atol=1e-6)  # the matrix printed is the result's
    assert any(line.startswith(f"boards used ({len(res.boards_used)} of 6)") for line in lines)
    e_R = float(lines[-1].split("e_R = ")[1].split(" deg")[0])
    assert lines[-1].startswith("against ground truth") and e_R < 1e-3
