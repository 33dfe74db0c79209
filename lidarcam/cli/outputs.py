"""Where the verbs write: every output path is checked before any work, so an unwritable ``--out`` is one line and
exit 2 (``OutputError``, a LidarcamError that ``lidarcam.cli.main`` prints), never a traceback after the work.

``writable_file(path, flag)`` for a file (its folder must exist, unless ``parents``), ``writable_folder(path,
flag)`` for a folder the verb creates or fills (its nearest existing ancestor must be a writable folder),
``replaced_folder`` for a folder written whole or not at all (a scratch folder renamed into place at the end).
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path

from calib_core.errors import LidarcamError


class OutputError(LidarcamError):
    """An output path the verb cannot write: names the option and the path."""


def _probe(folder: Path, flag: str, target) -> None:
    """Create and remove a scratch file in ``folder`` (root ignores permission bits, so ``os.access`` cannot tell)."""
    try:
        fd, name = tempfile.mkstemp(prefix=".lidarcam-probe-", dir=folder)
        os.close(fd)
        os.unlink(name)
    except OSError as err:
        raise OutputError(f"{flag} {target}: cannot write in folder '{folder}' ({err.strerror})") from None


def _existing_ancestor(path: Path, flag: str, target) -> Path:
    """The nearest existing ancestor of ``path``; an OutputError if it is not a folder."""
    p = path
    while not p.exists():
        if p.parent == p:
            break
        p = p.parent
    if not p.is_dir():
        raise OutputError(f"{flag} {target}: '{p}' is a file, not a folder")
    return p


def writable_file(path, flag: str = "--out", *, parents: bool = False) -> Path | None:
    """``path`` as a Path once a file can be written there (None passes through); OutputError otherwise.

    The folder must exist; with ``parents`` the verb creates it, and its nearest existing ancestor is checked."""
    if path is None:
        return None
    p = Path(path)
    if p.is_dir():
        raise OutputError(f"{flag} {path}: is a folder; give a file name")
    folder = p.parent if str(p.parent) else Path(".")
    if parents:
        _probe(_existing_ancestor(folder, flag, path), flag, path)
        return p
    if not folder.is_dir():
        what = "is not a folder" if folder.exists() else "does not exist"
        raise OutputError(f"{flag} {path}: folder '{folder}' {what}")
    _probe(folder, flag, path)
    return p


def writable_folder(path, flag: str = "--out") -> Path | None:
    """``path`` as a Path once the verb can create or fill that folder (None passes through); OutputError
    otherwise. Nothing is created here."""
    if path is None:
        return None
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise OutputError(f"{flag} {path}: is a file, not a folder")
    _probe(_existing_ancestor(p, flag, path), flag, path)
    return p


def not_an_input(path, flag: str, *inputs) -> None:
    """OutputError when the output ``path`` is one of the files the verb reads (``inputs``: paths or None)."""
    if path is None:
        return
    for src in inputs:
        try:
            same = src is not None and os.path.samefile(path, src)
        except OSError:
            same = False
        if same:
            raise OutputError(f"{flag} {path}: is the input file {src} this run reads; give another name")


def _listing(p: Path, n: int = 4) -> str:
    names = sorted(e.name for e in p.iterdir())
    return ", ".join(names[:n]) + (f" and {len(names) - n} more" if len(names) > n else "")


def replaceable_folder(path, flag: str, own: Callable[[Path], bool], what: str) -> Path:
    """``path`` as a Path once ``replaced_folder`` can write it (checked before any work); OutputError otherwise."""
    p = Path(path)
    writable_folder(p, flag)
    _probe(_existing_ancestor(p.absolute().parent, flag, path), flag, path)  # the scratch folder goes beside it
    if p.is_dir() and any(p.iterdir()) and not own(p):
        raise OutputError(f"{flag} {path}: holds {_listing(p)}, which is not {what}; give a new or empty folder")
    return p


@contextmanager
def replaced_folder(path, flag: str, own: Callable[[Path], bool], what: str):
    """Write a folder whole or not at all: yields a scratch folder beside ``path``; when the block ends it takes
    ``path``'s place (an earlier ``path`` that ``own`` recognises as this verb's output is replaced), and when the
    block raises or is interrupted the scratch folder is removed and ``path`` is left as it was.

    A ``path`` holding anything else (``own`` false: another rig's poses, the user's files) is an OutputError
    before any work, naming what it holds; ``what`` names the verb's output for the messages."""
    p = replaceable_folder(path, flag, own, what)
    scratch = p.parent / f".{p.name}.partial-{os.getpid()}"
    if scratch.exists():
        shutil.rmtree(scratch)
    scratch.mkdir(parents=True)
    try:
        yield scratch
    except BaseException:
        shutil.rmtree(scratch, ignore_errors=True)
        if not isinstance(sys.exc_info()[1], Exception):  # Ctrl-C: say what is on disk
            print(f"{path}: " + ("left as it was" if p.exists() else "not written") + " (the partial copy removed)",
                  file=sys.stderr)
        raise
    old = p.parent / f".{p.name}.old-{os.getpid()}"
    if p.exists():
        p.rename(old)
    scratch.rename(p)
    if old.exists():
        shutil.rmtree(old)
