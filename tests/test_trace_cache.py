"""Traced programs on disk (`gmr_jax._trace_cache`): same results as the plain jit, loaded in a
'new process' (the in-process memo cleared), a corrupt file ignored, transforms bypass it."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as gmr
from gmr_jax import _trace_cache as tc


@pytest.fixture
def trace_dir(tmp_path, monkeypatch):
    monkeypatch.setattr(tc, "FOLDER_IN_USE", [tmp_path / tc.FOLDER])
    monkeypatch.setattr(tc, "_MEMO", {})
    return tmp_path / tc.FOLDER


def _data(seed=0, n=600):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-2
    x = 0.1 * np.sin(2.1 * t) + 0.03 * np.sin(5.3 * t) + 1e-4 * rng.normal(size=n)
    v = np.gradient(x, t)
    y = 4.0 * x + 2.0 * x**3 + 0.3 * v
    return x, v, y


def _same(a, b):
    la, lb = jax.tree.leaves(a), jax.tree.leaves(b)
    assert jax.tree.structure(a) == jax.tree.structure(b)
    for p, q in zip(la, lb):
        np.testing.assert_array_equal(np.asarray(p), np.asarray(q))


@pytest.mark.slow  # four to five compilations of the fits (~12 s cold); the default tier's in-process
# CLI tests run with the trace cache on (conftest points GMR_CACHE_DIR at the test cache)
def test_fit_local_from_disk_equals_plain_jit(trace_dir):
    x, v, y = _data()
    lib, sel = gmr.Library(3, 1), gmr.AutoThreshold(n_grid=8, n_folds=3)  # the CV path, kept small
    ref = gmr.fit_local.__wrapped_jit__(x, v, y, lib, gmr.STLS(), sel, throw=False)
    first = gmr.fit_local(x, v, y, lib, gmr.STLS(), sel, throw=False)  # exported and written
    files = list(trace_dir.glob("*/fit_local-*.pkl"))
    assert len(files) == 1
    tc._MEMO.clear()  # a new process: only the file is left
    second = gmr.fit_local(x, v, y, lib, gmr.STLS(), sel, throw=False)
    assert type(second) is type(ref) and type(second.value) is gmr.LocalFit
    _same(first, ref)
    _same(second, ref)
    assert second.result == gmr.RESULTS.successful
    # another shape, another static argument: other entries
    gmr.fit_local(x[:500], v[:500], y[:500], lib, gmr.STLS(), None, throw=False)
    gmr.fit_local(x[:500], v[:500], y[:500], gmr.Library(3, 2), gmr.STLS(), None, throw=False)
    assert len(list(trace_dir.glob("*/fit_local-*.pkl"))) == 3


@pytest.mark.slow  # four to five compilations of the fits (~12 s cold); the default tier's in-process
# CLI tests run with the trace cache on (conftest points GMR_CACHE_DIR at the test cache)
def test_coordinate_from_disk_equals_plain_jit(trace_dir):
    fits = []
    for x0 in (-1.0, 1.0):
        x, v, y = _data()
        fits.append(gmr.fit_local(x + x0, v, 4.0 * (x + x0) ** 3 - 4.0 * (x + x0) + 0.3 * v,
                                  gmr.Library(3, 1), gmr.STLS(), None, throw=False).value)
    stacked = jax.tree.map(lambda *a: jnp.stack(a), *fits)
    ref = gmr.coordinate.__wrapped_jit__(stacked, gmr.Library(3, 1), throw=False)
    gmr.coordinate(stacked, gmr.Library(3, 1), throw=False)
    tc._MEMO.clear()
    got = gmr.coordinate(stacked, gmr.Library(3, 1), throw=False)
    _same(got, ref)


def test_corrupt_file_falls_back(trace_dir):
    x, v, y = _data()
    lib = gmr.Library(3, 1)
    ref = gmr.fit_local.__wrapped_jit__(x, v, y, lib, gmr.STLS(), None, throw=False)
    gmr.fit_local(x, v, y, lib, gmr.STLS(), None, throw=False)
    (path,) = trace_dir.glob("*/fit_local-*.pkl")
    path.write_bytes(b"not a pickle")
    tc._MEMO.clear()
    _same(gmr.fit_local(x, v, y, lib, gmr.STLS(), None, throw=False), ref)  # traced again, file rewritten
    tc._MEMO.clear()
    _same(gmr.fit_local(x, v, y, lib, gmr.STLS(), None, throw=False), ref)


def test_transforms_and_off_bypass_the_files(trace_dir, monkeypatch):
    x, v, y = _data()
    lib = gmr.Library(3, 1)
    def coef(yy):
        return gmr.fit_local(x, v, yy, lib, gmr.STLS(), None, throw=False).value.coef

    batched = jax.vmap(coef)(jnp.stack([y, 2 * y]))
    np.testing.assert_allclose(batched[1], 2 * batched[0], rtol=1e-8, atol=1e-10)
    assert not trace_dir.exists()
    monkeypatch.setattr(tc, "FOLDER_IN_USE", [None])
    gmr.fit_local(x, v, y, lib, gmr.STLS(), None, throw=False)
    assert not trace_dir.exists()


def test_key_changes_with_source_and_shapes(monkeypatch):
    a = [np.zeros(3)]
    k1 = tc._key("f", a, jax.tree.structure(a), None)
    assert k1 == tc._key("f", [np.ones(3)], jax.tree.structure(a), None)  # values are not in the key
    assert k1 != tc._key("f", [np.zeros(4)], jax.tree.structure(a), None)
    assert k1 != tc._key("f", [np.zeros(3, np.float32)], jax.tree.structure(a), None)
    monkeypatch.setattr(tc, "_FINGERPRINT", ["edited source"])
    assert k1 != tc._key("f", a, jax.tree.structure(a), None)


def test_old_source_versions_pruned(trace_dir, monkeypatch):
    x, v, y = _data()
    for k in range(tc.KEEP_VERSIONS + 2):
        monkeypatch.setattr(tc, "_FINGERPRINT", [f"{k:016d}"])
        tc._MEMO.clear()
        gmr.fit_local(x, v, y, gmr.Library(3, 1), gmr.STLS(), None, throw=False)
    kept = sorted(p.name for p in trace_dir.iterdir())
    assert len(kept) == tc.KEEP_VERSIONS and kept[-1] == f"{tc.KEEP_VERSIONS + 1:016d}"
