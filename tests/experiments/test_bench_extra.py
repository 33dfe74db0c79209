"""``pip install '.[bench]'`` runs the benchmark: with only the base install and the ``[bench]`` extra's modules
importable (its requirements resolved, ``lidarcam[rig]`` included), every study imports and a simulated trial runs."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
EXTRAS = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
MODULES = {"opencv-python-headless": {"cv2"}, "pyyaml": {"yaml"}, "rosbags": {"rosbags"},
           "rosbags-image": {"rosbags_image"}, "matplotlib": {"matplotlib", "PIL"}, "hydra-core": {"hydra"},
           "omegaconf": {"omegaconf"}, "pandas": {"pandas"}, "joblib": {"joblib"}}
"""The modules an extra's distributions bring (those the project imports)."""


def extra_modules(name: str) -> set[str]:
    out: set[str] = set()
    for req in EXTRAS[name]:
        if m := re.fullmatch(r"lidarcam\[([\w,]+)\]", req.strip()):
            out |= set().union(*(extra_modules(e) for e in m.group(1).split(",")))
        else:
            out |= MODULES.get(re.split(r"[<>=!~\[ ;]", req, maxsplit=1)[0].lower(), set())
    return out


RUN = textwrap.dedent("""
    import importlib, sys
    BLOCK = set(sys.argv[1].split(","))
    class Blocker:  # an installation of lidarcam[bench] only
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCK:
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)
    sys.meta_path.insert(0, Blocker())
    from experiments.__main__ import STUDIES
    for module, _ in STUDIES.values():
        importlib.import_module(f"experiments.{module}")
    from experiments.engine.cell import Cell
    from experiments.engine.trial import simulate_trial
    rows = simulate_trial(Cell("x", {"n_boards": 4, "noise_mm": 10.0}, methods=("peng2022",)), 0, ("peng2022",))
    print(rows[0]["ok"])
""")


def test_the_bench_extra_runs_every_study_and_a_trial():
    every = set().union(*MODULES.values())
    block = every - extra_modules("bench")
    out = subprocess.run([sys.executable, "-c", RUN, ",".join(sorted(block)) or "none"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "True", out.stderr[-2000:]
