"""`python -m gmr_jax ...` is the `gmr` command."""

import sys
import time

from ._cli._main import main

if __name__ == "__main__":
    sys.exit(main(started=time.perf_counter()))
