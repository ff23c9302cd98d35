"""Shared test configuration.

Importing gmr_jax enables float64 (`jax_enable_x64`) before any test builds an array. The suite
also runs with JAX's strict rank promotion, so an implicit broadcast between arrays of different
rank is an error here rather than a silent shape bug.

XLA's CPU runtime can wedge its multi-threaded Eigen pool on vmap-heavy graphs (seen here: a CI
run that never returned from `select_threshold`; jax-ml/jax#25861 and PyAutoFit#1528/#1530 report
the same, and `--xla_cpu_multi_thread_eigen=false` as the cure). The suite runs with that flag (xdist
already gives one process per core, so intra-op threads bought little here).
Subprocesses (CLI runs, notebook kernels) inherit the flags through the environment.
"""

import os

_FLAGS = ("--xla_cpu_multi_thread_eigen=false",)
os.environ["XLA_FLAGS"] = " ".join(
    [os.environ.get("XLA_FLAGS", "")] + [f for f in _FLAGS if f not in os.environ.get("XLA_FLAGS", "")]
).strip()

# One persistent XLA compilation cache for the whole run: xdist workers, CLI subprocesses,
# notebook kernels and the slow tier after the default one compile the same kernels, and each
# would otherwise compile them again. Keyed by the HLO, the flags and the jax version, so it can
# only return what a fresh compile would. GMR_TEST_CACHE="" turns it off.
_CACHE = os.environ.get("GMR_TEST_CACHE", os.path.join(os.path.dirname(__file__), "..", ".pytest_cache", "jax"))
if _CACHE:
    os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", os.path.abspath(_CACHE))
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0.2")

import jax  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

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
