"""Fingerprints of the code that computes a trial row, and the provenance line of every generated report.

A row's ``code`` column is ``calib_core:<hash>;simulate:<hash>[;<plugin module>:<hash>]``: a hash of every
``calib_core`` source file (the method), of ``simulate/`` and ``experiments/engine/trial.py`` (the scene and how a trial
is drawn and scored), and, for a plugin's method, of its module's file. A stored row whose ``code`` differs
from the current one for its method is stale: the runner recomputes it and never mixes it with fresh rows.

The package hashes are taken once per process (the code this process imported); a plugin module whose file
changed since it was loaded is reloaded (``refresh_plugins``), so a notebook that edits a plugin and reruns a
sweep runs, and stores, the new code.
"""

from __future__ import annotations

import hashlib
import sys
from collections.abc import Iterable, Mapping, Sequence
from functools import cache
from pathlib import Path

from calib_core import CalibrationError, get_method
from calib_core.plugins import reload_module

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = {"calib_core": ("calib_core",), "simulate": ("simulate", "experiments/engine/trial.py")}
"""Fingerprint part -> the sources (folders or files, relative to the repository) it hashes."""
HASH_NAMES = {"experiments/engine/trial.py": "experiments/trial.py"}
"""Sources hashed under a fixed name instead of their path: the trial code keeps the name under which the stored
rows were first fingerprinted, so that moving the file within the package marks no stored row stale (its bytes are
what the hash is about; the name only orders and separates the files)."""
REPORT_MARK = "Code fingerprint:"
"""How a generated report's provenance line begins (``experiments.engine.verify`` reads it back)."""

_PLUGIN_SEEN: dict[str, str] = {}
"""Plugin module -> the hash of its file when this process first fingerprinted it (the code it runs)."""


def _hash_files(files: Iterable[Path], root: Path) -> str:
    h = hashlib.sha1()
    named = sorted((HASH_NAMES.get(str(f.relative_to(root)), str(f.relative_to(root))), f) for f in files)
    for name, f in named:
        h.update(name.encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()[:10]


@cache
def package_hash(part: str) -> str:
    """The hash of the sources of fingerprint part ``part`` (``PACKAGES``), once per process."""
    files = []
    for rel in PACKAGES[part]:
        p = ROOT / rel
        files += sorted(p.rglob("*.py")) if p.is_dir() else [p]
    return _hash_files(files, ROOT)


def file_hash(path: str | Path) -> str:
    p = Path(path)
    return _hash_files([p], p.parent)


def _plugin_module(method: str) -> str | None:
    """The plugin module of ``method`` (None for the package's methods and for names the registry lacks: a
    test's own trial function may run any name)."""
    try:
        origin = get_method(method).origin
    except CalibrationError:
        return None
    return None if origin == "lidarcam" else origin.split(":")[0]


def refresh_plugins(modules: Iterable[str]) -> list[str]:
    """Reload the loaded plugin ``modules`` whose file changed since this process first fingerprinted them;
    returns those reloaded."""
    out = []
    for name in modules:
        mod = sys.modules.get(name)
        path = getattr(mod, "__file__", None)
        if not path:
            continue
        now = file_hash(path)
        if _PLUGIN_SEEN.setdefault(name, now) != now:
            reload_module(name)
            _PLUGIN_SEEN[name] = now
            out.append(name)
    return out


def method_code(method: str) -> str:
    """The ``code`` string of rows of ``method`` computed by this process (see the module docstring)."""
    parts = [f"{p}:{package_hash(p)}" for p in PACKAGES]
    module = _plugin_module(method)
    if module is not None:
        path = getattr(sys.modules.get(module), "__file__", None)
        if path:
            _PLUGIN_SEEN.setdefault(module, file_hash(path))
            parts.append(f"{module}:{_PLUGIN_SEEN[module]}")
        else:
            parts.append(f"{module}:unknown")
    return ";".join(parts)


def method_codes(methods: Sequence[str]) -> dict[str, str]:
    return {m: method_code(m) for m in methods}


def _parts(code) -> dict[str, str]:
    if not isinstance(code, str) or ":" not in code:
        return {}
    return dict(p.split(":", 1) for p in code.split(";") if ":" in p)


def changed_parts(old, new: str) -> list[str]:
    """Which parts of a row's ``code`` differ from ``new`` (``no fingerprint`` for rows stored without one)."""
    a, b = _parts(old), _parts(new)
    if not a:
        return ["no fingerprint"]
    return [k for k in b if a.get(k) != b[k]] + [k for k in a if k not in b]


def rerun_message(reused: int, stale: Mapping[str, int], why: Mapping[str, set], new: int) -> str:
    """``N rows reused, M recomputed (code changed: ...)[, K new]``; ``stale``/``why`` per method."""
    n_stale = sum(stale.values())
    text = f"{reused} rows reused, {n_stale} recomputed"
    if n_stale:
        by_part: dict[str, list[str]] = {}
        for m in sorted(stale):
            for part in sorted(why[m]):
                by_part.setdefault(part, []).append(m)
        text += " (code changed: " + "; ".join(f"{p} for {', '.join(ms)}" for p, ms in by_part.items()) + ")"
    return text + (f", {new} new" if new else "")


def provenance(methods: Sequence[str] = ()) -> str:
    """The report's provenance line: the code fingerprint (packages, plugins of ``methods``). No commit: a rerun of
    the same code at a later commit writes the same line."""
    parts = [f"{p} {package_hash(p)}" for p in PACKAGES]
    parts += sorted({f"{m} {_PLUGIN_SEEN.get(m, 'unknown')}" for m in filter(None, map(_plugin_module, methods))})
    return f"{REPORT_MARK} {', '.join(parts)}."


def write_stamped(path: str | Path, text: str, methods: Sequence[str] = (), timing_columns: Sequence[str] = (),
                  timing_patterns: Sequence[str] = ()) -> Path:
    """Write a generated report with its provenance line at the end; with ``timing_columns`` / ``timing_patterns``,
    a report there that differs from it only in those timings is kept (``engine.keep``)."""
    from .keep import write_unless_timings

    path = Path(path)
    write_unless_timings(path, text.rstrip("\n") + f"\n\n{provenance(methods)}\n", timing_columns, timing_patterns)
    return path


def report_staleness(path: str | Path) -> str | None:
    """Why the report at ``path`` is stale against the current code (None when its fingerprint is current)."""
    line = next((ln for ln in Path(path).read_text().splitlines() if ln.startswith(REPORT_MARK)), None)
    if line is None:
        return "no code fingerprint (written before reports carried one)"
    stated = dict(p.rsplit(" ", 1) for p in line[len(REPORT_MARK):].split("(commit")[0].strip(" .").split(", "))
    changed = [p for p in PACKAGES if stated.get(p) != package_hash(p)]
    return f"code changed since it was written: {', '.join(changed)}" if changed else None
