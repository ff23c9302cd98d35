"""The `gmr` command line: one module per subcommand (`register(sub)` adds its parser, `run(args)`
does the work); formats and shapes are those of the contracts (README, "File formats").

Exit status: 0 success; 1 the computation failed (its RESULTS code is named); 2 the input was
wrong (the message names the file, option or value and the fix).
"""

import argparse
import json
import sys

from .._errors import GMRInputError
from .._solution import GMRComputationError
from . import _actuate, _basins, _demo, _discover, _fit, _refine

COMMANDS = (_demo, _fit, _basins, _discover, _actuate, _refine)


def build_parser():
    p = argparse.ArgumentParser(prog="gmr", description="Global model reconstruction of multi-stable structures")
    sub = p.add_subparsers(dest="cmd", required=True)
    for cmd in COMMANDS:
        cmd.register(sub)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
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


if __name__ == "__main__":
    sys.exit(main())
