"""argparse types of the verbs' numeric options: a value argparse accepts is one the verb can use, and a bad
one is argparse's one line naming the option (exit 2). ``check_numbers`` gives them to every verb's float options;
the number types themselves are ``lidarcam.rig.argtypes``' (shared with the experiments' studies)."""

from __future__ import annotations

import argparse

from lidarcam.rig.argtypes import finite_float, int_at_least, nonnegative_float, positive_float

seed_type = int_at_least(0)
"""A simulation seed: an integer >= 0 (numpy's seeds)."""


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
                a.type = (positive_float if names & POSITIVE else nonnegative_float if names & NON_NEGATIVE
                          else finite_float)
