"""Small dense linear algebra in plain XLA operations: thin QR by Householder reflections,
triangular substitution, Cholesky, and singular values / a symmetric square root by one-sided
Jacobi rotations.

`jnp.linalg.qr` on the CPU calls LAPACK (geqrf/orgqr) through jaxlib kernels that, for a batch
(any `vmap`), hand the batch to XLA's intra-op thread pool and block until it is done. When
the thunk executor runs as many such calls at once as the pool has threads (2 on a 2-core
machine: the vmapped STLS of the threshold selection does), every pool thread waits for work
queued behind it and the process hangs for ever (seen here: `gmr fit --method gmc-sindy` and CI;
jaxlib 0.10.2 `ParallelBatchMap`, compiled out in later jaxlib). The STLS kernels are vmapped by
design, so they factorise with this instead: p reflections, each a rank-one update, no custom
call, the same O(m p^2) work, backward stable, differentiable (a fixed-length loop).

The same deadlock hung CI in the coordination (stop 29: `coordinate`'s restoring and damping GLS
each ran a batch of QRs, SVDs and triangular solves over the candidate degrees, four independent
batch kernels in one program). Every routine the library runs under `vmap` (or `jacfwd`, which
batches the tangents) therefore comes from this module; `tests/test_no_lapack_batches.py`
checks the compiled programs for batched LAPACK calls.
"""

import jax
import jax.numpy as jnp
import numpy as np
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


def forward_substitute(l: Float[Array, "p p"], b: Float[Array, " p"]) -> Float[Array, " p"]:
    """c with L c = b for lower-triangular L (`back_substitute`'s mirror)."""
    p = l.shape[0]

    def step(k, c):
        return c.at[k].set((b[k] - l[k] @ c) / l[k, k])  # c[j] = 0 for j >= k so far

    return jax.lax.fori_loop(0, p, step, jnp.zeros_like(b))


def triangular_inverse(r: Float[Array, "p p"], lower: bool) -> Float[Array, "p p"]:
    """The inverse of a triangular matrix, column by column (`back_substitute`,
    `forward_substitute`)."""
    r = jnp.asarray(r)
    solve = forward_substitute if lower else back_substitute
    eye = jnp.eye(r.shape[0], dtype=r.dtype)
    return jax.vmap(solve, in_axes=(None, 1), out_axes=1)(r, eye)


def cholesky(a: Float[Array, "p p"]) -> Float[Array, "p p"]:
    """Lower-triangular L with L L^T = a for a symmetric positive definite `a` (column-wise
    Cholesky-Crout; NaN where `a` is not positive definite, as LAPACK's potrf in jax)."""
    a = jnp.asarray(a)
    p = a.shape[0]
    idx = jnp.arange(p)

    def step(j, l):
        d = a[j, j] - l[j] @ l[j]  # l[j, k] = 0 for k >= j so far
        ljj = jnp.sqrt(d)
        col = (a[:, j] - l @ l[j]) / ljj
        col = jnp.where(idx > j, col, jnp.where(idx == j, ljj, 0.0))
        return l.at[:, j].set(col)

    return jax.lax.fori_loop(0, p, step, jnp.zeros_like(a))


#: One-sided Jacobi sweeps (convergence is quadratic). Singular values against LAPACK's gesdd,
#: relative: a 30 x 30 Gaussian matrix needs 8 sweeps (1e-14; 7 give 4e-10), column-graded ones
#: like the whitened coordination systems (six to eight decades) 4 (5e-15); 12 leave a margin.
#: Checked in `tests/test_no_lapack_batches.py`.
JACOBI_SWEEPS = 12


def jacobi_rotate(a: Float[Array, "m p"]) -> tuple[Float[Array, "m p"], Float[Array, "p p"]]:
    """One-sided Jacobi (Hestenes): W = a V with V orthogonal and the columns of W mutually
    orthogonal, so the singular values of `a` are the column norms of W and, where `a` is
    symmetric positive semi-definite, V holds its eigenvectors. A fixed number of sweeps over
    all column pairs (`JACOBI_SWEEPS`); zero columns are left alone."""
    a = jnp.asarray(a)
    m, p = a.shape
    ii, jj = np.triu_indices(p, 1)
    pairs = jnp.asarray(np.stack([ii, jj], axis=1))
    tiny = jnp.finfo(a.dtype).tiny

    def rotate(k, carry):
        w, v = carry
        i, j = pairs[k, 0], pairs[k, 1]
        wi, wj = w[:, i], w[:, j]
        alpha, beta, gamma = wi @ wi, wj @ wj, wi @ wj
        act = jnp.abs(gamma) > jnp.finfo(a.dtype).eps * jnp.sqrt(alpha * beta) + tiny
        g = jnp.where(act, gamma, 1.0)
        zeta = (beta - alpha) / (2.0 * g)
        t = jnp.where(zeta >= 0, 1.0, -1.0) / (jnp.abs(zeta) + jnp.sqrt(1.0 + zeta * zeta))
        c = jnp.where(act, 1.0 / jnp.sqrt(1.0 + t * t), 1.0)
        s = jnp.where(act, c * t, 0.0)
        w = w.at[:, i].set(c * wi - s * wj).at[:, j].set(s * wi + c * wj)
        vi, vj = v[:, i], v[:, j]
        v = v.at[:, i].set(c * vi - s * vj).at[:, j].set(s * vi + c * vj)
        return w, v

    def sweep(_, carry):
        return jax.lax.fori_loop(0, len(ii), rotate, carry)

    if p < 2:
        return a, jnp.eye(p, dtype=a.dtype)
    return jax.lax.fori_loop(0, JACOBI_SWEEPS, sweep, (a, jnp.eye(p, dtype=a.dtype)))


def singular_values(a: Float[Array, "m p"]) -> Float[Array, " p"]:
    """The singular values of `a`, in descending order (`jacobi_rotate`)."""
    w, _ = jacobi_rotate(a)
    return jnp.sort(jnp.sqrt(jnp.sum(w * w, axis=0)))[::-1]


def psd_root(cov: Float[Array, "p p"]) -> Float[Array, "p p"]:
    """R with R R^T = cov for a symmetric positive semi-definite `cov`: V diag(sqrt(lambda))
    with V from `jacobi_rotate` (cov V = V diag(lambda), lambda clipped at 0)."""
    _, v = jacobi_rotate(cov)
    lam = jnp.sum(v * (cov @ v), axis=0)  # Rayleigh quotients: signed, round-off negatives clipped
    return v * jnp.sqrt(jnp.clip(lam, 0.0))[None, :]
