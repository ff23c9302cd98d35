"""Per-stage progress lines of the long commands, on stderr, with the time since the command
started: `[gmr fit] 3.1 s loading 2 recordings`.

The `gmr` console script (`gmr_launch.main`) prints the first line before it imports gmr_jax
(jax, diffrax, scipy and matplotlib take 2-4 s to import), then hands its start time to
`gmr_jax._cli._main.main(started=...)`, which calls `start` here; each command calls `stage` at
the start of every stage. Stdout is left as it was. Off with `--no-progress` or `GMR_PROGRESS=0`;
`main()` called from Python is quiet unless `GMR_PROGRESS=1`. Only the standard library here: the
console script's rules below are repeated there, where gmr_jax is not imported yet.
"""

import os
import sys
import time

#: Commands that can run for more than a few seconds: they print progress lines.
LONG = ("fit", "refine", "discover", "actuate", "basins", "demo", "simulate")

_state = {"cmd": None, "t0": 0.0, "on": False}


def wanted(cmd: str, argv, started: float | None) -> bool:
    """Progress for `cmd`? Long commands only; `GMR_PROGRESS=0` / `--no-progress` turn it off,
    `GMR_PROGRESS=1` on (also for `main()` called in-process, which is quiet by default)."""
    env = os.environ.get("GMR_PROGRESS", "")
    if cmd not in LONG or env == "0" or "--no-progress" in argv:
        return False
    return started is not None or env == "1"


def line(cmd: str, elapsed: float, msg: str) -> str:
    return f"[gmr {cmd}] {elapsed:.1f} s {msg}"


def start(cmd: str, started: float | None, on: bool) -> None:
    """Begin reporting for `cmd`; `started` is `time.perf_counter()` at process start (None: now)."""
    _state.update(cmd=cmd, t0=time.perf_counter() if started is None else started, on=on)


def stop() -> None:
    _state["on"] = False


def stage(msg: str) -> None:
    """Print one progress line (no-op when progress is off)."""
    if not _state["on"]:
        return
    try:
        print(line(_state["cmd"], time.perf_counter() - _state["t0"], msg), file=sys.stderr, flush=True)
    except (OSError, ValueError):  # a closed stderr must not stop the computation
        _state["on"] = False
