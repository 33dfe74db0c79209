"""Copies in the data: a scan that is one point repeated, boards listed twice, and the exhaustive scorer's memory
on 100 boards (``tests/fuzz_corpus.py`` copy cases) through the API and the CLI; the peng2022 scorer in blocks."""

from __future__ import annotations

import subprocess
import sys
import tracemalloc

import numpy as np
import pytest
from fuzz_corpus import base, copy_cases

from calib_core import calibrate, load_observations
from calib_core.data import lines
from calib_core.model import residuals
from calib_core.robust import scorers
from calib_core.solvers.candidates import minimal_candidates
from lidarcam.cli import main
from simulate import SimOptions, generate

METHODS = ("lidarcam", "zhang_pless", "vasconcelos", "peng2022")


@pytest.fixture(scope="module")
def cases():
    return {c.name: c for c in copy_cases(base(6, seed=0), base(3, seed=3), base(4, seed=5))}


def _write(case, tmp_path):
    path = tmp_path / f"{case.name}.json"
    path.write_bytes(case.data)
    return path


def test_a_line_through_one_repeated_point_is_refused_with_its_count():
    P = np.tile([[3.9, -0.2]], (40, 1))
    assert "40 scan points are one point repeated" in lines.line_problem(P)
    assert lines.line_problem(P + np.column_stack([np.zeros(40), np.linspace(0, 1e-4, 40)])) is None  # 0.1 mm: a line


@pytest.mark.parametrize("method", METHODS)
def test_repeated_point_board_is_named_by_every_method_through_the_cli(cases, tmp_path, capsys, method):
    path = _write(cases["scan_one_point_repeated"], tmp_path)
    code = main(["calibrate", str(path), "--method", method])
    out = capsys.readouterr()
    assert code in (0, 1) and "Traceback" not in out.err + out.out
    assert "board 2" in out.out and "one point repeated" in out.out, out.out


@pytest.mark.parametrize("method", METHODS)
def test_boards_listed_twice_are_named_by_the_verdict(cases, tmp_path, capsys, method):
    path = _write(cases["boards_3_each_listed_twice"], tmp_path)
    res = calibrate(load_observations(path), method)
    if res.ok:
        assert "duplicated" in res.info["verdict"]["causes"]
        assert any("boards 0 = 3, boards 1 = 4, boards 2 = 5" in w for w in res.to_dict()["warnings"])
    assert main(["calibrate", str(path), "--method", method]) in (0, 1)
    assert "duplicated boards" in capsys.readouterr().out


def test_distinct_boards_raise_no_copy_warning():
    obs = generate(SimOptions(n_boards=6, noise_mm=20), seed=2, trial=2)
    res = calibrate(obs, "peng2022")
    assert not {"duplicated", "repeated"} & set(res.info["verdict"]["causes"])


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("opts", [{}, {"normalise_candidates": False}, {"beta_norm": "max"},
                                  {"error": "point_plane"}])
def test_peng2022_scorer_in_blocks_scores_as_in_one_pass(monkeypatch, seed, opts):
    obs = generate(SimOptions(n_boards=5, noise_mm=20, lidar_res_deg=0.5), seed=seed, trial=seed)
    C = minimal_candidates(obs).T_lidar_cam
    whole, d1 = scorers.peng2022(obs, C, return_details=True, **opts)
    monkeypatch.setattr(scorers, "PENG_BLOCK_ELEMENTS", 9 * obs.n_boards * 7)   # 7 candidates a block
    monkeypatch.setattr(scorers, "PENG_KEEP_ELEMENTS", 0)                       # recomputed each pass
    blocked, d2 = scorers.peng2022(obs, C, return_details=True, **opts)
    assert int(np.argmin(blocked)) == int(np.argmin(whole))
    np.testing.assert_allclose(blocked, whole, rtol=1e-6)   # the weights 1/beta reach 1e12: rounding grows
    for k in ("O", "U", "beta"):
        np.testing.assert_allclose(d2[k], d1[k], rtol=1e-6)


def test_peng2022_scorer_memory_does_not_grow_with_candidates_times_boards(monkeypatch):
    obs = generate(SimOptions(n_boards=6, noise_mm=20, lidar_res_deg=1.0), seed=4, trial=4)
    C = np.tile(minimal_candidates(obs).T_lidar_cam, (1000, 1, 1))[:30_000]
    M, N = len(C), obs.n_boards
    monkeypatch.setattr(residuals, "CHUNK_ELEMENTS", 100_000)
    monkeypatch.setattr(scorers, "PENG_BLOCK_ELEMENTS", 100_000)
    monkeypatch.setattr(scorers, "PENG_KEEP_ELEMENTS", 0)
    tracemalloc.start()
    cost = scorers.peng2022(obs, C)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert cost.shape == (M,) and np.isfinite(cost).all()
    assert peak < 2 * M * N * 8, f"peak {peak / 2**20:.1f} MiB"   # one pass held (M,N,3,3): 4.5x this bound


@pytest.mark.slow
def test_peng2022_on_100_boards_stays_under_a_4_gib_address_space(tmp_path):
    case = {c.name: c for c in copy_cases(base(6), base(3, seed=3), base(94, seed=5, lidar_res_deg=0.5))}
    path = _write(case["boards_100_six_listed_twice"], tmp_path)
    code = ("import resource, sys; resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30)); "
            "from lidarcam.cli import main; sys.exit(main(sys.argv[1:]))")
    p = subprocess.run([sys.executable, "-c", code, "calibrate", str(path), "--method", "peng2022"],
                       capture_output=True, text=True)
    assert p.returncode == 0 and "Traceback" not in p.stderr, p.stderr[-2000:]
    assert "duplicated boards: boards 0 = 94" in p.stdout
