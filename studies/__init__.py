"""Studies and reproductions built on the public gmr_jax API (run from the repository root:
`python studies/<name>.py --help`). Tables and figures go to `results/`."""
