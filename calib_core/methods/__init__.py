"""The project's calibration methods, one family per module, registered explicitly by ``register_builtins``:
``baselines`` (the seed methods as their papers describe them), ``francisco`` (Francisco's method as its authors'
code runs it, and Zhou 2014's minimal solver), ``lidarcam`` (ours), ``suffixes`` (``X+ml`` and
``X+plane`` for any X) and ``ablations`` (variants of ``peng2022``)."""

from __future__ import annotations

from ..registry import METHODS, get_method, register, register_suffix
from .ablations import ablations
from .baselines import BASELINES
from .francisco import FRANCISCO_METHODS
from .lidarcam import LIDARCAM
from .suffixes import SUFFIX_FACTORIES

LISTED_DERIVED = tuple(f"{b}+{s}" for b in ("zhang_pless_linear", "vasconcelos", "peng2022") for s in SUFFIX_FACTORIES)
"""Derived methods listed in the table (any other ``X+s`` is built on request)."""


def register_builtins() -> None:
    """Fill the registry with the project's methods (idempotent)."""
    if "lidarcam" in METHODS:
        return
    for suffix, factory in SUFFIX_FACTORIES.items():
        register_suffix(suffix, factory)
    for m in BASELINES + FRANCISCO_METHODS:
        register(m)
    register(LIDARCAM)
    for name in LISTED_DERIVED:
        register(get_method(name))
    for m in ablations(METHODS["peng2022"]):
        register(m)
