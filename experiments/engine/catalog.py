"""The methods the experiments compare, their display names and their fixed colours (one per method,
the same in every figure)."""

from __future__ import annotations

import zlib

# The paper's comparison, and ours plus the refined variants (these join a run only when registered).
PAPER_METHODS = ("zhang_pless_linear", "zhang_pless", "vasconcelos", "peng2022")
OPTIONAL_METHODS = ("lidarcam", "peng2022+ml", "vasconcelos+ml", "vasconcelos_msac", "vasconcelos_msac_refined",
                    "zhou2014")

METHOD_LABELS = {
    "zhang_pless_linear": "Zhang & Pless (linear)",
    "zhang_pless": "Zhang & Pless (refined)",
    "vasconcelos": "Vasconcelos (\"Francisco\")",
    "peng2022": "Peng 2022",
    "lidarcam": "lidarcam",
    "peng2022+ml": "Peng 2022 + ML",
    "vasconcelos+ml": "Vasconcelos + ML",
    "vasconcelos_msac": "Vasconcelos MSAC (authors' code)",
    "vasconcelos_msac_refined": "Vasconcelos MSAC refined (authors' code)",
    "zhou2014": "Zhou 2014",
}

METHOD_COLOURS = {
    "zhang_pless_linear": "#ff7f0e",
    "zhang_pless": "#d62728",
    "vasconcelos": "#1f77b4",
    "peng2022": "#2ca02c",
    "lidarcam": "#9467bd",
    "peng2022+ml": "#8c564b",
    "vasconcelos+ml": "#17becf",
    "vasconcelos_msac": "#aec7e8",
    "vasconcelos_msac_refined": "#6baed6",
    "zhou2014": "#ff9896",
}
_SPARE = ("#7f7f7f", "#bcbd22", "#e377c2", "#393b79", "#637939", "#843c39")


def method_colour(method: str) -> str:
    """The fixed colour of ``method`` (an unlisted one gets a spare colour chosen by its name's hash)."""
    return METHOD_COLOURS.get(method) or _SPARE[zlib.crc32(method.encode()) % len(_SPARE)]


def method_label(method: str) -> str:
    return METHOD_LABELS.get(method, method)


def method_order(methods) -> list[str]:
    """The paper's methods first, then ours, then any other (sorted), each once."""
    present = set(methods)
    known = [m for m in (*PAPER_METHODS, *OPTIONAL_METHODS) if m in present]
    return known + sorted(present - set(known))
