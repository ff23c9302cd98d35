"""Shared test configuration.

Importing gmr_jax enables float64 (`jax_enable_x64`) before any test builds an array. The suite
also runs with JAX's strict rank promotion, so an implicit broadcast between arrays of different
rank is an error here rather than a silent shape bug.
"""

import jax
import numpy as np
import pytest

import gmr_jax  # noqa: F401  (enables jax_enable_x64)

jax.config.update("jax_numpy_rank_promotion", "raise")


def pytest_collection_modifyitems(config, items):
    # the default tier excludes `slow` unless -m is given (pyproject addopts cannot be undone by
    # `-m slow` alone, so the rule lives here)
    if config.getoption("-m"):
        return
    skip = pytest.mark.skip(reason="slow tier: run with `pytest -m slow` (or `-m ''` for all)")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def rng():
    """A seeded NumPy generator: tests that draw data are reproducible."""
    return np.random.default_rng(0)
