"""The command line of every study: a parser whose errors are one line (``<prog>: error: ...``, exit status 2, no
usage block) and argument types that refuse a value the study cannot run with (a count below its minimum, a
non-finite or non-positive scale, a list that is not integers) before anything is computed. The number types are
``lidarcam.rig.argtypes``' (shared with the ``lidarcam`` verbs; the layer rule keeps the studies from importing
``lidarcam.cli``)."""

from __future__ import annotations

import argparse
import sys
from typing import NoReturn

from lidarcam.rig.argtypes import finite_float, int_at_least, nonnegative_float, positive_float

__all__ = ["StudyParser", "finite_float", "int_at_least", "int_list", "n_jobs", "nonnegative_float",
           "nonnegative_int", "positive_float", "positive_int", "study_parser"]


class StudyParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose error is the one line ``<prog>: error: <message>`` and exit status 2."""

    def error(self, message: str) -> NoReturn:
        print(f"{self.prog}: error: {' '.join(message.split())}", file=sys.stderr)
        raise SystemExit(2)


def study_parser(doc: str | None, **kwargs) -> StudyParser:
    """A ``StudyParser`` described by the first paragraph of a study module's docstring."""
    return StudyParser(description=" ".join((doc or "").split("\n\n")[0].split()), **kwargs)


positive_int = int_at_least(1)
nonnegative_int = int_at_least(0)


def n_jobs(text: str) -> int:
    """An argparse type: a worker count, ``>= 1``, or negative for "all cores but ``-1 - n``" (-1: all cores)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if value == 0:
        raise argparse.ArgumentTypeError("0 workers: give 1 or more, or -1 for every core")
    return value


def int_list(low: int, empty: bool = False):
    """An argparse type: comma-separated integers, each ``>= low`` (``3,4,5``); ``empty``: "" is the empty list."""
    one = int_at_least(low)

    def parse(text: str) -> list[int]:
        if empty and not text.strip():
            return []
        items = [s.strip() for s in text.split(",")]
        if not text.strip() or any(not s for s in items):
            raise argparse.ArgumentTypeError(f"{text!r} is not a comma-separated list of integers")
        return [one(s) for s in items]
    parse.__name__ = f"list of integers >= {low}"
    return parse
