"""One setting of a sweep (``Cell``) and the columns of its trial rows.

A cell's key hashes everything that changes a row except the trial count and the method list: the store
(``experiments.engine.store``) keeps the cell's rows under ``<results_dir>/<sweep>/trials/<key>/``, the trial
(``experiments.engine.trial``) computes them, the scheduler (``experiments.engine.runner``) runs the missing ones.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from calib_core import get_method
from calib_core.geometry.metrics import TRUTH_MAX_ROT_DEG, TRUTH_MAX_TRANS_M, VALID_MAX_ROT_DEG, VALID_MAX_TRANS_M
from simulate.options import hashed_settings

# Columns of a trial row after the settings columns (sweep, setting_key, seed, every SimOptions field).
RESULT_COLUMNS = (
    "trial", "method", "ok", "reason", "e_R_deg", "e_t_m", "valid", "n_candidates", "true_among_candidates",
    "some_candidate_valid", "best_candidate_e_R_deg", "best_candidate_e_t_m", "seconds",
    "crlb_rot_deg", "crlb_trans_mm", "conditioning", "nees", "sigma_rot_deg", "sigma_trans_mm",
    "n_wrong", "n_rejected", "wrong_caught", "good_lost", "code",
)
# Columns that legitimately differ between two runs of the same settings (wall time).
TIMING_COLUMNS = ("seconds",)
CODE_COLUMN = RESULT_COLUMNS[-1]
"""The column holding the fingerprint of the code that computed a row (``experiments.engine.fingerprint``), written by
the runner, last in every row; rows stored without it are stale (recomputed), not damaged."""


class RunnerError(RuntimeError):
    """A sweep cannot run (bad settings, unreadable results folder)."""


def _default_metrics() -> dict[str, Any]:
    return {"max_rot_deg": VALID_MAX_ROT_DEG, "max_trans_m": VALID_MAX_TRANS_M, "truth_rot_deg": TRUTH_MAX_ROT_DEG,
            "truth_trans_m": TRUTH_MAX_TRANS_M,
            "uncertainty": True, "crlb_sigma_mm": None}


@dataclass(frozen=True)
class Cell:
    """One setting of a sweep: simulator options, seed, trial count, methods and metric thresholds.

    ``sim`` holds ``simulate.SimOptions`` fields as plain values; ``method_options`` maps a method name to
    its ``calibrate`` keyword options; ``plugins`` are modules every worker imports before running (their
    methods join the registry; ``calib_core.plugins``). Neither the plugins nor the method list change the key.
    ``crn_stream``: common random numbers -- trial ``t`` draws the same random numbers in every cell with the
    same stream (``simulate.trial_rngs``); None: seeded by the settings.
    """

    sweep: str
    sim: dict[str, Any]
    seed: int = 0
    n_trials: int = 100
    methods: tuple[str, ...] = ()
    method_options: dict[str, dict[str, Any]] = field(default_factory=dict)
    metrics: dict[str, Any] = field(default_factory=_default_metrics)
    results_dir: str = "results"
    plugins: tuple[str, ...] = ()
    crn_stream: int | None = None

    @property
    def key(self) -> str:
        """Readable, stable folder name: board count, noise, and a hash of every setting that shapes a row."""
        payload = json.dumps({"sim": hashed_settings(self.sim), "seed": self.seed, "metrics": self.metrics,
                              "method_options": {m: self.method_options[m] for m in sorted(self.method_options)},
                              **({} if self.crn_stream is None else {"crn_stream": self.crn_stream})},
                             sort_keys=True, default=str)
        digest = hashlib.sha1(payload.encode()).hexdigest()[:10]
        parts = [f"nb{self.sim['n_boards']}" if "n_boards" in self.sim else "",
                 f"noise{self.sim['noise_mm']:g}mm" if "noise_mm" in self.sim else ""]
        return "-".join([p for p in parts if p] + [digest])

    @property
    def dir(self) -> Path:
        return Path(self.results_dir) / self.sweep / "trials" / self.key

    def columns(self) -> dict[str, Any]:
        """The settings columns every row of this cell carries."""
        return {"sweep": self.sweep, "setting_key": self.key, "seed": self.seed, **self.sim}

    def options_for(self, method: str) -> dict[str, Any]:
        return dict(self.method_options.get(method, {}))


def resolve_methods(names: Iterable[str]) -> tuple[str, ...]:
    """``names``, each registered or derivable (``X+ml``): CalibrationError otherwise."""
    out = [get_method(n).name for n in names]
    if not out:
        raise RunnerError("no method to run")
    return tuple(out)

