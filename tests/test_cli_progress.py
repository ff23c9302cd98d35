"""Progress lines of the long commands: the first on stderr within 2 s of start (before the
import of gmr_jax), then per-stage lines with elapsed times; stdout untouched."""

import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINE = re.compile(r"^\[gmr (\w+)\] (\d+\.\d) s \S")


def _launch(args, env=None):
    """The console script's entry (gmr_launch.main) in a fresh interpreter; stderr piped."""
    e = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    e.pop("GMR_PROGRESS", None)
    e.update(env or {})
    return subprocess.Popen([sys.executable, "-m", "gmr_launch", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=e, cwd=ROOT)


def _first_line(args, env=None):
    t0 = time.perf_counter()
    p = _launch(args, env)
    try:
        line = p.stderr.readline()
        return time.perf_counter() - t0, line
    finally:
        p.kill()  # only the first line matters here
        p.communicate()


LONG = [["fit", "a.npz", "b.npz", "--out", "m.json"], ["refine", "m.json", "a.npz", "--out", "r.json"],
        ["discover", "m.json", "a.npz", "--holdout", "b.npz", "--out", "d"], ["actuate", "m.json", "--target", "0-1",
        "--out", "d"], ["basins", "m.json", "--f", "1:2:2", "--A", "0.1:1:2", "--out", "d"], ["demo", "--out", "d"],
        ["simulate", "m.json", "a.npz", "--out", "d"]]


@pytest.mark.parametrize("args", LONG, ids=[a[0] for a in LONG])
def test_first_progress_line_within_2_s(args):
    dt, line = _first_line(args)
    assert LINE.match(line) and f"[gmr {args[0]}]" in line, line
    assert dt < 2.0, f"first progress line after {dt:.2f} s: {line!r}"


def test_stage_lines_then_the_error_and_stdout_untouched(tmp_path):
    """A fit on missing files: the import line, the loading stage, then the one error line."""
    p = _launch(["fit", str(tmp_path / "a.npz"), str(tmp_path / "b.npz"), "--out", str(tmp_path / "m.json")])
    out, err = p.communicate(timeout=300)
    lines = err.strip().splitlines()
    assert p.returncode == 2 and out == ""
    assert [LINE.match(x)[1] for x in lines[:-1]] == ["fit", "fit"], lines
    times = [float(LINE.match(x)[2]) for x in lines[:-1]]
    assert times == sorted(times) and "loading 2 recording(s)" in lines[1]
    assert lines[-1].startswith("gmr fit: error:") and "no such file" in lines[-1]


@pytest.mark.parametrize("how", [{"GMR_PROGRESS": "0"}, "--no-progress"])
def test_progress_can_be_turned_off(tmp_path, how):
    args = ["fit", str(tmp_path / "a.npz"), str(tmp_path / "b.npz"), "--out", str(tmp_path / "m.json")]
    env = how if isinstance(how, dict) else None
    p = _launch(args + ([how] if isinstance(how, str) else []), env)
    _, err = p.communicate(timeout=300)
    assert p.returncode == 2 and len(err.strip().splitlines()) == 1 and "[gmr" not in err, err


def test_quick_commands_and_in_process_main_print_no_progress(tmp_path, capsys):
    from gmr_jax._cli._main import main

    # in-process main() stays quiet (GMR_PROGRESS=1 turns it on)
    assert main(["fit", str(tmp_path / "a.npz"), str(tmp_path / "b.npz"), "--out", str(tmp_path / "m.json")]) == 2
    assert "[gmr" not in capsys.readouterr().err
    os.environ["GMR_PROGRESS"] = "1"
    try:
        assert main(["fit", str(tmp_path / "a.npz"), str(tmp_path / "b.npz"), "--out", str(tmp_path / "m.json")]) == 2
    finally:
        del os.environ["GMR_PROGRESS"]
    err = capsys.readouterr().err.splitlines()
    assert LINE.match(err[0]) and err[-1].startswith("gmr fit: error:")
