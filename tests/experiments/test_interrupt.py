"""Ctrl-C in a sweep: one line saying how far it got and that the same command resumes, exit status 130; a
mistyped Hydra key or group option is one line with the closest name."""

from __future__ import annotations

import pytest
from hydra import compose, initialize_config_dir

from experiments.config.overrides import check_overrides
from experiments.config.schema import register_configs
from experiments.config.sweeps import CONF_DIR
from experiments.config.validate import ConfigError
from experiments.engine.cell import Cell
from experiments.engine.entry import EXIT_INTERRUPTED, SweepInterrupted, run_main
from experiments.engine.runner import run_cells


def _trial_interrupted_at(stop: int):
    def trial(cell, t, methods):
        if t == stop:
            raise KeyboardInterrupt
        return [{**cell.columns(), "trial": t, "method": m, "ok": True, "reason": "", "valid": True}
                for m in methods]
    return trial


def test_an_interrupted_sweep_says_how_far_it_got_and_resumes(tmp_path, capsys):
    cell = Cell("ctrlc", {"n_boards": 5, "noise_mm": 20.0}, n_trials=6, methods=("m",), results_dir=str(tmp_path))
    with pytest.raises(SweepInterrupted, match="interrupted after 2 of 6 trials; the same command resumes"):
        run_cells([cell], n_jobs=1, chunk_size=1, trial_fn=_trial_interrupted_at(2), progress=False)
    df = run_cells([cell], n_jobs=1, chunk_size=1, trial_fn=_trial_interrupted_at(-1), progress=False)
    assert len(df) == 6 and "2 rows reused, 0 recomputed, 4 new" in capsys.readouterr().err


def test_run_main_exits_130_with_one_line(capsys):
    def main():
        raise SweepInterrupted("interrupted after 3 of 9 trials; the same command resumes")

    with pytest.raises(SystemExit) as exc:
        run_main(main, prog="sweep")
    assert exc.value.code == EXIT_INTERRUPTED
    assert capsys.readouterr().err == "sweep: interrupted after 3 of 9 trials; the same command resumes\n"


@pytest.mark.parametrize("override, needle", [
    ("scene.n_board=3", "unknown key 'scene.n_board'; did you mean 'scene.n_boards'?"),
    ("n_trial=3", "did you mean 'n_trials'?"),
    ("experiment=boardz", "no option 'boardz' in config group 'experiment'; did you mean 'boards'?"),
    ("noise.noise=3", "did you mean 'noise.noise_mm'?"),
])
def test_a_mistyped_hydra_override_is_one_line_with_the_closest_key(override, needle):
    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        with pytest.raises(ConfigError) as err:
            check_overrides([override], lambda ch: compose(config_name="config", overrides=ch), CONF_DIR)
        check_overrides(["scene.n_boards=3,4", "experiment=boards", "+methods.options.x.y=1"],
                        lambda ch: compose(config_name="config", overrides=ch), CONF_DIR)
    assert needle in str(err.value) and "\n" not in str(err.value)
