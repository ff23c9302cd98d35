"""Private implementation package: import the public names from `gmr_jax`."""
