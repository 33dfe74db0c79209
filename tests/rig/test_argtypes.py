"""The number types of both command lines (``lidarcam`` verbs and ``python -m experiments`` studies) have one home,
``lidarcam.rig.argtypes``: a value outside the type is an ``ArgumentTypeError`` naming it, a value inside comes back
as a number."""

from __future__ import annotations

import argparse
import math

import pytest

from experiments.engine import cli as studies
from lidarcam.cli import argtypes as verbs
from lidarcam.rig import argtypes as shared


def test_both_command_lines_use_the_shared_types():
    for name in ("finite_float", "positive_float", "nonnegative_float", "int_at_least"):
        assert getattr(studies, name) is getattr(shared, name), name
    for name in ("finite_float", "positive_float", "nonnegative_float"):
        assert getattr(verbs, name) is getattr(shared, name), name


@pytest.mark.parametrize("parse, good, bad", [
    (shared.finite_float, {"-2.5": -2.5, "0": 0.0, "1e3": 1000.0}, ("nan", "inf", "-inf", "x", "")),
    (shared.positive_float, {"0.1": 0.1, "1e-9": 1e-9}, ("0", "-1", "nan", "inf", "x")),
    (shared.nonnegative_float, {"0": 0.0, "2": 2.0}, ("-1e-9", "nan", "inf", "x")),
    (shared.int_at_least(1), {"1": 1, "40": 40}, ("0", "-1", "1.5", "x", "nan")),
    (verbs.seed_type, {"0": 0, "7": 7}, ("-1", "1.0", "x")),
])
def test_values_in_and_out_of_each_type(parse, good, bad):
    for text, value in good.items():
        out = parse(text)
        assert out == value and type(out) is type(value) and math.isfinite(out)
    for text in bad:
        with pytest.raises(argparse.ArgumentTypeError) as err:
            parse(text)
        assert text.lstrip("-") in str(err.value) or text == "", (text, str(err.value))
