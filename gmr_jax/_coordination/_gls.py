"""Covariance-weighted coordination: the Hermite problem of Eqs. (15)-(18) solved in the
generalised-least-squares sense, with the global degree chosen by a chi-squared test.

The Hermite interpolant of degree K (Eq. 18) reproduces every local Taylor coefficient
exactly, noise included: with three wells and local cubics (K = 11) a 2 % error of one local
cubic coefficient, within its standard error, becomes a 2 % error of the global restoring force.
When the local fits carry more constraints than the global law needs, a lower degree K' fitted
to all of them, each weighted by the inverse of its local covariance, averages that noise out.

Rule: K' is the smallest degree, at least 2n - 1 for n wells (room for the n - 1 saddles between
them; the damping polynomial, which has none, from 0) and below K, whose weighted residual is
consistent with the local covariances (chi-squared with m - K' - 1 degrees of freedom, p > `alpha`);
if none is, K' = K and the solution is the paper's exact Hermite interpolant. For a restoring force
(`confining=True`; `reconstruct` uses it where the paper route's degree is even, and for a cell that
borrowed orders from cells of its design) only odd degrees count (only they can confine, with a
positive leading coefficient: F -> +-inf on both sides); `reconstruct` checks the sign where it
matters: a cell that borrowed orders and whose law turns outward within the reach of its motions
takes a lower degree (`max_degree`). The smallest accepted degree, at most `max_degree`; where none
is accepted, the exact interpolant (K), or, for a confining law of even K or K above `max_degree`,
the highest odd degree below it, fitted to all the conditions. Known zeros given no variance (a zero
covariance diagonal) carry a variance floor far below the kept terms', so they act as (nearly) hard
constraints, as in the Hermite solve; `coordinate` gives each term STLS removed, and each the
t-screen zeroed, the variance it would have had kept (`with_dropped`, `LocalFit.dropped`), so
only zeros that come with no such variance (fits made without it) still act so.
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .._fit._householder import back_substitute, cholesky, householder_qr, singular_values, triangular_inverse
from ._hermite import confluent_vandermonde, monomial_map, scaling

#: Relative variance floor of the known zeros (terms STLS removed).
ZERO_FLOOR = 1e-12


def _whitener(cov: Float[Array, "n o o"], active: Float[Array, "n o"]):
    """Per-well inverse Cholesky factors of the active block (identity elsewhere)."""
    n, o, _ = cov.shape
    both = active[:, :, None] * active[:, None, :]
    cov = cov * both
    diag = jnp.diagonal(cov, axis1=1, axis2=2)
    scale = jnp.max(diag, axis=1, keepdims=True)
    floor = ZERO_FLOOR * jnp.where(scale > 0, scale, 1.0) + 1e-300
    cov = cov + jax.vmap(jnp.diag)(jnp.where(active > 0, floor, 1.0))
    # plain-XLA kernels, not LAPACK's batch kernels (`_fit/_householder.py`: they deadlock jaxlib 0.10.2)
    inv = jax.vmap(lambda c: triangular_inverse(cholesky(c), lower=True))(cov)
    return inv * active[:, :, None]  # rows of inactive orders vanish


def weighted_system(nodes, taylor, order, cov):
    """The whitened confluent Vandermonde system of `hermite_gls` in scaled coordinates:
    `(a_w, b_w, c, h, active)` with the monomial coefficients of the fit in s = (x - c) / h."""
    n, rp1 = taylor.shape
    size = n * rp1
    c, h = scaling(nodes)
    s = (nodes - c) / h
    vand = confluent_vandermonde(s, rp1 - 1, size).reshape(n, rp1, size)
    jpow = jnp.arange(rp1)
    hp = h ** jpow.astype(taylor.dtype)
    rhs = taylor * hp[None, :]
    scov = cov * hp[None, :, None] * hp[None, None, :]
    active = (jpow[None, :] <= order[:, None]).astype(taylor.dtype)
    winv = _whitener(scov, active)
    a_w = jnp.einsum("nij,njk->nik", winv, vand).reshape(size, size)
    b_w = jnp.einsum("nij,nj->ni", winv, rhs).reshape(size)
    return a_w, b_w, c, h, active


def nested_fit(r, qtb, k):
    """The least-squares coefficients on columns 0..k from the QR of all columns (R, Q^T b): the
    first k + 1 Householder steps are that smaller problem's QR, so its solution is R's leading
    block back-substituted (zeros above k)."""
    size = r.shape[0]
    p = jnp.arange(size)
    block = (p[:, None] <= k) & (p[None, :] <= k)
    return back_substitute(jnp.where(block, r, jnp.eye(size, dtype=r.dtype)), jnp.where(p <= k, qtb, 0.0))


def weighted_fit(a_w, b_w, k):
    """Least-squares fit of degree `k` (scaled monomials) to the whitened (square) system; returns
    the coefficients and the chi-squared."""
    coef = nested_fit(*householder_qr(a_w, b_w), k)
    return coef, jnp.sum((a_w @ coef - b_w) ** 2)


def kept_condition(a_w, k):
    """2-norm condition number of the whitened system's columns 0..k (a diagnostic: computed
    once, at the chosen degree, and not differentiated)."""
    size = a_w.shape[1]
    keep = (jnp.arange(size) <= k).astype(a_w.dtype)
    sv = singular_values(jax.lax.stop_gradient(a_w * keep[None, :]))  # descending
    return sv[0] / sv[jnp.clip(jnp.sum(keep).astype(int) - 1, 0, size - 1)]


def hermite_gls(
    nodes: Float[Array, " n"],
    taylor: Float[Array, "n orders"],
    order: Int[Array, " n"],
    cov: Float[Array, "n orders orders"],
    alpha: float = 0.05,
    confining: bool = False,
    max_degree: Int[Array, ""] | int | None = None,
    min_degree: int | None = None,
):
    """Global polynomial from local Taylor coefficients and their covariances (Eqs. 15-18
    as generalised least squares; module docstring for the degree rule).

    **Arguments:**

    - `nodes`, `taylor`, `order`: as `hermite_interpolate`.
    - `cov`: covariance of each point's Taylor vector (n, r + 1, r + 1).
    - `alpha`: level of the chi-squared test.
    - `confining`: the polynomial is a restoring force: odd degrees only (module docstring).
      Kresling chain, 1 mm, seed 3, cell 4 (F''' resolved at the deployed well only, local
      orders 2 and 3): the exact sextic was 6.55 % off and cannot confine, the quintic 1.3 %.
    - `max_degree`: the highest degree allowed (None: no bound; a traced integer does not
      recompile); an exact interpolant of higher degree gives way to the highest allowed one.
    - `min_degree`: the lowest degree tested (None: 2n - 1, room for the n - 1 saddles of a
      restoring force; the damping polynomial has no saddles to make room for and takes 0).

    **Returns:** `(coeffs, degree, cond, stats)`: monomial coefficients (zero above the degree),
    the chosen degree K', the condition number of the scaled weighted system at K', and
    `stats` with `K_hermite` (Eq. 18), `chi2`, `dof` and `p` of the chosen degree.
    """
    n, rp1 = taylor.shape
    size = n * rp1
    a_w, b_w, c, h, active = weighted_system(nodes, taylor, order, cov)
    m = jnp.sum(active)
    k_herm = n - 1 + jnp.sum(order)
    p = jnp.arange(size)
    # Nested least squares from one QR (the fit of degree k uses the first k + 1 columns, and a
    # Householder QR's first k + 1 steps are that fit's QR): chi2_k = sum_{i > k} (Q^T b)_i^2, no
    # cancellation; the coefficients are then back-substituted at the chosen degree only
    r, qtb = householder_qr(a_w, b_w)  # a_w is square (size x size)
    tail = jnp.cumsum((qtb**2)[::-1])[::-1]
    chi2 = jnp.concatenate([tail[1:], jnp.zeros(1, tail.dtype)])
    dof = m - p - 1
    pval = jnp.where(dof > 0, jax.scipy.special.gammaincc(jnp.maximum(dof, 1) / 2, chi2 / 2), 0.0)
    # confining: only odd degrees confine (F -> +-inf on both sides); an even K' is never chosen, and
    # an even K (a term resolved at one well only: Kresling 1 mm seed 3, cell 4, local orders 2 and 3, the
    # exact sextic 6.55 % off) gives way to the highest odd degree below it, fitted to all.
    cap = p <= (size if max_degree is None else max_degree)
    odd = ((p % 2 == 1) | (not confining)) & (p >= (2 * n - 1 if min_degree is None else min_degree))
    ok = (pval > alpha) & odd & (p < k_herm) & cap
    below = odd & (p < k_herm) & cap
    lower = confining & (k_herm % 2 == 0) | ~cap[jnp.clip(k_herm, 0, size - 1)]
    fallback = jnp.where(lower & jnp.any(below), jnp.max(jnp.where(below, p, 0)), k_herm)
    degree = jnp.where(jnp.any(ok), jnp.argmax(ok), fallback)
    # At K' = K the weighted fit is the exact interpolant (square, nonsingular system).
    coef_s = nested_fit(r, qtb, degree)
    stats = {"K_hermite": k_herm, "chi2": chi2[degree], "dof": dof[degree], "p": pval[degree]}
    return monomial_map(c, h, size) @ coef_s, degree, kept_condition(a_w, degree), stats
