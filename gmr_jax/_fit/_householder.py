"""Thin QR by Householder reflections in plain XLA operations.

`jnp.linalg.qr` on the CPU calls LAPACK (geqrf/orgqr) through jaxlib kernels that, for a batch
(any `vmap`), hand the batch to XLA's intra-op thread pool and block until it is done. When
the thunk executor runs as many such calls at once as the pool has threads (2 on a 2-core
machine: the vmapped STLS of the threshold selection does), every pool thread waits for work
queued behind it and the process hangs for ever (seen here: `gmr fit --method gmc-sindy` and CI;
jaxlib 0.10.2 `ParallelBatchMap`, compiled out in later jaxlib). The STLS kernels are vmapped by
design, so they factorise with this instead: p reflections, each a rank-one update, no custom
call, the same O(m p^2) work, backward stable, differentiable (a fixed-length loop).
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float


def householder_qr(
    a: Float[Array, " m p"], b: Float[Array, " m *k"]
) -> tuple[Float[Array, " p p"], Float[Array, " p *k"]]:
    """R and Q^T b of the thin QR a = Q R (m >= p): min ||b - a c|| = min ||Q^T b - R c|| over c
    (plus the part of b outside range(a)); b is a vector or a matrix of right-hand sides. R's
    diagonal may be negative (as LAPACK's)."""
    m, p = a.shape
    rows = jnp.arange(m)

    def step(k, carry):
        a, b = carry
        x = jnp.where(rows >= k, a[:, k], 0.0)
        xx = x @ x
        nx = jnp.where(xx > 0, jnp.sqrt(jnp.where(xx > 0, xx, 1.0)), 0.0)
        alpha = -jnp.where(x[k] >= 0, 1.0, -1.0) * nx
        v = x - alpha * (rows == k)
        vv = v @ v
        beta = jnp.where(vv > 0, 2.0 / jnp.where(vv > 0, vv, 1.0), 0.0)
        a = a - beta * jnp.outer(v, v @ a)
        b = b - beta * (v * (v @ b) if b.ndim == 1 else v[:, None] * (v @ b)[None, :])
        return a, b

    a, b = jax.lax.fori_loop(0, p, step, (a, b))
    return jnp.triu(a[:p]), b[:p]


def back_substitute(r: Float[Array, "p p"], b: Float[Array, " p"]) -> Float[Array, " p"]:
    """c with R c = b for upper-triangular R, in plain XLA operations (jax's `solve_triangular`
    is LAPACK trsm on the CPU, the same batch-kernel family as the QR)."""
    p = r.shape[0]

    def step(i, c):
        k = p - 1 - i
        return c.at[k].set((b[k] - r[k] @ c) / r[k, k])  # c[j] = 0 for j <= k so far

    return jax.lax.fori_loop(0, p, step, jnp.zeros_like(b))


def inverse_logdet(g: Float[Array, "p p"]) -> tuple[Float[Array, "p p"], Float[Array, ""]]:
    """g^-1 and log|det g| by the QR above and back substitution (no LAPACK getrf/getri batch
    kernel): |det g| = prod |R_kk|."""
    r, qt = householder_qr(g, jnp.eye(g.shape[0], dtype=g.dtype))
    inv = jax.vmap(back_substitute, in_axes=(None, 1), out_axes=1)(r, qt)
    return inv, jnp.sum(jnp.log(jnp.abs(jnp.diag(r))))


def inverse(g: Float[Array, "p p"]) -> Float[Array, "p p"]:
    """g^-1 (`inverse_logdet`)."""
    return inverse_logdet(g)[0]
