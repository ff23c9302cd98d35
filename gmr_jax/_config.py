"""Numerics configuration.

gmr_jax works in float64 throughout: the coordination solve (a confluent Vandermonde
system) and the local fits on small-amplitude data lose most of their digits in float32.
Importing `gmr_jax` therefore enables JAX's x64 mode (`jax_enable_x64`) for the process.
"""

import jax

jax.config.update("jax_enable_x64", True)
