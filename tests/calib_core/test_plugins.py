"""Methods from outside the package: plugin modules, the ``lidarcam.methods`` entry points, errors of one line,
and a plugin method running in the sweep's worker processes."""

import importlib
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from joblib.externals.loky import get_reusable_executor

import calib_core.plugins as plugins
from calib_core import calibrate
from calib_core.plugins import PluginError, load_entry_point, load_module, load_plugins
from calib_core.registry import METHODS
from experiments.engine.cell import Cell
from experiments.engine.runner import run_cells
from lidarcam.cli import main
from simulate import SimOptions, generate

PLUGIN = '''
from calib_core.registry import Method, get_method, register


def {fn}(obs, **options):
    return get_method("peng2022").func(obs, **options)


register(Method("{name}", {fn}, 3, "a test lab", "peng2022 under another name", cost="O(N^3)"))
'''


def _write(folder, module, text):
    path = folder.joinpath(*module.split(".")).with_suffix(".py")
    path.parent.mkdir(parents=True, exist_ok=True)
    for parent in path.relative_to(folder).parents:
        if str(parent) != ".":
            (folder / parent / "__init__.py").touch()
    path.write_text(textwrap.dedent(text))
    importlib.invalidate_caches()


def test_a_module_registers_its_method_with_the_module_as_origin(plugin_dir):
    _write(plugin_dir, "lab_a.mine", PLUGIN.format(fn="mine", name="lab_a_mine"))
    assert load_module("lab_a.mine") == ("lab_a_mine",)
    assert METHODS["lab_a_mine"].origin == "lab_a.mine"
    assert load_module("lab_a.mine") == ("lab_a_mine",)  # idempotent: nothing registered twice
    obs = generate(SimOptions(n_boards=5, noise_mm=5), seed=0, trial=0)
    assert calibrate(obs, "lab_a_mine").ok
    assert calibrate(obs, "lab_a_mine+ml").ok  # the suffixes apply to plugin methods too


def test_cli_lists_plugin_methods_with_origin_and_cost(plugin_dir, capsys):
    _write(plugin_dir, "lab_b", PLUGIN.format(fn="mine", name="lab_b_mine"))
    assert main(["--plugin", "lab_b", "methods"]) == 0
    lines = capsys.readouterr().out.splitlines()
    i = next(i for i, ln in enumerate(lines) if ln.startswith("lab_b_mine"))
    assert "from lab_b: a test lab" in lines[i] and "cost: O(N^3)" in "\n".join(lines[i:i + 3])
    assert any(ln.startswith("peng2022 ") and "from lidarcam" in ln for ln in lines)


def test_a_plugin_that_fails_to_import_is_one_line_naming_it(plugin_dir, capsys):
    _write(plugin_dir, "lab_c", "import not_a_module_anywhere\n")
    with pytest.raises(PluginError, match=r"^plugin lab_c: cannot load \(ModuleNotFoundError"):
        load_module("lab_c")
    assert main(["--plugin", "lab_c", "methods"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "plugin lab_c" in err and "not_a_module_anywhere" in err


def test_a_plugin_that_takes_a_registered_name_is_an_error_and_leaves_nothing(plugin_dir):
    _write(plugin_dir, "lab_d", PLUGIN.format(fn="first", name="lab_d_first")
           + PLUGIN.format(fn="mine", name="peng2022"))
    with pytest.raises(PluginError, match=r"^plugin lab_d: method 'peng2022' is already registered \(from lidarcam\)"):
        load_module("lab_d")
    assert "lab_d_first" not in METHODS and METHODS["peng2022"].origin == "lidarcam"


def _dist(folder, name, entry_points):
    d = folder / f"{name}-0.1.dist-info"
    d.mkdir()
    (d / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n")
    (d / "entry_points.txt").write_text("[lidarcam.methods]\n" + entry_points)
    importlib.invalidate_caches()


def test_entry_points_name_a_callable_or_a_module(plugin_dir, monkeypatch):
    _write(plugin_dir, "lab_e", '''
        from calib_core.registry import Method, get_method

        def methods():
            base = get_method("vasconcelos")
            return [Method("lab_e_one", base.func, 3, "lab e", "vasconcelos again"),
                    Method("lab_e_two", base.func, 3, "lab e", "and again", origin="lab e, v2")]
        ''')
    _write(plugin_dir, "lab_f", PLUGIN.format(fn="mine", name="lab_f_mine"))
    _dist(plugin_dir, "lab-e", "one = lab_e:methods\nfour = lab_f\n")
    eps = {ep.name: ep for ep in plugins.entry_points()}
    assert {"one", "four"} <= set(eps)
    monkeypatch.setattr(plugins, "_INSTALLED_LOADED", False)
    new = load_plugins()
    assert {"lab_e_one", "lab_e_two", "lab_f_mine"} <= set(new)
    assert METHODS["lab_e_one"].origin == "lab_e" and METHODS["lab_e_two"].origin == "lab e, v2"
    assert METHODS["lab_f_mine"].origin == "lab_f"


def test_an_entry_point_returning_something_else_is_an_error(plugin_dir):
    _write(plugin_dir, "lab_g", "def methods():\n    return 42\n")
    _dist(plugin_dir, "lab-g", "bad = lab_g:methods\n")
    ep = next(ep for ep in plugins.entry_points() if ep.name == "bad")
    with pytest.raises(PluginError, match=r"^plugin lab_g:methods: returned int"):
        load_entry_point(ep)


def test_plugin_method_runs_in_the_sweep_worker_processes(plugin_dir, tmp_path):
    _write(plugin_dir, "lab_h", PLUGIN.format(fn="mine", name="lab_h_mine"))
    load_module("lab_h")
    sim = {"n_boards": 5, "noise_mm": 10.0}
    cell = Cell(sweep="plug", sim=sim, n_trials=4, methods=("peng2022", "lab_h_mine"),
                results_dir=str(tmp_path / "res"), plugins=("lab_h",))
    df = run_cells([cell], n_jobs=2, chunk_size=1, progress=False)
    get_reusable_executor().shutdown(wait=True)  # workers gone before interpreter exit (no loky atexit noise)
    assert len(df) == 8 and df["ok"].all()
    a = df[df["method"] == "peng2022"]["e_R_deg"].to_numpy()
    b = df[df["method"] == "lab_h_mine"]["e_R_deg"].to_numpy()
    assert (a == b).all()  # the same method under two names, on the same data


def test_a_sweep_with_a_broken_plugin_stops_with_one_line(tmp_path):
    root = Path(__file__).resolve().parents[2]
    (tmp_path / "lab_i.py").write_text("raise RuntimeError('half-written')\n")
    env = {**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{root}"}
    r = subprocess.run([sys.executable, "-m", "experiments.run", "methods.plugins=[lab_i]", "n_trials=1",
                        f"results_dir={tmp_path / 'res'}"], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.strip() == "experiments.run: error: plugin lab_i: cannot load (RuntimeError: half-written)"
