"""The `gmr` console script's entry point, outside the gmr_jax package on purpose.

Importing `gmr_jax` (jax, diffrax, scipy, matplotlib) takes 2-4 s, and any module inside the
package runs that import first. This module imports only the standard library, so that
`gmr --version` answers at once and a long command (fit, refine, discover, actuate, basins, demo)
(and simulate) prints its first progress line on stderr before the heavy import; then it hands over to
`gmr_jax._cli._main.main` with its start time. The progress rules repeat
`gmr_jax._cli._progress` (which it cannot import without importing gmr_jax).
"""

import time

_T0 = time.perf_counter()

import os  # noqa: E402
import sys  # noqa: E402

_LONG = ("fit", "refine", "discover", "actuate", "basins", "demo", "simulate")


def _version() -> str:
    import importlib.metadata

    try:
        return importlib.metadata.version("gmr_jax")
    except importlib.metadata.PackageNotFoundError:  # a source tree that was not installed
        return "0+unknown"


def _command(argv) -> str | None:
    """The subcommand: the first argument that is not an option."""
    return next((a for a in argv if not a.startswith("-")), None)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv == ["--version"]:
        print(f"gmr_jax {_version()}")
        return 0
    cmd = _command(argv)
    if cmd in _LONG and os.environ.get("GMR_PROGRESS", "") != "0" and "--no-progress" not in argv \
            and "-h" not in argv and "--help" not in argv:
        try:
            print(f"[gmr {cmd}] {time.perf_counter() - _T0:.1f} s importing gmr_jax (jax, scipy, matplotlib)",
                  file=sys.stderr, flush=True)
        except (OSError, ValueError):
            pass
    from gmr_jax._cli._main import main as gmr_main

    return gmr_main(argv, started=_T0)


def console() -> None:
    """The `gmr` console script: `main`, then leave without the interpreter's teardown (JAX's
    runtime takes ~0.6 s to come down on 2 cores, a fifth of a warm `gmr fit`). Every file is
    written and closed by then; stdout and stderr are flushed. `gmr basins` exits normally:
    a multi-process sweep's `jax.distributed` client shuts down at exit."""
    argv = sys.argv[1:]
    rc = main(argv)
    if _command(argv) == "basins":
        sys.exit(rc)
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        os._exit(rc if isinstance(rc, int) else 1)


if __name__ == "__main__":
    console()
