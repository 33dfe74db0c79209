"""``make help`` states a duration for every target (measured, or "not measured" with why), and each target's
help line is what ``make help`` prints."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DURATION = re.compile(r"~\s?[\d.]+(-[\d.]+)?\s?(s|min)\b|< ?1 s|not measured")


def _targets() -> dict[str, str]:
    out = {}
    for line in (ROOT / "Makefile").read_text().splitlines():
        if m := re.match(r"^([a-zA-Z_-]+):.*## (.*)$", line):
            out[m.group(1)] = m.group(2)
    return out


def test_every_target_states_its_duration():
    targets = _targets()
    assert {"test", "bench", "reproduce-paper", "rig-like", "real-data", "verify-results"} <= set(targets)
    missing = [t for t, text in targets.items() if t != "help" and not DURATION.search(text)]
    assert missing == []
