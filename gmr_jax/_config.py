"""Numerics configuration.

gmr_jax works in float64 throughout: the coordination solve (a confluent Vandermonde
system) and the local fits on small-amplitude data lose most of their digits in float32.
Importing `gmr_jax` therefore enables JAX's x64 mode (`jax_enable_x64`) for the process.
"""

import functools

import jax

jax.config.update("jax_enable_x64", True)


def use_cpu_cores(n: int | None = None, *, strict: bool = True) -> int:
    """Expose `n` CPU cores (default: all) to JAX as separate CPU devices, so that sharded
    work (`basin_map`) runs on all of them. JAX's own runtime does the rest (no worker pool).

    Call it right after `import gmr_jax`, before any JAX computation; the command line does
    this for `gmr basins`. Returns the number of CPU devices JAX will use. If `XLA_FLAGS`
    already sets `--xla_force_host_platform_device_count`, that setting is kept. With
    `strict=False`, a call after JAX has started changes nothing and returns the number of
    CPU devices JAX already has.
    """
    import os
    import re

    from ._errors import GMRInputError

    flag = re.search(r"xla_force_host_platform_device_count=(\d+)", os.environ.get("XLA_FLAGS", ""))
    if flag:
        return int(flag.group(1))
    n = int(n or os.cpu_count() or 1)
    if n < 1:
        raise GMRInputError(f"use_cpu_cores needs n >= 1, got {n}")
    try:
        jax.config.update("jax_num_cpu_devices", n)
    except RuntimeError:
        if not strict:
            return len(jax.devices("cpu"))
        raise GMRInputError(
            "use_cpu_cores() must run before the first JAX computation: call it right after "
            "`import gmr_jax` (or set XLA_FLAGS=--xla_force_host_platform_device_count=N)"
        ) from None
    return n


CACHE_ENV = "GMR_CACHE_DIR"


def default_cache_dir() -> str | None:
    """Where compiled programs are kept between processes: `$GMR_CACHE_DIR` if set (empty or
    "off": no cache), else `$XDG_CACHE_HOME/gmr_jax/xla` (default `~/.cache/gmr_jax/xla`)."""
    import os

    env = os.environ.get(CACHE_ENV)
    if env is not None:
        return None if env.strip().lower() in ("", "off", "0", "none") else os.path.expanduser(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "gmr_jax", "xla")


def fast_compile_flags() -> bool:
    """Have XLA:CPU compile with its older elemental loop emitters
    (`--xla_cpu_use_fusion_emitters=false` appended to `XLA_FLAGS`), which compile about a third
    faster than its MLIR fusion emitters; the code computes the same (IEEE float64) and runs at
    about the same speed for fits, 20-40 % slower in long basin sweeps. The command line uses it
    for `gmr fit`. Only takes effect before JAX starts its CPU backend and when `XLA_FLAGS` does
    not already choose the emitters; returns whether the flag was added."""
    import os

    flags = os.environ.get("XLA_FLAGS", "")
    if "xla_cpu_use_fusion_emitters" in flags or _backend_started():
        return False
    os.environ["XLA_FLAGS"] = (flags + " --xla_cpu_use_fusion_emitters=false").strip()
    return True


def _backend_started() -> bool:
    try:
        from jax._src import xla_bridge

        return bool(xla_bridge._backends)
    except (ImportError, AttributeError):  # a JAX without this private: assume it started
        return True


def use_compilation_cache(path: "str | bool | None" = None, *, min_compile_time: float = 0.2) -> str | None:
    """Keep XLA's compiled programs on disk (JAX's persistent compilation cache), so that a new
    process running the same computations (a second fit on records of the same shapes, a restarted
    notebook) loads them instead of compiling again.

    Importing gmr_jax turns it on in `default_cache_dir()` (`$GMR_CACHE_DIR`, else
    `~/.cache/gmr_jax/xla`), unless JAX already has a cache folder of its own
    (`JAX_COMPILATION_CACHE_DIR`) or `GMR_CACHE_DIR=off`. Call this to choose another folder or to
    turn it off.

    **Arguments:**

    - `path`: the cache folder; None: `default_cache_dir()`; False: off (nothing is stored or read).
    - `min_compile_time`: programs that took less than this many seconds to compile are not stored.

    **Returns:** the folder in use (None: off). Entries are keyed by the program, the JAX version and
    the device, so a stale entry is never used; delete the folder to reclaim the space. The traced
    programs of `fit_local` and `coordinate` are kept there too (subfolder `gmr_traces`, keyed also
    by a hash of gmr_jax's source), which spares a new process their tracing.
    """
    import os

    from ._trace_cache import set_folder

    if path is False:
        path = None
    else:
        path = default_cache_dir() if path is None else os.path.expanduser(str(path))
    if path is not None:
        try:
            os.makedirs(path, exist_ok=True)
        except OSError:  # read-only home, full disk: run without the cache rather than fail
            path = None
    if path is None and jax.config.jax_compilation_cache_dir is None:
        set_folder(None)
        return None
    jax.config.update("jax_compilation_cache_dir", path)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_time))
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    try:  # a cache JAX already opened keeps its folder until reset
        from jax.experimental.compilation_cache import compilation_cache

        compilation_cache.reset_cache()
    except (ImportError, AttributeError):
        pass
    set_folder(path)  # and the traced programs of the fits (gmr_jax._trace_cache)
    return path


def compilation_cache_on_import() -> str | None:
    """What importing gmr_jax does: `use_compilation_cache()` unless JAX already has a cache folder
    (the user's `JAX_COMPILATION_CACHE_DIR` or `jax.config`), which is then left as it is."""
    if jax.config.jax_compilation_cache_dir:
        return jax.config.jax_compilation_cache_dir
    return use_compilation_cache()


#: `relieve_map_pressure`: the share of the kernel's limit on one process's memory maps
#: (`vm.max_map_count`, 65530 by default) above which JAX's compiled programs are dropped
MAP_SHARE = 0.5


def map_pressure() -> float | None:
    """This process's memory maps as a share of the kernel's limit on them (Linux; None where
    either cannot be read). Each program XLA:CPU compiles, or loads from the compilation cache,
    holds about six maps for as long as JAX keeps it in memory, and JAX keeps every one: a
    process that compiles some 10 000 (a long notebook session of fits on records of many
    lengths; the test suite's slow tier) reaches the limit, and the next program it loads
    crashes the process with a segmentation fault inside XLA, not a Python error."""
    try:
        limit = _map_limit()
        with open("/proc/self/maps", "rb") as f:
            n = sum(1 for _ in f)
    except (OSError, ValueError):
        return None
    return n / limit if limit > 0 else None


@functools.cache
def _map_limit() -> int:
    """`vm.max_map_count`, read once (a failed read raises and is not kept)."""
    with open("/proc/sys/vm/max_map_count") as f:
        return int(f.read())


def relieve_map_pressure(share: float = MAP_SHARE) -> bool:
    """Where this process holds more than `share` of the memory maps the kernel allows
    (`map_pressure`), drop JAX's in-memory compiled programs (`jax.clear_caches()`) so that their
    maps are returned; programs used again are recompiled, or loaded from the persistent
    compilation cache. Results do not change, only the time of the next calls. `reconstruct`,
    `gmc_sindy`, `basin_map`, `basin_probability`, `refine`, `actuate` and `discover` call it on
    entry; call it between steps of a long loop of your own. Returns whether it dropped them."""
    p, last = map_pressure(), _AFTER_CLEAR[0]
    if p is None or p < share or (last is not None and p < last + REGROWTH * share):
        return False
    import gc

    jax.clear_caches()
    gc.collect()
    # maps JAX does not own (native libraries, mapped files) stay: the next drop waits until the maps have grown
    # by `REGROWTH` x `share` of the limit again, so a process that stays above `share` does not drop on every call
    _AFTER_CLEAR[0] = map_pressure()
    return True


#: `relieve_map_pressure` drops again only once the maps have grown by this fraction of `share` (of the limit)
#: since the last drop
REGROWTH = 0.25
_AFTER_CLEAR: list[float | None] = [None]
