"""``lidarcam --help`` names, for each verb, the extra it needs where that extra is not installed (an installation
without ``[rig]``: every verb but ``methods`` and ``calibrate``), and names none where everything is installed."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

BLOCKED = textwrap.dedent("""
    import sys
    BLOCK = {"cv2", "yaml", "rosbags", "matplotlib", "PIL"}
    class Blocker:  # an installation without lidarcam[rig]
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCK:
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)
    sys.meta_path.insert(0, Blocker())
    from lidarcam.cli import main
    sys.exit(main(sys.argv[1:]))
""")


def _verb_lines(text: str) -> dict[str, str]:
    """verb -> its (joined) help line in ``lidarcam --help``."""
    block = text[text.index("VERB\n") + 5:text.index("\noptions:")]
    out: dict[str, str] = {}
    verb = None
    for ln in block.splitlines():
        m = re.match(r"\s{4}(\w+)\s+(.*)", ln)
        if m and len(ln) - len(ln.lstrip()) == 4:
            verb = m.group(1)
            out[verb] = m.group(2)
        elif verb:
            out[verb] += " " + ln.strip()
    return out


def test_help_without_the_rig_extra_names_it_for_every_verb_that_needs_it():
    r = subprocess.run([sys.executable, "-c", BLOCKED, "--help"], capture_output=True, text=True, timeout=120,
                       env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "COLUMNS": "200"})
    assert r.returncode == 0, r.stderr[-800:]
    lines = _verb_lines(r.stdout)
    needing = {"simulate", "extract", "report", "import", "bag", "demo", "plan"}
    assert needing | {"methods", "calibrate"} <= set(lines), lines
    for verb in needing:
        assert "needs lidarcam[rig]" in lines[verb] and "pip install 'lidarcam[rig]'" in lines[verb], lines[verb]
    for verb in ("methods", "calibrate"):
        assert "needs" not in lines[verb], lines[verb]
    assert "--from OBS.json alone runs without" in lines["plan"]


def test_help_with_everything_installed_names_no_extra(capsys):
    import pytest

    from lidarcam.cli import main

    with pytest.raises(SystemExit):
        main(["--help"])
    assert "needs lidarcam[" not in capsys.readouterr().out
