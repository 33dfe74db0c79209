"""No committed report, figure source, doc or the README holds an absolute path of the machine that wrote it; the
generators write repo-relative paths (``experiments.engine.paths.repo_relative``)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

from experiments.engine.paths import ROOT, repo_relative

MACHINE = re.compile(r"(?<![\w.])/(?:work|root|home|Users|mnt|tmp)/[\w.-]")
"""An absolute path under a folder where a checkout or a scratch file lives."""
TEXT = (".md", ".json", ".csv", ".yaml", ".txt", ".tex", ".html")
COMMAND = re.compile(r"\b(?:lidarcam|python -m|make|time)\s")
"""A command the reader types: a scratch folder of theirs (``lidarcam demo /tmp/demo``) is not a machine's path."""


def _tracked(*where: str) -> list[Path]:
    out = subprocess.run(["git", "ls-files", "--", *where], cwd=ROOT, capture_output=True, text=True, check=True)
    return [ROOT / f for f in out.stdout.split()]


def test_no_tracked_result_doc_or_readme_holds_a_machine_path():
    bad = []
    for f in _tracked("results", "docs", "README.md"):
        if f.suffix not in TEXT or not f.is_file():
            continue
        in_results = f.relative_to(ROOT).parts[0] == "results"
        for i, line in enumerate(f.read_text(errors="replace").splitlines(), 1):
            for m in MACHINE.finditer(line):
                scratch = m.group(0).startswith("/tmp/") and COMMAND.search(line)
                if in_results or not scratch or str(ROOT) in line:
                    bad.append(f"{f.relative_to(ROOT)}:{i}: {line.strip()[:120]}")
    assert not bad, "\n".join(bad[:20])


def test_repo_relative_never_writes_an_absolute_path(tmp_path):
    assert repo_relative(ROOT / "results" / "real") == "results/real"
    assert repo_relative(ROOT.parent / "shared" / "real-data") == "../shared/real-data"
    outside = tmp_path / "rec120"
    assert not Path(repo_relative(outside)).is_absolute()
    if ROOT.parent not in outside.parents:
        assert repo_relative(outside) == "rec120"


def test_no_wheel_or_other_build_artefact_is_tracked():
    assert not [f for f in _tracked() if f.suffix == ".whl"]


def test_the_docs_commands_write_only_where_git_ignores():
    """docs/real-rigs.md's commands leave no untracked folder in the checkout: their outputs are ignored."""
    text = (ROOT / "docs" / "real-rigs.md").read_text()
    outs = sorted(set(re.findall(r"--(?:out|yaml) (work/[\w./-]+)", text)))
    assert outs, "no --out under work/ in docs/real-rigs.md"
    r = subprocess.run(["git", "check-ignore", "--no-index", *outs], cwd=ROOT, capture_output=True, text=True)
    assert sorted(r.stdout.split()) == outs, set(outs) - set(r.stdout.split())
