"""Numerics configuration.

gmr_jax works in float64 throughout: the coordination solve (a confluent Vandermonde
system) and the local fits on small-amplitude data lose most of their digits in float32.
Importing `gmr_jax` therefore enables JAX's x64 mode (`jax_enable_x64`) for the process.
"""

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
