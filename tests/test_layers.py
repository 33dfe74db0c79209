"""The layer rule: ``calib_core`` is numpy + scipy only and imports nothing above it; no import cycles."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("calib_core", "lidarcam.rig", "simulate", "lidarcam.cli", "experiments")
ABOVE = {"calib_core": {"lidarcam", "lidarcam.rig", "simulate", "lidarcam.cli", "experiments"},
         "simulate": {"lidarcam", "lidarcam.rig", "lidarcam.cli", "experiments"},
         "lidarcam.rig": {"simulate", "lidarcam.cli", "experiments"},
         "lidarcam.cli": {"experiments"},
         "experiments": {"lidarcam.cli"}}
HEAVY = ("hydra", "omegaconf", "cv2", "yaml", "matplotlib", "PIL", "pandas", "joblib", "rosbags")


def _modules(pkg: str) -> dict[str, Path]:
    out = {}
    for path in sorted((ROOT / pkg.replace(".", "/")).rglob("*.py")):
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


def _package(module: str) -> str:
    """The package of PACKAGES that holds ``module`` (``lidarcam`` itself for its top files), else its top name."""
    return next((p for p in PACKAGES if module == p or module.startswith(p + ".")), module.split(".")[0])


ALL = {n: p for pkg in PACKAGES for n, p in _modules(pkg).items()}


@pytest.mark.parametrize("pkg", PACKAGES)
def test_no_import_up_the_layers(pkg):
    bad = [(n, m) for n, p in _modules(pkg).items() for m in _imports(n, p) if _package(m) in ABOVE[pkg]]
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


CORE_FLOORS = (("errors",), ("geometry",), ("data",), ("model",), ("solvers",), ("refine",), ("robust",), ("checks",),
               ("planning",), ("registry",), ("methods",), ("entry", "plugins"), ("evaluate",), ("__init__",))
"""The stages of ``calib_core`` in import order, lowest first: a module imports only from its own stage or from a
lower floor (the flow: data -> scan lines -> candidates -> refinement and robust choice -> checks -> methods ->
the one entry; the capture planner reads the degeneracy analysis). ``registry`` sits below the methods that
register themselves in it."""


def test_calib_core_stage_order():
    bad = _check_floors("calib_core", CORE_FLOORS, _room)
    assert not bad, f"calib_core imports across or up its stages: {bad}"


MAX_MODULE_LINES = 400
MAX_FUNCTION_LINES = 80
"""Size limits of every module and function of the five packages."""


@pytest.mark.parametrize("pkg", PACKAGES)
def test_module_and_function_sizes(pkg):
    long = []
    for n, p in _modules(pkg).items():
        text = p.read_text()
        if text.count("\n") > MAX_MODULE_LINES:
            long.append(f"{n}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text)):
            size = getattr(node, "end_lineno", 0) - getattr(node, "lineno", 0) + 1
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and size > MAX_FUNCTION_LINES:
                long.append(f"{n}.{node.name}: {size} lines")
    assert not long, f"over {MAX_MODULE_LINES} lines a module or {MAX_FUNCTION_LINES} a function: {long}"


EXPERIMENT_FLOORS = (("engine",), ("config", "summary", "bench"), ("paper", "suites", "real", "run", "__main__"),
                     ("__init__",))
"""The rooms of ``experiments`` in import order, lowest first: ``engine`` runs and keeps trials; ``config`` (the
Hydra side and the sweeps), ``summary`` (rows to tables, figures and intervals) and ``bench`` (timings) stand on
it; the studies of ``paper``, ``suites`` and ``real`` (the public rigs), the Hydra runner and the door stand on
top, peers of one another (no study imports another)."""


def _room(name: str) -> str:
    parts = name.split(".")
    return "__init__" if len(parts) == 1 else parts[1]


def _check_floors(pkg: str, floors, room) -> list:
    floor = {s: k for k, rooms in enumerate(floors) for s in rooms}
    mods = _modules(pkg)
    assert {room(n) for n in mods} <= set(floor), f"rooms without a floor: {set(map(room, mods)) - set(floor)}"
    return [(n, m) for n, p in mods.items() for m in _imports(n, p) if m in mods and room(m) != room(n)
            and floor[room(m)] >= floor[room(n)]]


def test_experiments_floor_order():
    bad = _check_floors("experiments", EXPERIMENT_FLOORS, _room)
    assert not bad, f"experiments imports across or up its floors: {bad}"


def test_experiments_in_few_rooms():
    rooms = {p.name for p in (ROOT / "experiments").iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert len(rooms) <= 8 and rooms == {r for f in EXPERIMENT_FLOORS for r in f} - {"run", "__main__", "__init__"}


def floor_table(floors) -> str:
    """The markdown table of ``floors`` in docs/architecture.md (written by ``python tests/test_layers.py``)."""
    rows = ["| floor | stages |", "|---:|---|"]
    rows += [f"| {k} | {', '.join(f'`{s}`' for s in stages)} |" for k, stages in enumerate(floors)]
    return "\n".join(rows)


def module_tree(pkg: str) -> str:
    """The tree of ``pkg`` in docs/architecture.md: each folder with its modules, read from the files (written by
    ``python tests/test_layers.py``; every module's own docstring says what it holds)."""
    base = ROOT / pkg.replace(".", "/")
    folders: dict[str, list[str]] = {}
    for path in sorted(base.rglob("*.py")):
        if path.name == "__init__.py":
            continue
        folder = path.parent.relative_to(base).as_posix()
        folders.setdefault("" if folder == "." else folder + "/", []).append(path.stem)
    width = max(len(f) for f in folders) + 2
    lines = [f"{pkg.replace('.', '/')}/"]
    for folder in sorted(folders, key=lambda f: (f != "", f)):
        names, row = folders[folder], f"  {(folder or '(top)'):<{width}}"
        for k, name in enumerate(names):
            piece = name + (", " if k < len(names) - 1 else "")
            if len(row) + len(piece) > 116:
                lines.append(row.rstrip())
                row = " " * (width + 2)
            row += piece
        lines.append(row.rstrip())
    return "```\n" + "\n".join(lines) + "\n```"


DOC = ROOT / "docs" / "architecture.md"
DOC_TABLES = {"calib_core": CORE_FLOORS, "experiments": EXPERIMENT_FLOORS}
DOC_TREES = ("calib_core", "lidarcam.rig", "lidarcam.cli", "simulate", "experiments")


def _between(text: str, begin: str, end: str, body: str) -> str:
    head, _, rest = text.partition(begin)
    _, _, tail = rest.partition(end)
    return f"{head}{begin}\n{body}\n{end}{tail}"


def _doc_with_tables(text: str) -> str:
    for pkg, floors in DOC_TABLES.items():
        text = _between(text, f"<!-- floors {pkg}: generated by python tests/test_layers.py -->",
                        f"<!-- end floors {pkg} -->", floor_table(floors))
    for pkg in DOC_TREES:
        text = _between(text, f"<!-- tree {pkg}: generated by python tests/test_layers.py -->",
                        f"<!-- end tree {pkg} -->", module_tree(pkg))
    return text


def test_architecture_doc_states_the_tested_floors():
    text = DOC.read_text()
    assert text == _doc_with_tables(text), ("docs/architecture.md's floor tables or module trees differ: run "
                                            "python tests/test_layers.py")


def test_architecture_doc_has_every_tree():
    text = DOC.read_text()
    assert all(f"<!-- tree {pkg}: generated" in text for pkg in DOC_TREES)


if __name__ == "__main__":
    DOC.write_text(_doc_with_tables(DOC.read_text()))
