"""No batched LAPACK call in the programs the library runs under vmap or jacfwd.

jaxlib 0.10.2 hands a batch of small LAPACK problems (QR, SVD, eigh, Cholesky, LU, triangular
solves) to XLA's intra-op thread pool and blocks until it is done; two such calls running at
once on a 2-thread pool wait for each other for ever (`gmr_jax/_fit/_householder.py`). CI hung
twice this way: in `select_threshold` and, in stop 29's slow tier, in `coordinate` (the
restoring and damping GLS each mapped a QR, an SVD and triangular solves over the candidate
degrees). The library therefore factorises with plain XLA operations wherever a batch arises;
these tests walk the jaxprs of those programs (every sub-jaxpr included) and fail on any linear
algebra primitive whose operands carry a batch axis.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._discover import _select
from gmr_jax._model._uncertainty import covariance_root

#: jax primitives lowered to LAPACK custom calls on the CPU
LAPACK = {"lu", "cholesky", "triangular_solve", "qr", "geqrf", "geqp3", "householder_product", "svd", "eigh",
          "eig", "schur", "hessenberg", "tridiagonal", "tridiagonal_solve"}


def _sub_jaxprs(eqn):
    for p in eqn.params.values():
        for q in (p if isinstance(p, (list, tuple)) else [p]):
            if isinstance(q, jax.extend.core.ClosedJaxpr):
                yield q.jaxpr
            elif isinstance(q, jax.extend.core.Jaxpr):
                yield q


def batched_lapack(jaxpr) -> list[str]:
    """The LAPACK-lowered equations of `jaxpr` (recursively) with operands of rank > 2."""
    found = []
    for eqn in jaxpr.eqns:
        if eqn.primitive.name in LAPACK and any(getattr(v.aval, "ndim", 0) > 2 for v in eqn.invars):
            found.append(f"{eqn.primitive.name}{[tuple(v.aval.shape) for v in eqn.invars]}")
        for sub in _sub_jaxprs(eqn):
            found += batched_lapack(sub)
    return found


def _found(fn, *args):
    return batched_lapack(jax.make_jaxpr(fn)(*args).jaxpr)


def test_the_audit_sees_a_batched_lapack_call():
    """The walker finds what it is for: a vmapped QR, and one inside a scan's body."""
    a = jnp.ones((4, 6, 3))
    assert _found(jax.vmap(jnp.linalg.qr), a)
    assert _found(lambda a: jax.lax.scan(lambda c, m: (c, jax.vmap(jnp.linalg.svd)(m)), 0.0, a[None])[1], a)
    assert _found(jnp.linalg.qr, a[0]) == []  # one matrix: LAPACK runs it inline, no pool


def _fits(n=3, library=g.Library(5, 5), seed=0):
    rng = np.random.default_rng(seed)
    p = library.n_terms
    root = rng.normal(size=(n, p, p)) * 1e-3
    return g.LocalFit(equilibrium=jnp.linspace(-1.0, 1.0, n), coef=jnp.asarray(rng.normal(size=(n, p))),
                      covariance=jnp.asarray(root @ np.swapaxes(root, 1, 2)), threshold=jnp.zeros(n),
                      rss=jnp.ones(n), n_samples=jnp.full(n, 100.0))


@pytest.mark.parametrize("method,confining", [("gls", False), ("gls", True), ("hermite", False)])
def test_coordination_has_no_lapack_batch(method, confining):
    lib = g.Library(5, 5)
    fits = _fits(3, lib)
    fn = lambda f: g.coordinate(f, lib, method=method, confining=confining, throw=False).value  # noqa: E731
    assert _found(fn, fits) == []
    # and mapped over several DOFs' fits, as a user sweeping datasets would
    stacked = jax.tree_util.tree_map(lambda *a: jnp.stack(a), _fits(3, lib, 1), _fits(3, lib, 2))
    assert _found(jax.vmap(fn), stacked) == []


def test_hermite_solvers_under_vmap_have_no_lapack_batch():
    nodes = jnp.array([[-1.0, 0.0, 1.0]] * 4)
    taylor = jnp.ones((4, 3, 4))
    order = jnp.full((4, 3), 3)
    cov = jnp.broadcast_to(jnp.eye(4) * 1e-4, (4, 3, 4, 4))
    assert _found(jax.vmap(g.hermite_interpolate), nodes, taylor, order) == []
    assert _found(jax.vmap(lambda *a: g.hermite_gls(*a)[0]), nodes, taylor, order, cov) == []


def test_local_fits_and_threshold_selection_have_no_lapack_batch():
    lib = g.Library(5, 5)
    t = jnp.linspace(0.0, 2.0, 400)
    x = 0.01 * jnp.sin(7 * t)
    v = 0.07 * jnp.cos(7 * t)
    y = -50.0 * x - 0.1 * v
    fn = lambda x, v, y: g.fit_local(x, v, y, lib, throw=False).value.coef  # noqa: E731
    assert _found(fn, x, v, y) == []
    assert _found(jax.vmap(fn), jnp.stack([x, 2 * x]), jnp.stack([v, 2 * v]), jnp.stack([y, 2 * y])) == []


def test_uncertainty_and_discovery_selection_have_no_lapack_batch():
    cov = jnp.asarray(np.stack([np.eye(6) * (k + 1) for k in range(3)]))
    assert _found(covariance_root, cov) == []
    G = jnp.asarray(np.eye(5) * 3.0 + 0.1)
    Gf, bf, yyf = jnp.stack([G, G, G]), jnp.ones((3, 5)), jnp.ones(3)
    masks = jnp.array([[1, 1, 0, 0, 1], [1, 0, 1, 0, 1]], bool)
    assert _found(_select._cv_many, Gf, bf, yyf, masks, jnp.zeros(Gf.shape[1:])) == []
    assert _found(_select._rss_boot, Gf, bf, yyf, jnp.stack([masks] * 3)) == []
    assert _found(_select._coef_boot, Gf, bf, masks[0]) == []


def test_plain_xla_kernels_match_lapack_under_jit_vmap_and_grad():
    """The replacements (`_fit/_householder.py`) against NumPy's LAPACK: singular values, Cholesky,
    triangular inverse, the PSD square root; jit, vmap, and grad against central differences."""
    from gmr_jax._fit._householder import cholesky, psd_root, singular_values, triangular_inverse

    rng = np.random.default_rng(3)
    for m, p in [(36, 18), (18, 18), (7, 3), (5, 1)]:
        a = rng.normal(size=(m, p)) * np.logspace(0, -6, p)[None, :]  # graded columns: six decades
        ref = np.linalg.svd(a, compute_uv=False)
        np.testing.assert_allclose(np.asarray(jax.jit(singular_values)(jnp.asarray(a))), ref, rtol=1e-12)
    a = rng.normal(size=(4, 9, 5))
    np.testing.assert_allclose(np.asarray(jax.vmap(singular_values)(jnp.asarray(a))),
                               np.linalg.svd(a, compute_uv=False), rtol=1e-12)
    b = rng.normal(size=(6, 6))
    spd = b @ b.T + 0.5 * np.eye(6)
    lo = np.asarray(jax.jit(cholesky)(jnp.asarray(spd)))
    np.testing.assert_allclose(lo, np.linalg.cholesky(spd), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(np.asarray(triangular_inverse(jnp.asarray(lo), lower=True)), np.linalg.inv(lo),
                               rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(np.asarray(triangular_inverse(jnp.asarray(lo.T), lower=False)),
                               np.linalg.inv(lo.T), rtol=1e-11, atol=1e-12)
    c = rng.normal(size=(8, 5))
    psd = c @ c.T  # rank 5 of 8: three zero eigenvalues
    root = np.asarray(psd_root(jnp.asarray(psd)))
    np.testing.assert_allclose(root @ root.T, psd, atol=1e-12 * np.abs(psd).max())
    # gradients against central differences
    d = rng.normal(size=(5, 5))
    for f in (lambda a: jnp.sum(singular_values(a) ** 1.5), lambda a: jnp.sum(cholesky(a @ a.T + jnp.eye(5)) ** 2)):
        grad = np.asarray(jax.grad(f)(jnp.asarray(d)))
        h, e = 1e-6, np.zeros_like(d)
        fd = np.zeros_like(d)
        for i in np.ndindex(d.shape):
            e[...] = 0.0
            e[i] = h
            fd[i] = (float(f(jnp.asarray(d + e))) - float(f(jnp.asarray(d - e)))) / (2 * h)
        np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-7)
