"""Hydra entry of the Monte-Carlo runner: one setting, or a sweep with ``-m``.

    python -m experiments.run scene.n_boards=6 n_trials=20
    python -m experiments.run -m experiment=boards                    # the paper's Fig. 3a, 4, 5
    python -m experiments.run -m experiment=boards scene.n_boards=3,4,5
    python -m experiments.run -m experiment=noise                     # the paper's Fig. 3b, 6, 7

Rows land in ``<results_dir>/<sweep>/trials/<setting-key>/``; re-running resumes. Then
``python -m experiments aggregate`` (tables), ``experiments.summary.figures``, ``experiments.paper.report``.
"""

from __future__ import annotations

import sys

import hydra
from omegaconf import DictConfig

from calib_core.errors import LidarcamError

from .config.schema import cell_from_cfg, register_configs
from .config.validate import ConfigError
from .engine.runner import run_cells

register_configs()


def summary_line(df) -> str:
    """``method valid/n`` for each method of a cell's rows."""
    if df.empty:
        return "no rows"
    g = df.groupby("method", sort=False)["valid"].agg(["sum", "size"])
    return ", ".join(f"{m} {int(r['sum'])}/{int(r['size'])} valid" for m, r in g.iterrows())


@hydra.main(version_base="1.3", config_path="../conf", config_name="config")
def main(cfg: DictConfig) -> float:
    try:
        cell = cell_from_cfg(cfg)
    except ConfigError as err:  # one line, no traceback: the config, not the code, is wrong
        print(f"error: {err}", file=sys.stderr)
        sys.exit(2)
    except LidarcamError as err:  # a plugin that does not load: one line, exit 2
        print(f"experiments.run: error: {err}", file=sys.stderr)
        sys.exit(2)
    df = run_cells([cell], n_jobs=cfg.n_jobs, chunk_size=cfg.chunk_size, progress=cfg.progress,
                   label=f"{cell.sweep} {cell.key}")
    print(f"{cell.dir}: {summary_line(df)}")
    return float(df["valid"].mean()) if not df.empty else 0.0


def check_argv(argv) -> None:
    """The command line's overrides checked before Hydra composes them (``experiments.config.overrides``)."""
    from hydra import compose, initialize_config_dir

    from .config.overrides import check_overrides
    from .config.sweeps import CONF_DIR

    overrides = [a for a in argv if "=" in a and not a.startswith("-")]
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        check_overrides(overrides, lambda choices: compose(config_name="config", overrides=choices), CONF_DIR)


if __name__ == "__main__":
    from .engine.entry import run_main

    run_main(lambda: check_argv(sys.argv[1:]) or main())
