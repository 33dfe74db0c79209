"""The results store: per cell, ``settings.json`` and ``chunk-<first>-<last>-<methods hash>.csv`` files under
``<results_dir>/<sweep>/trials/<setting-key>/``, each written whole (temporary file, then rename); reading,
checking (a damaged chunk is never read in part), and the (trial, method) pairs still to compute.

Every row carries a checksum (``CHECK_COLUMN``: SHA-1 of its values as the file reads back, the code fingerprint
aside), so a row edited or damaged after it was written -- one digit changed, one ``valid`` flipped, text or bytes
where a number belongs -- makes its chunk damaged: moved aside and recomputed, never served.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import os
import re
import socket
import sys
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pandas as pd

from .cell import CODE_COLUMN, RESULT_COLUMNS, Cell, RunnerError
from .fingerprint import changed_parts

CHECK_COLUMN = "row_check"
"""The column holding each stored row's checksum (``row_checks``), written by the store after every other column."""


def _canonical(value) -> str:
    """One value as the checksum sees it: numbers as 10 significant digits (the precision the store writes),
    booleans as True/False, empty and NaN as "", anything else as its text."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, float, np.integer, np.floating)):
        return format(float(value), ".10g")
    return str(value)


def row_checks(df: pd.DataFrame) -> pd.Series:
    """Per row, the 16-hex SHA-1 of its values (columns in name order; ``CODE_COLUMN`` and ``CHECK_COLUMN`` left
    out: a changed fingerprint makes a row stale, which recomputes it as well)."""
    cols = sorted(c for c in df.columns if c not in (CODE_COLUMN, CHECK_COLUMN))
    text = pd.Series([""] * len(df), index=df.index, dtype=object)
    for c in cols:
        text = text + "\x1f" + df[c].map(_canonical)
    return text.map(lambda t: hashlib.sha1(t.encode()).hexdigest()[:16])


def read_table(path: Path, text_columns: Sequence[str] = ("reason",)) -> pd.DataFrame:
    """A CSV table whose ``text_columns`` read back as strings ("" where empty, even when all are empty)."""
    df = pd.read_csv(path)
    for col in text_columns:
        if col in df:
            df[col] = df[col].astype(object).where(df[col].notna(), "").astype(str)
    return df


class DamagedChunk(RunnerError):
    """A chunk file that does not parse in full (empty, cut mid-row, junk): never read in part."""


def methods_tag(methods: Sequence[str]) -> str:
    """The 6-hex hash of a method list (in order) that a chunk file's name carries."""
    return hashlib.sha1(",".join(methods).encode()).hexdigest()[:6]


_CHUNK_NAME = re.compile(r"^chunk-(\d{5,})-(\d{5,})-([0-9a-f]{6})\.csv$")


_PARSED: dict[Path, tuple[str, pd.DataFrame]] = {}
"""Chunk files parsed and checked in this process, keyed by path, with the SHA-1 of the bytes they had: a sweep
parses each chunk once although pruning, scheduling and loading each look at it; a file whose bytes changed in
any way is parsed and checked again."""
_PARSED_MAX = 4096


def _read_chunk(path: Path) -> pd.DataFrame:
    """``_parse_chunk`` of ``path``, from this process's cache when the file holds the bytes parsed before."""
    if not _CHUNK_NAME.match(path.name) or not path.is_file():
        return _parse_chunk(path, b"")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise DamagedChunk(f"{path}: damaged chunk file (unreadable: {exc.strerror})") from None
    digest = hashlib.sha1(raw).hexdigest()
    hit = _PARSED.get(path)
    if hit is not None and hit[0] == digest:
        return hit[1].copy()
    df = _parse_chunk(path, raw)
    if len(_PARSED) >= _PARSED_MAX:
        _PARSED.clear()
    _PARSED[path] = (digest, df)
    return df.copy()


def _parse_chunk(path: Path, raw: bytes) -> pd.DataFrame:
    """The rows of one chunk file, checked in full: the header has the result columns; every (trial, method) of
    the name's trial range and of the methods whose hash the name carries appears exactly once; trial, method,
    ok and valid are well-formed in every row. DamagedChunk otherwise."""
    def damaged(why: str) -> DamagedChunk:
        return DamagedChunk(f"{path}: damaged chunk file ({why})")

    m = _CHUNK_NAME.match(path.name)
    if not m:
        raise damaged("name is not chunk-<first>-<last>-<methods hash>.csv")
    if not path.is_file():
        raise damaged("not a file")
    try:
        df = read_table(io.BytesIO(raw))
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError, ValueError, OSError) as exc:
        raise damaged(f"does not parse: {str(exc).splitlines()[0][:120]}") from None
    missing = [c for c in RESULT_COLUMNS if c not in df.columns and c != CODE_COLUMN]
    if missing:
        raise damaged(f"missing columns {missing[:4]}")
    if CHECK_COLUMN not in df:
        raise damaged(f"no {CHECK_COLUMN!r} column (written before rows carried checksums)")
    bad = np.flatnonzero(row_checks(df).to_numpy() != df[CHECK_COLUMN].astype(str).to_numpy())
    if bad.size:
        raise damaged(f"{bad.size} row(s) fail their checksum, the first on line {bad[0] + 2} (edited or damaged)")
    df = df.drop(columns=CHECK_COLUMN)
    if CODE_COLUMN in df and not df[CODE_COLUMN].map(lambda v: isinstance(v, str) and ":" in v).all():
        raise damaged(f"a row without its {CODE_COLUMN!r} (cut short?)")
    first, last = int(m.group(1)), int(m.group(2))
    trial = pd.to_numeric(df["trial"], errors="coerce")
    if trial.isna().any() or not (trial == trial.round()).all():
        raise damaged("a trial number that is not an integer")
    if df["method"].isna().any() or not df["method"].map(lambda v: isinstance(v, str) and v != "").all():
        raise damaged("a row without a method")
    methods = list(dict.fromkeys(df["method"]))
    tag = methods_tag(methods)
    # a real observation file without a reference has no valid rate: its rows leave 'valid' empty
    no_ref = df["has_reference"].map(lambda v: str(v) == "False") if "has_reference" in df else False
    for col, may_be_empty in (("ok", False), ("valid", no_ref)):
        if not (df[col].map(lambda v: str(v) in ("True", "False")) | (may_be_empty & df[col].isna())).all():
            raise damaged(f"a row whose {col!r} is not True/False")
    want = {(t, mm) for t in range(first, last + 1) for mm in methods}
    got = list(zip(trial.astype(int), df["method"], strict=True))
    if tag != m.group(3) or len(got) != len(set(got)) or set(got) != want:
        raise damaged(f"{len(got)} rows, expected {(last - first + 1)} trials x the methods of hash {m.group(3)}")
    df["trial"] = trial.astype(int)
    for col in ("ok", "valid"):
        df[col] = df[col].map(lambda v: str(v) == "True").astype(bool)
    return df


def verify_cell_dir(path: Path) -> list[str]:
    """Problems of the store of one cell (empty when sound): damaged chunk files, stray temporary files."""
    out = []
    for f in sorted(Path(path).glob("chunk-*.csv")):
        try:
            _read_chunk(f)
        except DamagedChunk as err:
            out.append(str(err))
    out += [f"{f}: temporary file left by an interrupted write" for f in sorted(Path(path).glob(".chunk-*.tmp"))]
    return out


def verify_store(results_dir: str | Path, sweep: str | None = None) -> list[str]:
    """Problems of every cell under ``results_dir`` (one sweep, or all): see ``verify_cell_dir``."""
    root = Path(results_dir)
    sweeps = [root / sweep] if sweep else sorted(p for p in root.iterdir() if (p / "trials").is_dir())
    return [msg for sw in sweeps for cell in sorted((sw / "trials").glob("*/")) for msg in verify_cell_dir(cell)]


def load_cell_dir(path: Path, heal: bool = False) -> pd.DataFrame:
    """Every row stored under one cell folder (duplicates of a (trial, method) pair dropped).

    A damaged chunk file raises DamagedChunk; with ``heal`` it is renamed ``<name>.damaged`` (so its trials are
    recomputed), reported on stderr, and left out whole.
    """
    frames = []
    for f in sorted(Path(path).glob("chunk-*.csv")):
        try:
            frames.append(_read_chunk(f))
        except DamagedChunk as err:
            if not heal:
                raise DamagedChunk(f"{err}; rerun the sweep to recompute it") from None
            os.replace(f, f.with_name(f.name + ".damaged"))
            sys.stderr.write(f"{err}: moved aside to {f.name}.damaged; its trials are recomputed\n")
    if not frames:
        return pd.DataFrame()
    df = pd.concat(frames, ignore_index=True)
    return df.drop_duplicates(["trial", "method"], keep="first")


def load_cell(cell: Cell) -> pd.DataFrame:
    """The rows of ``cell``: its trials ``0..n_trials-1`` and its methods, sorted by trial then method order."""
    df = load_cell_dir(cell.dir)
    if df.empty:
        return df
    df = df[(df["trial"] < cell.n_trials) & df["method"].isin(cell.methods)].copy()
    order = {m: i for i, m in enumerate(cell.methods)}
    df["_m"] = df["method"].map(order)
    return df.sort_values(["trial", "_m"]).drop(columns="_m").reset_index(drop=True)


def load_sweep(results_dir: str | Path, sweep: str) -> pd.DataFrame:
    """Every row stored for ``sweep`` under ``results_dir`` (all its cells)."""
    cells = sorted((Path(results_dir) / sweep / "trials").glob("*/"))
    frames = [load_cell_dir(c) for c in cells]
    frames = [f for f in frames if not f.empty]
    if not frames:
        raise RunnerError(f"no trials stored under {Path(results_dir) / sweep / 'trials'}")
    return pd.concat(frames, ignore_index=True)


def _tmp_name(path: Path) -> Path:
    """A hidden temporary name next to ``path``, unique per host and process (workers of a cluster share the store
    on one file system, where two hosts may run the same pid)."""
    return path.with_name(f".{path.name}.{socket.gethostname()}.{os.getpid()}.tmp")


def _csv_text(df: pd.DataFrame) -> str:
    return df.to_csv(index=False, float_format="%.10g", lineterminator="\n")


def _write_atomic(df: pd.DataFrame, path: Path) -> None:
    """Write whole or not at all: a temporary file in the same folder, flushed to disk, then renamed. Each row
    gets its checksum over its values as they read back from the file (``row_checks``)."""
    df = df.drop(columns=CHECK_COLUMN, errors="ignore")
    back = read_table(io.StringIO(_csv_text(df)))
    df = df.assign(**{CHECK_COLUMN: row_checks(back).to_numpy()})
    tmp = _tmp_name(path)
    with open(tmp, "w", newline="") as fh:
        fh.write(_csv_text(df))
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def write_chunk(cell: Cell, trials: Sequence[int], methods: Sequence[str], rows: list[dict]) -> None:
    """One chunk file of ``cell``: the rows of ``trials`` x ``methods``, named by its trial range and methods."""
    cols = list(cell.columns()) + list(RESULT_COLUMNS)
    df = pd.DataFrame(rows)
    df = df.reindex(columns=cols + [c for c in df.columns if c not in cols])  # a trial_fn may omit metric columns
    tag = methods_tag(methods)
    _write_atomic(df, cell.dir / f"chunk-{min(trials):05d}-{max(trials):05d}-{tag}.csv")


def prepare_cell(cell: Cell) -> None:
    """The cell's folder and its ``settings.json`` (written once, whole or absent); RunnerError when the results
    folder, or a folder on the way to the cell's, is not a folder."""
    for p in (cell.dir, *cell.dir.parents):
        if p.exists() and not p.is_dir():
            raise RunnerError(f"{p}: not a folder (the results folder holds the trial store: "
                              f"--results / results_dir={cell.results_dir})")
    cell.dir.mkdir(parents=True, exist_ok=True)
    settings = cell.dir / "settings.json"
    if not settings.exists():
        d = asdict(cell)
        d.pop("n_trials"), d.pop("methods"), d.pop("results_dir"), d.pop("plugins")
        tmp = _tmp_name(settings)  # whole or absent: a worker killed mid-write must not leave half a file
        tmp.write_text(json.dumps({"key": cell.key, **d}, indent=1, sort_keys=True, default=str) + "\n")
        os.replace(tmp, settings)


def prune_stale(cell: Cell, codes: dict[str, str]) -> tuple[dict[str, int], dict[str, set]]:
    """Remove from the chunk files of ``cell`` the rows of the methods in ``codes`` that another code computed
    (``code`` column absent or different), so that they are recomputed and never mixed with fresh rows; a chunk
    keeps its other methods' rows under its new methods hash. Returns, per method, the rows removed among the
    cell's trials and why (the fingerprint parts that changed)."""
    removed: dict[str, int] = {}
    why: dict[str, set] = {}
    for f in sorted(cell.dir.glob("chunk-*.csv")):
        try:
            df = _read_chunk(f)
        except DamagedChunk:
            continue  # pending() moves damaged chunks aside first
        code = df[CODE_COLUMN] if CODE_COLUMN in df else pd.Series([None] * len(df), index=df.index)
        stale_rows = df["method"].isin(list(codes)) & (code != df["method"].map(codes))
        if not stale_rows.any():
            continue
        stale = set(df.loc[stale_rows, "method"])
        for m in stale:
            rows = df["method"] == m
            removed[m] = removed.get(m, 0) + int((rows & (df["trial"] < cell.n_trials)).sum())
            why.setdefault(m, set()).update(*(changed_parts(c, codes[m]) for c in code[rows].unique()))
        keep = df[~df["method"].isin(stale)]
        m = _CHUNK_NAME.match(f.name)
        if not keep.empty:
            _write_atomic(keep, f.with_name(f"chunk-{m.group(1)}-{m.group(2)}-"
                                            f"{methods_tag(list(dict.fromkeys(keep['method'])))}.csv"))
        f.unlink()
    return removed, why


def pending(cell: Cell, chunk_size: int) -> list[tuple[int, ...] | tuple]:
    """(trials, methods) tasks still to run for ``cell``: consecutive trials missing the same methods."""
    df = load_cell_dir(cell.dir, heal=True)
    done = set(zip(df["trial"], df["method"], strict=True)) if not df.empty else set()
    tasks: list[tuple[list[int], tuple[str, ...]]] = []
    for t in range(cell.n_trials):
        missing = tuple(m for m in cell.methods if (t, m) not in done)
        if not missing:
            continue
        if tasks and tasks[-1][1] == missing and len(tasks[-1][0]) < chunk_size and tasks[-1][0][-1] == t - 1:
            tasks[-1][0].append(t)
        else:
            tasks.append(([t], missing))
    return [(tuple(ts), ms) for ts, ms in tasks]
