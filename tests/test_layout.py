"""The public surface: no name that is both a module and an object, no private imports outside
the package, a version from the package metadata."""

import ast
import importlib
import pkgutil
from pathlib import Path

import gmr_jax

ROOT = Path(__file__).resolve().parents[1]


def test_no_public_name_shadows_a_submodule():
    submodules = {m.name for m in pkgutil.iter_modules(gmr_jax.__path__)}
    for name in dir(gmr_jax):
        if name.startswith("_") or name not in submodules:
            continue
        # a public submodule is fine only when the attribute *is* that module
        mod = importlib.import_module(f"gmr_jax.{name}")
        assert getattr(gmr_jax, name) is mod, f"gmr_jax.{name} hides the submodule gmr_jax.{name}"
    # importing every submodule must not rebind a public name to something else
    before = {n: getattr(gmr_jax, n) for n in dir(gmr_jax) if not n.startswith("_")}
    for m in pkgutil.walk_packages(gmr_jax.__path__, "gmr_jax."):
        importlib.import_module(m.name)
    after = {n: getattr(gmr_jax, n) for n in before}
    changed = [n for n in before if before[n] is not after[n]]
    assert not changed, f"importing submodules rebinds gmr_jax.{changed}"
    for name in ("systems", "metrics", "data", "plots"):
        for attr in dir(getattr(gmr_jax, name)):
            if attr.startswith("_"):
                continue
            sub = f"gmr_jax.{name}.{attr}"
            if importlib.util.find_spec(sub) is not None:
                raise AssertionError(f"{sub} is both a module and a name")


def _private_imports(path: Path) -> list[str]:
    if path.suffix == ".ipynb":
        import json

        cells = json.loads(path.read_text())["cells"]
        source = "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "code")
        source = "\n".join(line for line in source.splitlines() if not line.lstrip().startswith(("%", "!")))
    else:
        source = path.read_text()
    bad = []
    for node in ast.walk(ast.parse(source)):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            if node.value.id in ("g", "gmr", "gmr_jax") and node.attr.startswith("_") \
                    and node.attr not in ("__version__",):
                bad.append(f"{node.value.id}.{node.attr}")
        for n in names:
            parts = n.split(".")
            if parts[0] == "gmr_jax" and any(p.startswith("_") for p in parts[1:]):
                bad.append(n)
    return bad


def test_notebooks_studies_and_benchmarks_use_only_the_public_api():
    files = [p for d in ("notebooks", "studies", "benchmarks") for p in (ROOT / d).rglob("*")
             if p.suffix in (".py", ".ipynb") and ".ipynb_checkpoints" not in p.parts]
    assert files, "no notebooks, studies or benchmarks found"
    offenders = {str(p.relative_to(ROOT)): b for p in files if (b := _private_imports(p))}
    assert not offenders, f"private gmr_jax imports outside the package: {offenders}"


def test_private_import_detector_catches_each_form(tmp_path):
    p = tmp_path / "x.py"
    p.write_text("import gmr_jax._fit\nfrom gmr_jax._simulate import _integrate\n"
                 "from gmr_jax.systems import _kresling\nimport gmr_jax as g\ng._solution\n")
    assert len(_private_imports(p)) >= 4


def test_version_comes_from_metadata():
    import importlib.metadata as md

    try:
        assert gmr_jax.__version__ == md.version("gmr_jax")
    except md.PackageNotFoundError:
        assert gmr_jax.__version__ == "0+unknown"
    assert (Path(gmr_jax.__file__).parent / "py.typed").exists()


def _imported_modules(path: Path, source: str | None = None) -> set[str]:
    """Every module `path` (a module of gmr_jax; its text, or `source` in its place) imports, absolute, at any
    depth of its code: `import a.b`, `from a import b` (a and a.b) and relative imports resolved against the
    module's package."""
    package = path.relative_to(ROOT).with_suffix("").parts[:-1]  # ("gmr_jax", "_coordination")
    if path.name == "__init__.py":
        package = path.relative_to(ROOT).parts[:-1]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8") if source is None else source)):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = list(package[: len(package) - node.level + 1]) if node.level else []
            mod = ".".join(base + ([node.module] if node.module else []))
            out.add(mod)
            out |= {f"{mod}.{a.name}" for a in node.names}
    return out


#: (lower layer, upper layer): no module under the first imports anything under the second
LAYERS = [("_coordination", "_reconstruct"), ("_model", "_discover"), ("_simulate", "_discover")]


def _layer_violations(root: Path) -> list[str]:
    bad = []
    for lower, upper in LAYERS:
        for path in sorted((root / "gmr_jax" / lower).rglob("*.py")):
            hits = sorted(m for m in _imported_modules(path)
                          if m == f"gmr_jax.{upper}" or m.startswith(f"gmr_jax.{upper}."))
            bad += [f"{path.relative_to(root)} imports {m}" for m in hits]
    return bad


def test_lower_layers_import_nothing_from_the_upper_ones():
    """The coordination imports nothing from the reconstruction, the model and the simulation nothing from
    discovery (absolute and relative imports, at module level or inside a function)."""
    assert _layer_violations(ROOT) == []


def test_layer_check_catches_each_import_form():
    path = ROOT / "gmr_jax" / "_coordination" / "_probe.py"  # not written: its source is given
    for line in ("from .._reconstruct._slow import apply_band", "from gmr_jax._reconstruct import _slow",
                 "import gmr_jax._reconstruct._slow", "from .. import _reconstruct",
                 "def f():\n    from .._reconstruct._filter_gain import apply_gain"):
        found = _imported_modules(path, line)
        assert any(m == "gmr_jax._reconstruct" or m.startswith("gmr_jax._reconstruct.") for m in found), line
    assert not any("_reconstruct" in m for m in _imported_modules(path, "from .._fit._library import Library"))


def test_every_decision_of_the_reconstruction_is_listed_where_it_lives():
    """docs/explanation/decisions.md names, per decision, the module and the functions that make it:
    each exists, and the table stays within twelve decisions."""
    rows = [line.split("|")[1:-1] for line in (ROOT / "docs/explanation/decisions.md").read_text().splitlines()
            if line.startswith("| ") and line.split("|")[1].strip().isdigit()]
    assert 0 < len(rows) <= 12
    for row in rows:
        path, names = row[-1].strip().strip("`").split(": ")
        module = importlib.import_module("gmr_jax." + path.removesuffix(".py").replace("/", "."))
        for name in names.split(", "):
            assert hasattr(module, name), f"{path} has no {name}"
    assert len(gmr_jax.reconstruct.__doc__.splitlines()) <= 40
