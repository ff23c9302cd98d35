"""Shared test configuration.

Importing gmr_jax enables float64 (`jax_enable_x64`) before any test builds an array. The suite
also runs with JAX's strict rank promotion, so an implicit broadcast between arrays of different
rank is an error here rather than a silent shape bug.

Two hangs seen in CI (a worker idle for ever in `select_threshold`, then in stop 29's slow tier in
`coordinate`) were jaxlib 0.10.2's LAPACK batch kernels: a vmapped QR hands its batch to XLA's
intra-op pool and blocks, and two such calls at once fill a 2-thread pool with waiters. The
library now factorises without LAPACK wherever a batch arises (`gmr_jax/_fit/_householder.py`;
`test_no_lapack_batches.py` audits the programs). Beyond that, each xdist worker is pinned to one
CPU of its own before JAX starts: XLA sizes its pool from the CPU affinity, and with one thread
jaxlib runs every batch inline, so no kernel of any library can wedge a worker this way (the
workers already run one per core with single-threaded Eigen; measured: the pool goes from 2
threads to 1). pytest-timeout (pyproject) turns any other hang into a named failure after 15 min
instead of eating CI's 90.

Compilation, not execution, is most of the suite's time (measured with jax.monitoring: about
225 s of XLA backend compilation per worker out of 360 s, 1,800 compilations). So the suite runs
with three XLA flags that only change how the code is compiled, not what it computes (IEEE float64
either way; results can differ in the last bits, as between machines):
- `--xla_backend_optimization_level=0`: LLVM does not optimise the generated code; compiling
  is faster and the tests' small problems do not run noticeably slower (user time of the default
  tier 11:18 -> 9:46 on 2 cores).
- `--xla_cpu_multi_thread_eigen=false`: xdist already runs one process per core, and two workers
  each spreading over both cores only contend.
- `--xla_cpu_use_fusion_emitters=false`: XLA:CPU's older elemental emitters for fused loops
  instead of its MLIR fusion emitters, which take longer to compile (cold default tier on the
  2-core dev machine, 2026-11-24: 5:10 -> 3:21 wall, 614 -> 394 CPU-s, the same 435 tests pass).
  The library itself keeps XLA's defaults: the MLIR emitters' code runs faster in long sweeps.
Subprocesses (CLI runs, notebook kernels) inherit them through the environment. The persistent
compilation cache below helps little (a warm cache did not shorten the default tier: most of
the compiled code is not shared between tests) but costs nothing.
"""

import os

_WORKER = os.environ.get("PYTEST_XDIST_WORKER", "")
if _WORKER.startswith("gw") and hasattr(os, "sched_setaffinity"):
    _cpus = sorted(os.sched_getaffinity(0))
    os.sched_setaffinity(0, {_cpus[int(_WORKER[2:]) % len(_cpus)]})

_FLAGS = ("--xla_cpu_multi_thread_eigen=false", "--xla_backend_optimization_level=0",
          "--xla_cpu_use_fusion_emitters=false")
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
    # every program, however small: the two xdist workers compile most of the same ones, and
    # the second finds them on disk (cold default tier about 10 s shorter than with 0.2 s)
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
# the command line, run in process by the CLI tests, points JAX at `$GMR_CACHE_DIR` (default
# ~/.cache/gmr_jax/xla): the same folder as above, so a test run never writes to the user's
# home and every worker keeps one cache from start to end
os.environ.setdefault("GMR_CACHE_DIR", os.path.abspath(_CACHE) if _CACHE else "off")

import jax  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import gmr_jax  # noqa: E402  (enables jax_enable_x64)

jax.config.update("jax_numpy_rank_promotion", "raise")


def pytest_collection_modifyitems(config, items):
    # the default tier excludes `slow` unless -m is given (pyproject addopts cannot be undone by
    # `-m slow` alone, so the rule lives here)
    if config.getoption("-m"):
        return
    skip = pytest.mark.skip(reason='slow tier: run with `pytest -m slow` (`-m "slow or not slow"` for all)')
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def rng():
    """A seeded NumPy generator: tests that draw data are reproducible."""
    return np.random.default_rng(0)


@pytest.fixture(autouse=True)
def _relieve_map_pressure():
    """After each test, a worker holding over half the memory maps the kernel allows drops JAX's
    compiled programs (`gmr_jax._config.relieve_map_pressure`): a worker of the slow tier reached
    the limit after some 10 000 programs and crashed inside XLA (stop 52's CI, and locally)."""
    yield
    gmr_jax._config.relieve_map_pressure()
