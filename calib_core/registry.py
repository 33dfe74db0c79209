"""The table of calibration methods: name, minimum boards, citation, summary, origin and function, read by the
CLI, the experiments and the README instead of if-chains on method names.

The table is filled explicitly: ``calib_core.methods.register_builtins`` adds the project's methods when
``calib_core`` is imported; plugins add theirs with ``register`` (see ``calib_core.plugins``).
"""

from __future__ import annotations

import difflib
import inspect
from collections.abc import Callable
from dataclasses import dataclass, replace

from .errors import CalibrationError


@dataclass(frozen=True)
class Method:
    """One registered method.

    ``func(obs, **options) -> (T_lidar_cam 4x4, candidates (M,4,4), info dict)``; it raises
    ``SolveFailure`` with a reason when it cannot solve. An ``info["covariance"]`` (6x6) becomes the result's
    covariance. ``origin`` says where the method comes from (``"lidarcam"`` for the project's own, else the
    plugin's module or entry point); ``cost`` says how its run time grows with the number of boards N.
    ``paper``: one of the paper's methods (or an ablation of one): its answer stands as its paper computes it, the
    verdict is reported beside it and never turns it into ``ok=False``; every other method (ours, a derived
    ``X+ml``, a plugin) is held to the verdict.
    ``options``: the keyword options ``calibrate(obs, name, **options)`` accepts, declared once here (None: the
    named keyword parameters of ``func``, as for a plugin that declares none); ``calibrate``, the experiments'
    config validation and ``lidarcam methods`` all read ``accepted_options``. ``takes_prior``: the method takes a
    mounting prior (``calibrate(..., prior=...)``).
    """

    name: str
    func: Callable
    min_boards: int
    citation: str
    summary: str
    origin: str = "lidarcam"
    cost: str = ""
    paper: bool = False
    options: frozenset[str] | None = None
    takes_prior: bool = False


RENAMED_OPTIONS = {"f_scale": "f_scale_m (metres) or f_scale_sigmas (range-noise stds)",
                   "min_conditioning": "null_conditioning (the refusal threshold; the warning's MIN_CONDITIONING is "
                                       "fixed)"}
"""Option names that meant two things, and the names that replaced them (a call with the old one is refused
with this hint rather than read one way)."""


def accepted_options(method: Method) -> frozenset[str] | None:
    """The keyword options ``method`` accepts: its declared ``options``, else the named keyword parameters of its
    function after the observations; None when it declares none and takes ``**keywords`` (any name)."""
    if method.options is not None:
        return method.options
    params = list(inspect.signature(method.func).parameters.values())[1:]
    if any(q.kind is q.VAR_KEYWORD for q in params):
        return None
    return frozenset(q.name for q in params if q.kind in (q.KEYWORD_ONLY, q.POSITIONAL_OR_KEYWORD))


def check_options(method: Method, names) -> None:
    """CalibrationError naming the first option of ``names`` that ``method`` does not accept, with the accepted
    ones listed (a renamed option: its new name)."""
    accepted = accepted_options(method)
    for key in names:
        if key in RENAMED_OPTIONS:
            raise CalibrationError(f"{method.name}: option {key!r} is now {RENAMED_OPTIONS[key]}")
        if accepted is not None and key not in accepted:
            raise CalibrationError(f"{method.name}: unknown option {key!r}; it takes "
                                   f"{', '.join(sorted(accepted)) or 'no options'}")


METHODS: dict[str, Method] = {}
"""Every registered method by name (read-only for callers: use ``register``)."""

SUFFIXES: dict[str, Callable[[Method], Method]] = {}
"""Method-name suffixes (``"ml"`` for ``X+ml``, ...): each makes a derived method from its base method. A name
``X+s`` that is not in ``METHODS`` is built by ``get_method`` from ``X`` and ``SUFFIXES[s]``."""


def register(method: Method) -> Method:
    """Add ``method`` to ``METHODS``; CalibrationError if its name is taken."""
    if method.name in METHODS:
        raise CalibrationError(f"method {method.name!r} is already registered (from {METHODS[method.name].origin})")
    METHODS[method.name] = method
    return method


def register_suffix(suffix: str, factory: Callable[[Method], Method]) -> None:
    """Declare the suffix ``+suffix``: ``factory(base)`` makes ``base.name + "+" + suffix``."""
    SUFFIXES[suffix] = factory


def get_method(name: str) -> Method:
    """The method ``name``: a registered one, or ``X+s`` built from ``X`` and a known suffix ``s`` (not stored);
    CalibrationError listing the known names otherwise."""
    if name in METHODS:
        return METHODS[name]
    base, plus, suffix = name.rpartition("+")
    if plus and suffix in SUFFIXES:
        try:
            return SUFFIXES[suffix](get_method(base))
        except CalibrationError:
            pass
    close = difflib.get_close_matches(name, [*METHODS, *(f"{m}+{s}" for m in METHODS if "+" not in m
                                                          for s in SUFFIXES)], n=1)
    hint = f"did you mean {close[0]!r}? " if close else ""
    raise CalibrationError(f"unknown method {name!r}; {hint}known: {', '.join(n for n in METHODS if '+' not in n)} "
                           f"and X+{'/X+'.join(SUFFIXES)} for any X")


def derived(base: Method, suffix: str, func: Callable, summary: str, own_options) -> Method:
    """A method derived from ``base`` under ``base.name + "+" + suffix`` (same minimum boards and citation; ours,
    so not ``paper``): it takes ``own_options`` and passes every other option on to ``base`` (whose schema it
    extends; a base that accepts any name keeps that). It takes no prior."""
    base_options = accepted_options(base)
    options = None if base_options is None else frozenset(own_options) | base_options
    return replace(base, name=f"{base.name}+{suffix}", func=func, summary=summary, paper=False, options=options,
                   takes_prior=False)
