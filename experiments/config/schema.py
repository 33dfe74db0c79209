"""Structured configs of the experiments, registered in Hydra's ConfigStore.

The simulation part has one schema, ``simulate.SimOptions`` (flat, one primitive per field). The config
groups split its fields by concern -- ``scene`` (boards, placement, the rig's true extrinsic), ``lidar``
(``lidar_*``), ``camera`` (image size, intrinsics, how board poses are measured) and ``noise`` (every
``*noise*`` field) -- under the fields' own names, so ``scene.n_boards`` is ``SimOptions.n_boards``. The group
dataclasses are generated from ``SimOptions``: its defaults and types are the only copy, and a field the
simulator adds shows up in its group without an edit here.
"""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass, field
from typing import Any

from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf

from calib_core.geometry.metrics import TRUTH_MAX_ROT_DEG, TRUTH_MAX_TRANS_M, VALID_MAX_ROT_DEG, VALID_MAX_TRANS_M
from simulate import SimOptions

from ..engine.catalog import PAPER_METHODS

SIM_GROUPS = ("scene", "lidar", "camera", "noise")
_CAMERA_PREFIXES = ("cam_", "focal_", "image_", "render_", "pose_", "pixel_", "min_depth", "principal_", "distortion_",
                    "std_intrinsics")



def sim_group_of(name: str) -> str:
    """The config group that holds the SimOptions field ``name``."""
    if "noise" in name:
        return "noise"
    if name.startswith("lidar_"):
        return "lidar"
    if name.startswith(_CAMERA_PREFIXES):
        return "camera"
    return "scene"


def _group_schema(group: str) -> type:
    hints = typing.get_type_hints(SimOptions)
    spec = [(f.name, hints[f.name], field(default=f.default))
            for f in dataclasses.fields(SimOptions) if sim_group_of(f.name) == group]
    return dataclasses.make_dataclass(f"{group.capitalize()}Conf", spec)


SceneConf = _group_schema("scene")
LidarConf = _group_schema("lidar")
CameraConf = _group_schema("camera")
NoiseConf = _group_schema("noise")


@dataclass
class MethodsConf:
    """Which registered methods run on every trial (all on the same simulated data).

    ``names`` must be registered (an unknown name is a config error); ``options`` maps a method name to keyword
    options of ``calib_core.calibrate``; ``plugins`` are modules imported first (in every worker too) whose
    methods join the registry (``methods.plugins=[my_lab.my_method]``; installed ``lidarcam.methods`` entry
    points are always loaded, see ``calib_core.plugins``).
    """

    names: list[str] = field(default_factory=lambda: list(PAPER_METHODS))
    plugins: list[str] = field(default_factory=list)
    options: dict[str, Any] = field(default_factory=dict)


@dataclass
class MetricsConf:
    """Thresholds of the per-trial metrics.

    A result is valid when ``e_R < max_rot_deg`` and ``e_t < max_trans_m`` (paper eq. 13-14: 8 deg, 0.8 m).
    The truth is among the candidates when some candidate has ``e_R < truth_rot_deg`` and
    ``e_t < truth_trans_m``. ``uncertainty``: add the CRLB and conditioning columns; the CRLB uses
    ``crlb_sigma_mm`` or, when null, the trial's ``noise_mm``.
    """

    max_rot_deg: float = VALID_MAX_ROT_DEG
    max_trans_m: float = VALID_MAX_TRANS_M
    truth_rot_deg: float = TRUTH_MAX_ROT_DEG
    truth_trans_m: float = TRUTH_MAX_TRANS_M
    uncertainty: bool = True
    crlb_sigma_mm: float | None = None


@dataclass
class ExperimentConfig:
    """The whole run: simulation groups, methods, metrics, and how to execute.

    ``sweep`` names the results folder ``<results_dir>/<sweep>/``; ``n_trials`` trials ``0..n_trials-1`` per
    setting, data seeded by ``(seed, trial, settings)``; ``n_jobs`` joblib workers over trials (-1: all cores);
    ``chunk_size`` trials per task and per results file (0: automatic). ``crn_stream``: common random numbers
    (the same draws per trial index in every setting, ``simulate.trial_rngs``); null: seeded by the settings.
    """

    scene: SceneConf = field(default_factory=SceneConf)  # type: ignore[valid-type]
    lidar: LidarConf = field(default_factory=LidarConf)  # type: ignore[valid-type]
    camera: CameraConf = field(default_factory=CameraConf)  # type: ignore[valid-type]
    noise: NoiseConf = field(default_factory=NoiseConf)  # type: ignore[valid-type]
    methods: MethodsConf = field(default_factory=MethodsConf)
    metrics: MetricsConf = field(default_factory=MetricsConf)
    sweep: str = "default"
    n_trials: int = 100
    seed: int = 0
    n_jobs: int = -1
    chunk_size: int = 0
    results_dir: str = "results"
    progress: bool = True
    crn_stream: int | None = None


def register_configs() -> None:
    """Store the schemas: ``base_config`` (the primary schema) and ``base_<group>`` in each SimOptions group."""
    cs = ConfigStore.instance()
    cs.store(name="base_config", node=ExperimentConfig)
    for group, schema in zip(SIM_GROUPS, (SceneConf, LidarConf, CameraConf, NoiseConf), strict=True):
        cs.store(group=group, name=f"base_{group}", node=schema)
    cs.store(group="methods", name="base_methods", node=MethodsConf)


def sim_options(cfg: DictConfig) -> SimOptions:
    """The ``SimOptions`` of a composed config: the union of the four simulation groups."""
    kwargs: dict[str, Any] = {}
    for group in SIM_GROUPS:
        kwargs.update(OmegaConf.to_container(cfg[group], resolve=True))
    return SimOptions(**kwargs)


register_configs()


def cell_from_cfg(cfg: DictConfig):
    """The runner's ``Cell`` of a composed config: its plugins loaded, then validated (``experiments.config.validate``:
    ConfigError naming the key; the simulator options by ``SimOptions``)."""
    from calib_core.plugins import load_plugins

    from ..engine.cell import Cell, resolve_methods
    from .validate import ConfigError, check_methods, check_run, sim_error_key

    plugins = tuple(str(p) for p in cfg.methods.get("plugins", None) or ())
    load_plugins(plugins)
    check_run(cfg)
    try:
        sim = dataclasses.asdict(sim_options(cfg))
    except (TypeError, ValueError) as err:
        groups = {f.name: sim_group_of(f.name) for f in dataclasses.fields(SimOptions)}
        raise ConfigError(sim_error_key(str(err), groups)) from None
    options = OmegaConf.to_container(cfg.methods.options, resolve=True) or {}
    check_methods(list(cfg.methods.names), options)
    methods = resolve_methods(cfg.methods.names)
    return Cell(sweep=str(cfg.sweep), sim=sim, seed=int(cfg.seed), n_trials=int(cfg.n_trials), methods=methods,
                method_options={m: dict(options[m]) for m in methods if options.get(m)}, plugins=plugins,
                metrics=OmegaConf.to_container(cfg.metrics, resolve=True), results_dir=str(cfg.results_dir),
                crn_stream=None if cfg.crn_stream is None else int(cfg.crn_stream))
