"""Shared test helpers: a random generator seeded from the test's own name (order-independent scenes)."""

import zlib

import numpy as np
import pytest


@pytest.fixture
def rng(request) -> np.random.Generator:
    """A generator seeded from the test's node name, so a test's data does not depend on test order."""
    return np.random.default_rng(zlib.crc32(request.node.name.encode()))
