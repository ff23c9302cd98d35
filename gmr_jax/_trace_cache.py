"""Traced programs kept on disk between processes (a start-up cost, not a numerical feature).

JAX's persistent compilation cache (`use_compilation_cache`) skips XLA's compile in a new
process, but not the tracing and lowering that come before it: for `fit_local` (threshold
cross-validation, STLS) and `coordinate` (Hermite GLS and its Jacobian) those take ~1.5 s of
a warm `gmr fit`, more than the work itself. `disk_traced` keeps each traced program as a
`jax.export.Exported` (StableHLO, JAX's documented serialisation) next to the compilation
cache, keyed by the function, the static arguments, the shapes and dtypes of the array
arguments, the versions of JAX and its libraries, the device and a hash of gmr_jax's own
source (an edited gmr_jax never loads a stale program). A later call with the same key
deserialises it and runs it; its compile is then a compilation-cache hit.

Active only where `use_compilation_cache` turned the compilation cache on (the command line
does) and the call is not under a JAX transform (traced arguments: vmap, grad or
an enclosing jit use the plain `eqx.filter_jit` function). Any failure to export, write or
read falls back to the plain function: the cache can only save time, never change a result
(the exported program is the one `filter_jit` would compile; tests check equality).
"""

import functools
import hashlib
import os
import pickle
import sys
from collections.abc import Callable
from pathlib import Path

import equinox as eqx
import jax

FOLDER = "gmr_traces"
_MEMO: dict[str, tuple | None] = {}
_FINGERPRINT: list[str] = []


class _Leaf:
    """Where an output array goes in a stored output structure."""


def _fingerprint() -> str:
    """Versions, device and gmr_jax's source: part of every key."""
    if not _FINGERPRINT:
        import importlib.metadata as md

        h = hashlib.sha256()
        for pkg in ("jax", "jaxlib", "equinox", "lineax", "optimistix", "diffrax"):
            try:
                h.update(f"{pkg}={md.version(pkg)};".encode())
            except md.PackageNotFoundError:
                h.update(f"{pkg}=?;".encode())
        dev = jax.devices()[0]
        h.update(f"{sys.version_info[:2]};{dev.platform};{getattr(dev, 'device_kind', '')};"
                 f"{jax.config.jax_enable_x64};".encode())
        root = Path(__file__).parent
        for p in sorted(root.rglob("*.py")):
            h.update(p.relative_to(root).as_posix().encode())
            h.update(p.read_bytes())
        _FINGERPRINT.append(h.hexdigest())
    return _FINGERPRINT[0]


#: where traced programs are kept; set by `use_compilation_cache` (None: off)
FOLDER_IN_USE: list[Path | None] = [None]


#: fingerprints (source versions) whose programs are kept; older ones are deleted on a write
KEEP_VERSIONS = 4


def set_folder(cache_dir: str | None) -> None:
    """Keep traced programs under `cache_dir`/gmr_traces (None: do not)."""
    FOLDER_IN_USE[0] = None if cache_dir is None else Path(cache_dir) / FOLDER


def _prune(folder: Path) -> None:
    """Delete the programs of all but the `KEEP_VERSIONS` most recently written source versions
    (an edited or upgraded gmr_jax never reads them again)."""
    import shutil

    versions = sorted((p for p in folder.iterdir() if p.is_dir()), key=lambda p: p.stat().st_mtime)
    for old in versions[:-KEEP_VERSIONS]:
        shutil.rmtree(old, ignore_errors=True)


def _folder() -> Path | None:
    return FOLDER_IN_USE[0]


def _key(name: str, dyn_leaves, in_def, static) -> str:
    h = hashlib.sha256(_fingerprint().encode())
    h.update(name.encode())
    h.update(repr(in_def).encode())
    h.update(repr(jax.tree.flatten(static)).encode())
    for a in dyn_leaves:
        h.update(f"{a.shape}{a.dtype}{getattr(a, 'weak_type', False)};".encode())
    return h.hexdigest()[:40]


def _export(fn, static, in_def, leaves):
    box = {}

    def flat_fn(*xs):
        args, kwargs = eqx.combine(jax.tree.unflatten(in_def, xs), static)
        out = fn(*args, **kwargs)
        out_leaves = [a for a in jax.tree.leaves(out) if eqx.is_array(a)]
        # the output's structure as an object (arrays replaced by markers): it pickles where a
        # PyTreeDef of equinox Modules does not (their sentinels lose identity when unpickled)
        box["out"] = jax.tree.map(lambda a: _Leaf() if eqx.is_array(a) else a, out)
        return out_leaves

    exported = jax.export.export(jax.jit(flat_fn))(*leaves)
    return exported, box["out"]


def _load(path: Path):
    with open(path, "rb") as f:
        blob, out = pickle.load(f)
    return jax.export.deserialize(blob), out


def _save(path: Path, exported, out) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    blob = pickle.dumps((bytes(exported.serialize()), out))  # fails before any file is touched
    tmp = path.with_suffix(f".{os.getpid()}.tmp")
    try:
        tmp.write_bytes(blob)
        os.replace(tmp, path)  # atomic: a concurrent reader sees no file or the whole file
    finally:
        tmp.unlink(missing_ok=True)


def disk_traced(fn: Callable) -> Callable:
    """`eqx.filter_jit(fn)`, whose traced program is also kept on disk (module docstring)."""
    jitted = eqx.filter_jit(fn)
    name = f"{fn.__module__}.{fn.__qualname__}"

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        folder = _folder()
        dyn, static = eqx.partition((args, kwargs), eqx.is_array)
        leaves, in_def = jax.tree.flatten(dyn)
        if folder is None or any(isinstance(a, jax.core.Tracer) for a in leaves):
            return jitted(*args, **kwargs)
        try:
            key = _key(name, leaves, in_def, static)
        except Exception:  # an unhashable or unprintable static argument: no cache for it
            return jitted(*args, **kwargs)
        entry = _MEMO.get(key, ())
        if entry == ():
            path = folder / _fingerprint()[:16] / f"{name.rsplit('.', 1)[-1]}-{key}.pkl"
            entry = _entry(fn, path, static, in_def, leaves)
            _MEMO[key] = entry
        if entry is None:
            return jitted(*args, **kwargs)
        call, (template, out_def) = entry
        arrays = iter(call(*leaves))
        return jax.tree.unflatten(out_def, [next(arrays) if isinstance(z, _Leaf) else z
                                            for z in jax.tree.leaves(template)])

    wrapper.__wrapped_jit__ = jitted  # the plain jitted function (tests compare both)
    return wrapper


def _entry(fn, path: Path, static, in_def, leaves):
    """(jitted call of the exported program, output structure), from disk or exported now and
    written; None when this function cannot be exported (then the plain jit is used)."""
    try:
        exported, out = _load(path)
    except Exception:
        try:
            exported, out = _export(fn, static, in_def, leaves)
        except Exception:
            return None
        try:
            _save(path, exported, out)
            _prune(path.parent.parent)
        except Exception:  # read-only or full disk: this process still uses what it traced
            pass
    return jax.jit(exported.call), (out, jax.tree.structure(out))
