"""The documentation: docstring examples run as doctests, and the site builds strictly.

- Doctests (default tier): every `>>>` example in the docstrings of the public API (the names
  `gmr_jax/__init__.py` exports and those of the `systems`, `metrics`, `data`, `plots`
  namespaces, methods included) runs with an empty namespace, so each example imports what it
  uses, as a reader would.
- Site (slow tier): `mkdocs build --strict` (mkdocs.yml; broken links, anchors, references and
  griffe warnings fail it) into a temporary folder, with every notebook and the results index
  rendered. Needs the `docs` extra (`pip install -e ".[docs]"`); skipped without it.
"""

import doctest
import importlib.util
import inspect
import os
import subprocess
import sys
from pathlib import Path

import pytest

import gmr_jax

ROOT = Path(__file__).resolve().parents[1]
NAMESPACES = ("systems", "metrics", "data", "plots")


def _public_objects():
    """(qualified name, object) for every public name of gmr_jax and of its namespaces."""
    yield "gmr_jax", gmr_jax
    for name in sorted(n for n in dir(gmr_jax) if not n.startswith("_")):
        obj = getattr(gmr_jax, name)
        yield f"gmr_jax.{name}", obj
        if name in NAMESPACES:
            for sub in sorted(n for n in dir(obj) if not n.startswith("_")):
                yield f"gmr_jax.{name}.{sub}", getattr(obj, sub)


def _doctests():
    finder = doctest.DocTestFinder(recurse=True, exclude_empty=True)
    found, seen = {}, set()
    for qualname, obj in _public_objects():
        if not (callable(obj) or inspect.ismodule(obj)):
            continue  # constants (numbers, dicts) carry no docstring of their own (jitted functions
            # are callables, not functions, hence `callable`)
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        for test in finder.find(obj, qualname, globs={}):
            if test.examples:
                found.setdefault(test.name, test)
    return [found[k] for k in sorted(found)]


DOCTESTS = _doctests()


def test_the_public_api_has_docstring_examples():
    # the examples below are the ones a reader meets first; losing them silently is a regression
    names = {t.name for t in DOCTESTS}
    for expected in ("gmr_jax.Library", "gmr_jax.stls", "gmr_jax.from_terms", "gmr_jax.predict",
                     "gmr_jax.load_model", "gmr_jax.simulate", "gmr_jax.metrics.equilibria"):
        assert any(n == expected or n.startswith(expected + ".") for n in names), expected


@pytest.mark.parametrize("test", DOCTESTS, ids=[t.name for t in DOCTESTS])
def test_docstring_examples(test):
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    out = []
    result = runner.run(test, out=out.append)
    assert result.failed == 0, "".join(out)


_DOCS_MODULES = ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python", "mkdocs_jupyter")


def _missing_docs_modules():
    missing = []
    for mod in _DOCS_MODULES:
        try:
            if importlib.util.find_spec(mod) is None:
                missing.append(mod)
        except ModuleNotFoundError:
            missing.append(mod)
    return missing


@pytest.mark.slow
def test_docs_site_builds_strictly(tmp_path):
    missing = _missing_docs_modules()
    if missing:
        pytest.skip(f"docs tooling not installed ({', '.join(missing)}): pip install -e \".[docs]\"")
    site = tmp_path / "site"
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
    )
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, log[-6000:]
    warnings = [line for line in log.splitlines() if line.startswith(("WARNING", "ERROR"))]
    assert not warnings, "\n".join(warnings)
    # what the hook adds from outside docs/: the results index, its figures, every notebook
    assert (site / "results" / "index.html").is_file()
    for fig in (ROOT / "results" / "figures").glob("*.png"):
        assert (site / "results" / "figures" / fig.name).is_file(), fig.name
    notebooks = sorted((ROOT / "notebooks").glob("*.ipynb"))
    for nb in notebooks:
        page = site / "notebooks" / nb.stem / "index.html"
        assert page.is_file(), f"{nb.name} was not rendered"
    # the API reference is generated from the docstrings (a page per group, not empty)
    api = (site / "api" / "fitting" / "index.html").read_text(encoding="utf-8")
    assert "Sequentially thresholded least squares" in api
    cli = (site / "howto" / "cli" / "index.html").read_text(encoding="utf-8")
    assert "gmr fit" in cli and "--threshold" in cli
