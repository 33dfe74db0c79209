"""Checks of a composed experiment config before any trial runs: every failure is one line naming the key.

Ranges of the simulator options are ``simulate.SimOptions``' own checks; here: known method names, known
options for each method (read from the method function's signature), counts, metric thresholds.
"""

from __future__ import annotations

import inspect
from typing import Any

from calib_core import CalibrationError, get_method
from calib_core.methods.suffixes import REFINE_OPTIONS
from calib_core.robust.scorers import PENG2022_OPTIONS


class ConfigError(CalibrationError, ValueError):
    """A config value that cannot run; the message names the key."""


def _solver_options() -> set[str]:
    from calib_core.solvers.vasconcelos import solve_triples

    sig = inspect.signature(solve_triples)
    return {p.name for p in sig.parameters.values() if p.kind is inspect.Parameter.KEYWORD_ONLY}


def method_options(name: str) -> set[str]:
    """The keyword options ``calibrate(obs, name, **options)`` accepts: the named parameters of the method
    function; where it takes ``**options``, those its documented sinks take (the minimal solver's keywords, the
    ``peng2022`` scorer's readings, the refinement options of an ``X+suffix`` variant and its base's options)."""
    m = get_method(name)
    base, plus, _ = name.rpartition("+")
    if plus and base:
        return set(REFINE_OPTIONS) | method_options(base)
    sig = inspect.signature(m.func)
    params = list(sig.parameters.values())[1:]        # the first is the observations
    out = {p.name for p in params if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)}
    if any(p.kind is p.VAR_KEYWORD for p in params):
        out |= _solver_options()
        if name.split("/")[0] == "peng2022":
            out |= set(PENG2022_OPTIONS)
    return out | {"verdict"}


def _need(cond: bool, key: str, msg: str) -> None:
    if not cond:
        raise ConfigError(f"config key '{key}': {msg}")


def check_methods(names, options: dict[str, Any]) -> None:
    """Known method names; options only for configured methods, each option known to its method."""
    _need(len(names) > 0, "methods.names", "no method to run")
    for n in names:
        try:
            get_method(str(n))
        except CalibrationError as err:
            raise ConfigError(f"config key 'methods.names': {err}") from None
    for m, opts in (options or {}).items():
        _need(m in names, f"methods.options.{m}", f"options for a method that is not run (methods.names: "
                                                  f"{', '.join(map(str, names))})")
        _need(isinstance(opts, dict), f"methods.options.{m}", "must map option names to values")
        unknown = sorted(set(opts) - method_options(m))
        _need(not unknown, f"methods.options.{m}", f"unknown option(s) {unknown}; {m} takes "
                                                   f"{', '.join(sorted(method_options(m)))}")


def check_run(cfg) -> None:
    """Counts and thresholds of the run itself."""
    _need(isinstance(cfg.n_trials, int) and cfg.n_trials > 0, "n_trials", f"must be a positive integer, got "
                                                                          f"{cfg.n_trials!r}")
    _need(isinstance(cfg.seed, int) and cfg.seed >= 0, "seed", f"must be a non-negative integer, got {cfg.seed!r}")
    _need(cfg.n_jobs != 0, "n_jobs", "must be positive (workers) or negative (all cores + 1 + n_jobs), not 0")
    _need(cfg.chunk_size >= 0, "chunk_size", f"must be >= 0 (0: automatic), got {cfg.chunk_size}")
    _need(bool(str(cfg.sweep).strip()) and "/" not in str(cfg.sweep), "sweep", f"must be a folder name, got "
                                                                                f"{cfg.sweep!r}")
    for k in ("max_rot_deg", "max_trans_m", "truth_rot_deg", "truth_trans_m"):
        _need(cfg.metrics[k] > 0, f"metrics.{k}", f"must be > 0, got {cfg.metrics[k]}")
    s = cfg.metrics.get("crlb_sigma_mm")
    _need(s is None or s > 0, "metrics.crlb_sigma_mm", f"must be > 0 or null, got {s}")


def sim_error_key(msg: str, groups: dict[str, str]) -> str:
    """``SimOptions: n_boards must be >= 1, ...`` -> ``config key 'scene.n_boards': must be >= 1, ...``."""
    body = msg.removeprefix("SimOptions: ")
    for name, group in groups.items():
        if body.startswith(name + " ") or body.startswith(f"need 0 < {name}") or f" {name} " in body[:40]:
            return f"config key '{group}.{name}': {body}"
    return f"config: {body}"
