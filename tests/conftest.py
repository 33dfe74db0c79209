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
