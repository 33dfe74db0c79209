"""argparse types of the verbs' numeric options: a value argparse accepts is one the verb can use, and a bad
one is argparse's one line naming the option (exit 2). ``check_numbers`` gives them to every verb's float options."""

from __future__ import annotations

import argparse
import math


def finite_float(text: str) -> float:
    """A finite number (``nan`` and ``inf`` parse as floats but mean nothing as an option's value)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return v


def seed_type(text: str) -> int:
    """A simulation seed: an integer >= 0 (numpy's seeds)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {v}")
    return v


def positive_float(text: str) -> float:
    """A finite number > 0 (a noise level, a bound, a tolerance)."""
    v = finite_float(text)
    if v <= 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, got {text!r}")
    return v


def non_negative_float(text: str) -> float:
    """A finite number >= 0 (0: automatic or off, as the option's help says)."""
    v = finite_float(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected a number >= 0, got {text!r}")
    return v


POSITIVE = {"--max-offset", "--max-reproj", "--max-board", "--still-px",
            "--max-offset-time", "--sync-tol", "--square"}
"""Options of the verbs whose value must be > 0."""
NON_NEGATIVE = {"--quiet-grey", "--scan-still", "--min-angle", "--min-move"}
"""Options whose value must be >= 0."""
OWN_CHECK = {"--range-sigma", "--max-curvature-chi2"}
"""Options their verb checks itself, with a hint (``lidarcam.cli.rig.check_noise_flags``: leave it out to estimate
it): left as they are."""


def check_numbers(parser: argparse.ArgumentParser) -> None:
    """Give every float option of ``parser`` and its verbs a type that refuses NaN and inf, and the options of
    ``POSITIVE`` / ``NON_NEGATIVE`` their sign: a bad value is argparse's one line naming the option."""
    todo = [parser]
    while todo:
        p = todo.pop()
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                todo.extend(a.choices.values())
            elif a.type in (float, finite_float) and not set(a.option_strings) & OWN_CHECK:
                names = set(a.option_strings)
                a.type = (positive_float if names & POSITIVE else non_negative_float if names & NON_NEGATIVE
                          else finite_float)
