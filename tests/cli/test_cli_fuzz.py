"""The command line's hostile-input corpus (``tests/cli_fuzz_corpus.py``): every error case ends in exit 2 with one
line ``lidarcam VERB: error: ...`` naming the file, flag or field, every answer case in exit 0 or 1 with no ``nan``
printed; no traceback, no RuntimeWarning."""

from __future__ import annotations

import warnings

import pytest
from cli_fuzz_corpus import CASES, PREPARE, make_sources

from lidarcam.cli import main


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    return make_sources(tmp_path_factory.mktemp("cli_sources"))


def test_the_corpus_covers_every_verb_it_names():
    assert len(CASES) >= 30 and len({c.name for c in CASES}) == len(CASES)
    assert {c.argv[0] for c in CASES} >= {"import", "plan", "bag", "calibrate", "demo", "simulate", "report"}
    assert {c.expect for c in CASES} == {"error", "answer"} and all(c.names for c in CASES if c.expect == "error")


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.name)
def test_cli_case_is_one_error_line(case, sources, tmp_path, capsys):
    import shutil

    root = tmp_path / "S"
    shutil.copytree(sources, root)
    if case.prepare:
        PREPARE[case.prepare](root)
    argv = [a.replace("{S}", str(root)) for a in case.argv]
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        try:
            code = main(argv)
        except SystemExit as ex:  # argparse's own errors
            code = ex.code
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    if case.expect == "answer":
        assert code in (0, 1) and "Traceback" not in err, (code, err[-500:], out[-300:])
        assert "nan" not in (out + err).lower().replace("nanoseconds", ""), out[-500:]
        return
    assert case.expect == "error"
    assert code == 2, (code, err[-500:], out[-300:])
    assert len(lines) == 1 and f"lidarcam {argv[0]}" in lines[0] and "error:" in lines[0], err
    assert case.names in lines[0], lines[0]
