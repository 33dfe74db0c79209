"""Checks of a composed experiment config before any trial runs: every failure is one line naming the key.

Ranges of the simulator options are ``simulate.SimOptions``' own checks; here: known method names, known
options for each method (the registry's schema, as ``calibrate`` reads it), counts, metric thresholds.
"""

from __future__ import annotations

from typing import Any

from calib_core import CalibrationError, get_method
from calib_core.registry import accepted_options, check_options


class ConfigError(CalibrationError, ValueError):
    """A config value that cannot run; the message names the key."""


def method_options(name: str) -> set[str] | None:
    """The keyword options ``calibrate(obs, name, **options)`` accepts (the registry's schema,
    ``calib_core.registry.accepted_options``; None: any name), plus ``verdict``."""
    accepted = accepted_options(get_method(name))
    return None if accepted is None else set(accepted) | {"verdict"}


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
        try:
            check_options(get_method(m), set(opts) - {"verdict"})
        except CalibrationError as err:
            raise ConfigError(f"config key 'methods.options.{m}': {err}") from None


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
