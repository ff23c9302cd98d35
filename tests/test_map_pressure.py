"""`_config.relieve_map_pressure`: a process that compiles thousands of XLA:CPU programs runs out of
the memory maps the kernel allows it (about six per program, `vm.max_map_count` 65530), and the next
program loaded crashes the process inside XLA (the slow tier's worker, twice: stop 52's CI and a
local run, in `compilation_cache.get_executable_and_time`, its maps near the limit)."""

import os

import jax
import jax.numpy as jnp
import pytest

from gmr_jax import _config

linux = pytest.mark.skipif(not os.path.exists("/proc/self/maps"), reason="reads /proc (Linux)")


def _maps() -> int:
    with open("/proc/self/maps", "rb") as f:
        return sum(1 for _ in f)


@linux
def test_map_pressure_is_the_share_of_the_kernels_limit():
    with open("/proc/sys/vm/max_map_count") as f:
        limit = int(f.read())
    p = _config.map_pressure()
    assert p is not None and 0 < p < 1
    assert abs(p - _maps() / limit) < 200 / limit  # the same count, give or take the maps opened meanwhile


@linux
@pytest.mark.skipif(jax.default_backend() != "cpu", reason="counts XLA:CPU's maps per program")
def test_dropping_the_compiled_programs_returns_their_maps():
    """Programs compiled in this process hold maps until JAX's caches drop them; below the share
    nothing is dropped, above it every jitted function's cache is emptied and the maps come back."""
    fns = [jax.jit(lambda x, k=k: jnp.sin(x) * k + jnp.cos(x) ** 2) for k in range(150)]
    before = _maps()
    for k, f in enumerate(fns):
        f(jnp.ones(k + 1)).block_until_ready()
    held = _maps() - before
    assert held > 300, held  # about six maps a program
    assert _config.relieve_map_pressure(share=1.0) is False  # below the share: kept
    assert fns[0]._cache_size() == 1
    assert _config.relieve_map_pressure(share=0.0) is True
    assert fns[0]._cache_size() == 0 and fns[-1]._cache_size() == 0
    assert _maps() - before < held / 4, (_maps() - before, held)
    assert float(fns[3](jnp.ones(4))[0]) == pytest.approx(3 * float(jnp.sin(1.0)) + float(jnp.cos(1.0)) ** 2)


def test_unreadable_proc_reads_as_no_pressure(monkeypatch):
    def missing(*args, **kwargs):
        raise OSError("no /proc here")

    monkeypatch.setattr(_config, "open", missing, raising=False)  # the module's open only
    assert _config.map_pressure() is None
    assert _config.relieve_map_pressure(share=0.0) is False


def test_a_process_that_stays_above_the_share_does_not_drop_on_every_call(monkeypatch):
    """Maps JAX does not own stay after a drop: the next drop waits until the maps have grown by `REGROWTH` of the
    share again (else every entry point and test would recompile everything)."""
    level = [0.9]
    monkeypatch.setattr(_config, "map_pressure", lambda: level[0])
    monkeypatch.setattr(_config, "_AFTER_CLEAR", [None])
    assert _config.relieve_map_pressure() is True  # 0.9 of the limit; 0.9 still after the drop
    assert _config.relieve_map_pressure() is False
    level[0] = 0.9 + 0.9 * _config.REGROWTH * _config.MAP_SHARE
    assert _config.relieve_map_pressure() is False  # grown, but not by REGROWTH x share
    level[0] = 0.9 + 1.1 * _config.REGROWTH * _config.MAP_SHARE
    assert _config.relieve_map_pressure() is True
