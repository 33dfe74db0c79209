"""The table of calibration methods: name, minimum boards, citation and function, read by the CLI,
the experiments and the README instead of if-chains on method names."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from .errors import CalibrationError


@dataclass(frozen=True)
class Method:
    """One registered method.

    ``func(obs, **options) -> (T_lidar_cam 4x4, candidates (M,4,4), info dict)``; it raises
    ``SolveFailure`` with a reason when it cannot solve.
    """

    name: str
    func: Callable
    min_boards: int
    citation: str
    summary: str


METHODS: dict[str, Method] = {}


def register(name: str, *, min_boards: int, citation: str, summary: str):
    """Decorator adding a method function to ``METHODS`` under ``name``."""
    def wrap(func):
        if name in METHODS:
            raise CalibrationError(f"method {name!r} registered twice")
        METHODS[name] = Method(name, func, min_boards, citation, summary)
        return func
    return wrap


def get_method(name: str) -> Method:
    """The registered method ``name``; CalibrationError listing the known names otherwise."""
    try:
        return METHODS[name]
    except KeyError:
        raise CalibrationError(f"unknown method {name!r}; known: {', '.join(METHODS)}") from None
