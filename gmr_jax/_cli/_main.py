"""The `gmr` command line: one module per subcommand (`register(sub)` adds its parser, `run(args)`
does the work); formats and shapes are those of the contracts (docs/formats.md).

Exit status: 0 success; 1 the computation failed (its RESULTS code is named); 2 the input was
wrong (the message names the file, option or value and the fix); 3 an internal error (a bug in
gmr_jax: one line naming it; `GMR_DEBUG=1` shows the traceback). Output piped into a reader that
closes early (`gmr basins ... | head`) does not stop the computation. Long commands print
per-stage progress lines on stderr (`_progress`); stdout keeps each command's own output.
"""

import argparse
import json
import os
import sys

from .._errors import GMRInputError
from .._solution import GMRComputationError
from . import _actuate, _basins, _demo, _discover, _fit, _progress, _refine, _show, _simulate
from ._args import join_negative_values

COMMANDS = (_demo, _fit, _basins, _discover, _actuate, _refine, _show, _simulate)


def _version() -> str:
    import importlib.metadata

    try:
        return importlib.metadata.version("gmr_jax")
    except importlib.metadata.PackageNotFoundError:
        return "0+unknown"


class _DefaultsShown(argparse.HelpFormatter):
    """Help text with each option's default appended (`(default: 5)`), where it has one to show."""

    def _get_help_string(self, action):
        text = action.help or ""
        if ("%(default)" in text or "default" in text.lower() or action.default in (None, False, argparse.SUPPRESS)
                or not action.option_strings or action.required):
            return text
        return f"{text} (default: %(default)s)"


def build_parser():
    p = argparse.ArgumentParser(prog="gmr", description="Global model reconstruction of multi-stable structures")
    p.add_argument("--version", action="version", version=f"gmr_jax {_version()}",
                   help="print the installed gmr_jax version and exit")
    sub = p.add_subparsers(dest="cmd", required=True)
    for cmd in COMMANDS:
        parser = cmd.register(sub)
        parser.formatter_class = _DefaultsShown  # every option's default in --help
        if parser.prog.split()[-1] in _progress.LONG:
            parser.add_argument("--no-progress", action="store_true",
                                help="no progress lines on stderr (also GMR_PROGRESS=0)")
    return p


class _QuietWhenClosed:
    """stdout that keeps the computation going when its reader goes away (`gmr ... | head`):
    the first BrokenPipeError sends the rest of the output to /dev/null."""

    def __init__(self, stream):
        self._stream = stream

    def _closed(self):
        try:  # the file descriptor too, so that the interpreter's flush at exit is quiet
            os.dup2(os.open(os.devnull, os.O_WRONLY), self._stream.fileno())
        except (OSError, ValueError, AttributeError):
            pass
        self._stream = open(os.devnull, "w")

    def write(self, s):
        try:
            return self._stream.write(s)
        except BrokenPipeError:
            self._closed()
            return len(s)

    def flush(self):
        try:
            self._stream.flush()
        except BrokenPipeError:
            self._closed()

    def __getattr__(self, name):
        return getattr(self._stream, name)


#: commands whose cold run is mostly XLA compilation (`gmr fit`: 16-19 -> 11-12 s cold with
#: `fast_compile_flags`); the sweeps (`basins`, `actuate`, `demo`) run long loops, where XLA's
#: default emitters' code is faster (lanes sweep 22-42 % slower with the older ones)
_COMPILE_BOUND = ("fit",)


def main(argv=None, *, started: float | None = None) -> int:
    """Run `gmr ARGV`; returns the exit status. `started`: `time.perf_counter()` at process start
    (the console script passes it): long commands then print progress lines on stderr."""
    argv = join_negative_values(sys.argv[1:] if argv is None else list(argv))
    args = build_parser().parse_args(argv)
    _progress.start(args.cmd, started, _progress.wanted(args.cmd, argv, started))
    from .._config import fast_compile_flags, use_compilation_cache

    if args.cmd in _COMPILE_BOUND:
        fast_compile_flags()
    use_compilation_cache(min_compile_time=0.0)  # a second run on similar data loads its compiled programs ($GMR_CACHE_DIR)
    stdout = sys.stdout
    sys.stdout = _QuietWhenClosed(stdout)
    try:
        return args.fn(args)
    except GMRInputError as e:
        print(f"gmr {args.cmd}: error: {e}", file=sys.stderr)
        return 2
    except (OSError, json.JSONDecodeError) as e:
        print(f"gmr {args.cmd}: error: {e}", file=sys.stderr)
        return 2
    except GMRComputationError as e:
        print(f"gmr {args.cmd}: the computation failed: {e}", file=sys.stderr)
        return 1
    except Exception as e:  # a bug, not the user's input: one line, the traceback on request
        if os.environ.get("GMR_DEBUG"):
            raise
        print(f"gmr {args.cmd}: internal error ({type(e).__name__}: {e}); this is a bug in gmr_jax, "
              "please report it with the command (GMR_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 3
    finally:
        _progress.stop()
        sys.stdout = stdout


if __name__ == "__main__":
    sys.exit(main())
