"""Rows keyed on the code that computed them: an edited plugin's rows are recomputed and the others reused (in
one process, across a worker pool started before the plugin existed), stores without fingerprints are stale,
reports state their fingerprint and are found stale when the code moves on."""

from __future__ import annotations

import importlib

import pandas as pd
from joblib.externals.loky import get_reusable_executor

from calib_core.plugins import load_module
from experiments.engine import fingerprint
from experiments.engine.cell import CODE_COLUMN, Cell
from experiments.engine.runner import run_cells

PLUGIN = '''
from calib_core.registry import Method, get_method, register

SHIFT_M = {shift}


def shifted(obs, **options):
    T, cands, info = get_method("peng2022").func(obs, **options)
    T = T.copy()
    T[0, 3] += SHIFT_M
    return T, cands, info


register(Method("lab_fp_shifted", shifted, 3, "a test lab", "peng2022 moved along x"))
'''
SIM = {"n_boards": 5, "noise_mm": 10.0}


def _write_plugin(folder, shift):
    (folder / "lab_fp.py").write_text(PLUGIN.format(shift=shift))
    importlib.invalidate_caches()


def _rows(df, method):
    return df[df["method"] == method].reset_index(drop=True)


def test_an_edited_plugin_is_recomputed_and_the_other_rows_reused(plugin_dir, tmp_path, capsys):
    res = str(tmp_path / "res")
    # a first sweep starts the worker pool before the plugin exists (a worker must not depend on it)
    run_cells([Cell("warm", SIM, n_trials=2, methods=("peng2022",), results_dir=res)], n_jobs=2,
              chunk_size=1, progress=False)
    _write_plugin(plugin_dir, "0.0")
    load_module("lab_fp")
    cell = Cell("edit", SIM, n_trials=4, methods=("peng2022", "lab_fp_shifted"), results_dir=res,
                plugins=("lab_fp",))
    try:
        first = run_cells([cell], n_jobs=2, chunk_size=1, progress=False)
        assert first["ok"].all() and (first.groupby("trial")["e_t_m"].nunique() == 1).all()  # shift 0: the same
        capsys.readouterr()
        _write_plugin(plugin_dir, "0.05")      # edit the method: its answer moves by 5 cm
        again = run_cells([cell], n_jobs=2, chunk_size=1, progress=False)
    finally:
        get_reusable_executor().shutdown(wait=True)
    err = capsys.readouterr().err
    assert "edit: 4 rows reused, 4 recomputed (code changed: lab_fp for lab_fp_shifted)" in err, err
    pd.testing.assert_frame_equal(_rows(again, "peng2022"), _rows(first, "peng2022"))  # seconds too
    old, new = _rows(first, "lab_fp_shifted"), _rows(again, "lab_fp_shifted")
    assert (old[CODE_COLUMN] != new[CODE_COLUMN]).all()
    assert not (old["e_t_m"].fillna(-1) == new["e_t_m"].fillna(-1)).any()
    stored = pd.concat([pd.read_csv(f) for f in cell.dir.glob("chunk-*.csv")])
    assert len(stored) == 8 and set(stored[CODE_COLUMN]) == set(again[CODE_COLUMN])   # never mixed


def test_a_store_without_fingerprints_is_recomputed(tmp_path, capsys):
    cell = Cell("old", SIM, n_trials=3, methods=("zhang_pless_linear",), results_dir=str(tmp_path))
    run_cells([cell], n_jobs=1, progress=False)
    for f in cell.dir.glob("chunk-*.csv"):
        pd.read_csv(f).drop(columns=CODE_COLUMN).to_csv(f, index=False)
    capsys.readouterr()
    df = run_cells([cell], n_jobs=1, progress=False)
    err = capsys.readouterr().err
    assert "0 rows reused, 3 recomputed (code changed: no fingerprint for zhang_pless_linear)" in err
    assert len(df) == 3 and df[CODE_COLUMN].str.startswith("calib_core:").all()


def test_a_calib_core_change_recomputes_every_method(tmp_path, capsys, monkeypatch):
    cell = Cell("core", SIM, n_trials=2, methods=("zhang_pless_linear", "vasconcelos"), results_dir=str(tmp_path))
    run_cells([cell], n_jobs=1, progress=False)
    real = fingerprint.package_hash
    monkeypatch.setattr(fingerprint, "package_hash", lambda p: "0123456789" if p == "calib_core" else real(p))
    capsys.readouterr()
    run_cells([cell], n_jobs=1, progress=False)
    err = capsys.readouterr().err
    assert "0 rows reused, 4 recomputed (code changed: calib_core for vasconcelos, zhang_pless_linear)" in err
    capsys.readouterr()
    run_cells([cell], n_jobs=1, progress=False)
    assert "4 rows reused, 0 recomputed" in capsys.readouterr().err


def test_reports_state_their_fingerprint_not_the_commit_and_are_found_stale(tmp_path, monkeypatch):
    path = fingerprint.write_stamped(tmp_path / "REPORT.md", "# A report\n")
    line = path.read_text().splitlines()[-1]
    assert line.startswith(fingerprint.REPORT_MARK) and f"calib_core {fingerprint.package_hash('calib_core')}" in line
    assert "commit" not in line and fingerprint.report_staleness(path) is None  # the same code, the same line
    real = fingerprint.package_hash
    monkeypatch.setattr(fingerprint, "package_hash", lambda p: "0123456789" if p == "simulate" else real(p))
    assert fingerprint.report_staleness(path) == "code changed since it was written: simulate"
    (tmp_path / "OLD.md").write_text("# An old report\n")
    assert "no code fingerprint" in fingerprint.report_staleness(tmp_path / "OLD.md")
