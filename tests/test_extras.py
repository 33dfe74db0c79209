"""``pip install lidarcam`` is the library (numpy, scipy); ``[rig]`` and ``[bench]`` add the rest, ``[dev]`` all of
it; the CLI without ``[rig]`` runs the verbs that need nothing more and names the extra for the others."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def _names(reqs) -> set[str]:
    import re

    return {re.split(r"[<>=!~\[ ;]", r, maxsplit=1)[0].lower() for r in reqs}


def test_the_base_install_is_numpy_and_scipy():
    assert _names(PYPROJECT["project"]["dependencies"]) == {"numpy", "scipy"}


def test_the_extras_hold_the_rig_and_bench_stacks_and_dev_holds_everything():
    extras = PYPROJECT["project"]["optional-dependencies"]
    assert {"opencv-python-headless", "pyyaml", "rosbags", "rosbags-image", "matplotlib"} <= _names(extras["rig"])
    assert {"hydra-core", "pandas", "joblib", "matplotlib"} <= _names(extras["bench"])
    dev = " ".join(extras["dev"])
    assert "lidarcam[rig,bench]" in dev and {"pytest", "ruff"} <= _names(extras["dev"])
    assert not any(p.startswith("experiments") for p in PYPROJECT["tool"]["setuptools"]["packages"]["find"]["include"])


BLOCKED = textwrap.dedent("""
    import sys
    BLOCK = {"cv2", "yaml", "rosbags", "matplotlib", "PIL", "hydra", "omegaconf", "pandas", "joblib"}
    class Blocker:  # an installation without the extras
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCK:
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)
    sys.meta_path.insert(0, Blocker())
    from lidarcam.cli import main
    sys.exit(main(sys.argv[1:]))
""")


def _lidarcam_without_extras(*argv: str, cwd: Path):
    return subprocess.run([sys.executable, "-c", BLOCKED, *argv], cwd=cwd, capture_output=True, text=True,
                          timeout=120, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})


@pytest.fixture(scope="module")
def obs_file(tmp_path_factory):
    from lidarcam.cli import main

    path = tmp_path_factory.mktemp("extras") / "obs.json"
    assert main(["simulate", "--boards", "6", "--seed", "1", "--out", str(path)]) == 0
    return path


def test_the_library_verbs_run_without_the_extras(obs_file):
    for argv in (["methods"], ["calibrate", str(obs_file), "--out", str(obs_file.parent / "r.json")]):
        r = _lidarcam_without_extras(*argv, cwd=obs_file.parent)
        assert r.returncode == 0, r.stderr[-800:]


@pytest.mark.parametrize("argv", [["simulate", "--boards", "6", "--out", "s.json"],
                                  ["report", "obs.json", "r.json", "--out", "rep"],
                                  ["plan", str(ROOT / "conf" / "plan" / "rig.yaml")],
                                  ["demo", "demo"]])
def test_a_verb_of_a_missing_extra_is_one_line_naming_it(argv, obs_file):
    r = _lidarcam_without_extras(*argv, cwd=obs_file.parent)
    assert r.returncode == 2, r.stderr[-800:]
    assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr, r.stderr[-800:]
    assert "pip install 'lidarcam[rig]'" in r.stderr
