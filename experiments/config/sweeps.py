"""The sweeps of ``conf/experiment/``: the config folder, a basic sweeper's ``params`` expanded as ``-m`` would, and
the cells of an experiment (one per point of its sweep). Every study composes its cells here."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import HydraException
from omegaconf.errors import OmegaConfBaseException

from ..engine.cell import Cell
from .overrides import check_overrides, composition_error, override_key
from .schema import cell_from_cfg, register_configs
from .validate import ConfigError

CONF_DIR = Path(__file__).resolve().parents[2] / "conf"
"""The Hydra config folder of the project (``conf/``)."""


def expand_sweep_params(params) -> list[list[str]]:
    """The override lists of a basic-sweeper ``params`` mapping (cartesian product, as ``-m`` runs them)."""
    if not params:
        return [[]]
    parser = OverridesParser.create()
    axes = []
    for key, value in params.items():
        (ov,) = parser.parse_overrides([f"{key}={value}"])
        axes.append([f"{ov.get_key_element()}={v}" for v in ov.sweep_string_iterator()]
                    if ov.is_sweep_override() else [f"{key}={value}"])
    return [list(combo) for combo in itertools.product(*axes)]


def experiment_cells(experiment: str, overrides: Sequence[str] = ()) -> list[Cell]:
    """The cells of ``experiment`` (one per point of its sweep) with ``overrides`` applied to each."""
    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        base = [f"experiment={experiment}", *overrides]
        check_overrides(base, lambda choices: compose(config_name="config", overrides=choices), CONF_DIR)
        try:
            cfg = compose(config_name="config", overrides=base, return_hydra_config=True)
            swept = {override_key(o) for o in overrides}
            params = {k: v for k, v in (cfg.hydra.sweeper.params or {}).items() if k not in swept}
            return [cell_from_cfg(compose(config_name="config", overrides=[*base, *combo]))
                    for combo in expand_sweep_params(params)]
        except (HydraException, OmegaConfBaseException) as err:
            raise ConfigError(composition_error(err)) from None
