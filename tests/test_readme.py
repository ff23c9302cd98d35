"""Every command and Python block of README.md and docs/getting-started.md runs as written (slow tier).

Blocks run in document order in one temporary folder per document (a block may use the files an earlier one
wrote). Shell blocks: each `&&`-joined command that is not an installation or the test suite itself
(`python3 -m venv`, `. .venv/bin/activate`, `pip install`, `python -m pytest`, `mkdocs`) runs as
`python -m gmr_jax ...` for `gmr ...`; Python blocks run in one namespace per document.
"""

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = ("README.md", "docs/getting-started.md")
_BLOCK = re.compile(r"```(bash|python)\n(.*?)```", re.S)
_SKIP = ("python3 -m venv", ". .venv/bin/activate", "pip install", "python -m pytest", "mkdocs")


def blocks(doc: str) -> list[tuple[str, str]]:
    """(language, code) of each fenced bash or python block of `doc`, in order."""
    return [(m.group(1), m.group(2)) for m in _BLOCK.finditer((ROOT / doc).read_text(encoding="utf-8"))]


def commands(code: str) -> list[list[str]]:
    """The `gmr` commands of a shell block, as argv lists (comments, installs and the test suite left out)."""
    out = []
    for line in code.splitlines():
        line = line.split(" #")[0].strip()
        if not line or line.startswith("#"):
            continue
        for part in (p.strip() for p in line.split("&&")):
            if part.startswith(_SKIP):
                continue
            argv = shlex.split(part)
            assert argv[0] == "gmr", f"a shell command the test does not know how to run: {part!r}"
            out.append(argv[1:])
    return out


def test_the_documents_have_blocks_to_run():
    for doc in DOCUMENTS:
        kinds = {k for k, _ in blocks(doc)}
        assert kinds == {"bash", "python"}, doc
        assert any(commands(c) for k, c in blocks(doc) if k == "bash"), doc


@pytest.mark.slow
@pytest.mark.parametrize("doc", DOCUMENTS)
def test_every_block_runs(doc, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), GMR_PROGRESS="0")
    namespace = {"__name__": "__readme__"}
    for kind, code in blocks(doc):
        if kind == "python":
            exec(compile(code, f"{doc} python block", "exec"), namespace)
            continue
        for argv in commands(code):
            done = subprocess.run([sys.executable, "-m", "gmr_jax", *argv], cwd=tmp_path, env=env,
                                  capture_output=True, text=True, timeout=1800)
            assert done.returncode == 0, f"gmr {' '.join(argv)}: exit {done.returncode}\n{done.stderr[-3000:]}"
            if argv[0] == "fit":
                lines = done.stdout.strip().splitlines()
                assert len(lines) <= 15, done.stdout  # one DOF: the model, its wells, the fit, where the rest is
