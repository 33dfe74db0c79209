"""The steps after a sweep (tables, figures, report) skipped when nothing they are made of changed.

A study records in ``<out>/.inputs.json`` (not committed) the digest of its inputs -- the trial rows (every value,
the code fingerprint of each row included), the source of the ``experiments`` package, the versions of the
libraries that draw -- and of every file it wrote under ``<out>``. A rerun whose inputs have the same digest and
whose outputs are still those files (none deleted or edited) writes nothing; any difference redraws all of them.
"""

from __future__ import annotations

import hashlib
import json
from importlib import metadata
from pathlib import Path

import pandas as pd

STATE = ".inputs.json"
PACKAGE = Path(__file__).resolve().parents[1]
LIBRARIES = ("matplotlib", "pandas", "numpy")


def rows_digest(df: pd.DataFrame) -> str:
    """SHA-1 of a frame's column names and values (row order included)."""
    h = hashlib.sha1(json.dumps(list(map(str, df.columns))).encode())
    if len(df):
        h.update(pd.util.hash_pandas_object(df, index=False).to_numpy().tobytes())
    return h.hexdigest()


def code_digest() -> str:
    """SHA-1 of the ``experiments`` package's sources and the drawing libraries' versions."""
    h = hashlib.sha1()
    for f in sorted(PACKAGE.rglob("*.py")):
        h.update(f.relative_to(PACKAGE).as_posix().encode() + b"\0" + f.read_bytes())
    for lib in LIBRARIES:
        try:
            h.update(f"{lib} {metadata.version(lib)}".encode())
        except metadata.PackageNotFoundError:
            h.update(lib.encode())
    return h.hexdigest()


def inputs_digest(rows: pd.DataFrame, **settings) -> str:
    """The digest of a study's inputs: its rows, the code, and ``settings`` (JSON-able)."""
    extra = json.dumps(settings, sort_keys=True, default=str)
    return hashlib.sha1(f"{rows_digest(rows)} {code_digest()} {extra}".encode()).hexdigest()


def _outputs(out: Path) -> dict[str, str]:
    return {f.relative_to(out).as_posix(): hashlib.sha1(f.read_bytes()).hexdigest()
            for f in sorted(out.rglob("*")) if f.is_file() and f.name != STATE}


def unchanged(out: str | Path, digest: str) -> bool:
    """True when ``out`` was last written from inputs of ``digest`` and still holds exactly what was written."""
    out = Path(out)
    try:
        state = json.loads((out / STATE).read_text())
    except (OSError, ValueError):
        return False
    return isinstance(state, dict) and state.get("inputs") == digest and state.get("outputs") == _outputs(out)


def record(out: str | Path, digest: str) -> None:
    """Note that ``out`` now holds the outputs of inputs of ``digest``."""
    out = Path(out)
    (out / STATE).write_text(json.dumps({"inputs": digest, "outputs": _outputs(out)}, indent=1) + "\n")
