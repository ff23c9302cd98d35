import gmr_jax  # noqa: F401  (enables jax_enable_x64 before any test builds arrays)
