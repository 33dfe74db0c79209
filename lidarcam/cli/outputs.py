"""Where the verbs write: every output path is checked before any work, so an unwritable ``--out`` is one line and
exit 2 (``OutputError``, a LidarcamError that ``lidarcam.cli.main`` prints), never a traceback after the work.

``writable_file(path, flag)`` for a file (its folder must exist, unless ``parents``), ``writable_folder(path,
flag)`` for a folder the verb creates or fills (its nearest existing ancestor must be a writable folder).
"""

from __future__ import annotations

import os
import tempfile
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
