"""The layer rule: ``calib_core`` is numpy + scipy only and imports nothing above it; no import cycles."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("calib_core", "rig", "simulate", "lidarcam_cli", "experiments")
ABOVE = {"calib_core": {"rig", "simulate", "lidarcam_cli", "experiments"},
         "simulate": {"rig", "lidarcam_cli", "experiments"},
         "rig": {"simulate", "lidarcam_cli", "experiments"},
         "lidarcam_cli": {"experiments"},
         "experiments": {"lidarcam_cli"}}
HEAVY = ("hydra", "omegaconf", "cv2", "yaml", "matplotlib", "PIL", "pandas", "joblib", "rosbags")


def _modules(pkg: str) -> dict[str, Path]:
    out = {}
    for path in sorted((ROOT / pkg).rglob("*.py")):
        rel = path.relative_to(ROOT).with_suffix("")
        parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
        out[".".join(parts)] = path
    return out


def _imports(name: str, path: Path) -> set[str]:
    """Absolute module names imported anywhere in the file (top level, functions, __import__/import_module)."""
    is_pkg = path.name == "__init__.py"
    here = name.split(".") if is_pkg else name.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[: len(here) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            found.add(mod)
            found.update(f"{mod}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", "")) in (
                "__import__", "import_module") and node.args and isinstance(node.args[0], ast.Constant):
            found.add(str(node.args[0].value))
    return found


ALL = {n: p for pkg in PACKAGES for n, p in _modules(pkg).items()}


@pytest.mark.parametrize("pkg", PACKAGES)
def test_no_import_up_the_layers(pkg):
    bad = [(n, m) for n, p in _modules(pkg).items() for m in _imports(n, p) if m.split(".")[0] in ABOVE[pkg]]
    assert not bad, f"{pkg} imports a layer above it: {bad}"


def test_no_import_cycle():
    graph = {n: {m for m in _imports(n, p) if m in ALL and m != n} for n, p in ALL.items()}
    # a package's __init__ importing its own submodules is not a cycle of modules
    for n in graph:
        graph[n] = {m for m in graph[n] if not (n in ALL and ALL[n].name == "__init__.py" and m.startswith(n + "."))}
    state: dict[str, int] = {}

    def visit(n, stack):
        state[n] = 1
        for m in graph[n]:
            if state.get(m) == 1:
                pytest.fail("import cycle: " + " -> ".join(stack[stack.index(m):] + [m]))
            if m not in state:
                visit(m, stack + [m])
        state[n] = 2

    for n in graph:
        if n not in state:
            visit(n, [n])


def test_library_loads_no_io_or_plotting_stack():
    code = ("import sys, importlib, pkgutil, calib_core\n"
            "for m in pkgutil.walk_packages(calib_core.__path__, 'calib_core.'): importlib.import_module(m.name)\n"
            f"print(' '.join(k for k in {HEAVY!r} if k in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "", f"importing calib_core loads: {out.stdout.strip()}"


CORE_FLOORS = (("errors",), ("geometry",), ("data",), ("solvers",), ("refine",), ("robust",), ("checks", "held_out"),
               ("planning",), ("registry",), ("methods",), ("entry", "plugins"), ("crossval",), ("__init__",))
"""The stages of ``calib_core`` in import order, lowest first: a module imports only from its own stage or from a
lower floor (the flow: data -> scan lines -> candidates -> refinement and robust choice -> checks -> methods ->
the one entry; the capture planner reads the degeneracy analysis). ``registry`` sits below the methods that
register themselves in it."""


def _stage(name: str) -> str:
    parts = name.split(".")
    return "__init__" if len(parts) == 1 else parts[1]


def test_calib_core_stage_order():
    floor = {s: k for k, stages in enumerate(CORE_FLOORS) for s in stages}
    mods = _modules("calib_core")
    assert {_stage(n) for n in mods} <= set(floor), f"stages without a floor: {set(map(_stage, mods)) - set(floor)}"
    bad = [(n, m) for n, p in mods.items() for m in _imports(n, p) if m in mods and _stage(m) != _stage(n)
           and floor[_stage(m)] >= floor[_stage(n)]]
    assert not bad, f"calib_core imports across or up its stages: {bad}"


def test_calib_core_module_and_function_sizes():
    long = []
    for n, p in _modules("calib_core").items():
        text = p.read_text()
        if text.count("\n") > 400:
            long.append(f"{n}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.end_lineno - node.lineno + 1 > 80:
                long.append(f"{n}.{node.name}: {node.end_lineno - node.lineno + 1} lines")
    assert not long, f"over 400 lines a module or 80 a function: {long}"
