"""No calib_core module imports another's private (``_``-prefixed) name: what a module shares it names publicly, with
a docstring."""

from __future__ import annotations

import ast
from pathlib import Path

import calib_core

ROOT = Path(calib_core.__file__).parent


def test_no_module_imports_a_private_name_of_another():
    found = [f"{p.relative_to(ROOT.parent)}: {node.module}.{a.name}"
             for p in sorted(ROOT.rglob("*.py")) for node in ast.walk(ast.parse(p.read_text()))
             if isinstance(node, ast.ImportFrom) and node.module != "__future__"
             for a in node.names if a.name.startswith("_")]
    assert len(list(ROOT.rglob("*.py"))) > 50 and found == []
