"""Shared test helpers: a random generator seeded from the test's own name (order-independent scenes), a folder
for plugin modules."""

import importlib
import sys
import zlib

import numpy as np
import pytest


@pytest.fixture
def rng(request) -> np.random.Generator:
    """A generator seeded from the test's node name, so a test's data does not depend on test order."""
    return np.random.default_rng(zlib.crc32(request.node.name.encode()))


@pytest.fixture
def plugin_dir(tmp_path, monkeypatch):
    """A folder on sys.path for plugin modules; the registry, loaded plugins and modules restored afterwards."""
    import calib_core.plugins as plugins
    from calib_core.registry import METHODS

    methods, loaded, modules = dict(METHODS), dict(plugins._LOADED), set(sys.modules)
    monkeypatch.syspath_prepend(str(tmp_path))
    importlib.invalidate_caches()
    yield tmp_path
    METHODS.clear()
    METHODS.update(methods)
    plugins._LOADED.clear()
    plugins._LOADED.update(loaded)
    for name in set(sys.modules) - modules:
        del sys.modules[name]


def pytest_addoption(parser):
    parser.addoption("--shuffle", type=int, default=None, metavar="SEED",
                     help="run the test modules, and the tests within each, in an order shuffled by SEED (the same "
                          "order in every xdist worker); tests sharing a parametrised module fixture stay together")


def _wide_params(item) -> tuple:
    """The indices of the item's parameters of fixtures wider than a function (kept together when shuffling)."""
    cs = getattr(item, "callspec", None)
    if cs is None:
        return ()
    defs = item._fixtureinfo.name2fixturedefs
    return tuple(cs.indices[n] for n in sorted(cs.indices) if n in defs and defs[n][-1].scope != "function")


def pytest_collection_modifyitems(config, items):
    seed = config.getoption("--shuffle")
    if seed is None:
        return
    import random

    rnd = random.Random(seed)
    modules: dict[str, list] = {}
    for it in items:
        modules.setdefault(it.nodeid.split("::")[0], []).append(it)
    order = list(modules)
    rnd.shuffle(order)
    out = []
    for m in order:
        group = modules[m]
        rnd.shuffle(group)
        out += sorted(group, key=_wide_params)   # stable: shuffled within each wide-fixture parameter
    items[:] = out
