"""Coordinate coordination, paper Eqs. (12)-(21).

The local coefficients a_ij of (x - x_i)^j are Taylor coefficients of the one global polynomial
F(x) = sum_k A_k x^k at the equilibrium x_i: a_ij = F^(j)(x_i) / j!. Knowing them for
j = 0..r_i at n points is a Hermite interpolation problem (a confluent Vandermonde system, the
content of Eqs. 15-17) with sum_i (r_i + 1) equations; it has exactly one solution of degree
K = (n - 1) + sum_i r_i, which is Eq. (18) (Eq. 20 for the damping). A coefficient below r_i
that STLS set to zero is a known zero. The system is solved in scaled coordinates
s = (x - c) / h (c, h: centre and half-span of the equilibria) and mapped back to monomials.

Shapes are fixed: with n points and local order r the system has n (r + 1) rows and columns;
rows above each r_i and columns above K are masked out (active rows are moved first by a
stable sort, masked rows/columns replaced by the identity), so the solve jits and vmaps.
"""

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._fit._householder import back_substitute, householder_qr, inverse
from .._topology import _xp


def _binom_table(n: int) -> np.ndarray:
    import math

    return np.array([[float(math.comb(k, j)) for k in range(n)] for j in range(n)])  # [j, k] = C(k, j)


def highest_order(support: Bool[Array, "... orders"]) -> Int[Array, "..."]:
    """Highest index with a nonzero (active) coefficient; 0 if none."""
    xp = _xp(support)
    idx = xp.arange(support.shape[-1])
    return xp.max(xp.where(support, idx, 0), axis=-1)


def scaling(nodes: Float[Array, " n"]):
    lo, hi = jnp.min(nodes), jnp.max(nodes)
    c = 0.5 * (lo + hi)
    h = 0.5 * (hi - lo)
    return c, jnp.where(h > 0, h, 1.0)


def confluent_vandermonde(s: Float[Array, " n"], r: int, size: int):
    """Rows (i, j), j = 0..r: d^j/ds^j (s^k) / j! at s_i, for k = 0..size-1."""
    binom = jnp.asarray(_binom_table(max(size, r + 1)))[: r + 1, :size]  # [j, k]
    k = jnp.arange(size)
    j = jnp.arange(r + 1)
    expo = k[None, :] - j[:, None]  # [j, k]
    powr = jnp.where(expo[None] >= 0, s[:, None, None] ** jnp.maximum(expo[None], 0), 0.0)
    return (binom[None] * powr).reshape(s.shape[0] * (r + 1), size)


def monomial_map(c, h, size: int):
    """Matrix T with A = T @ Ã: sum_k Ã_k ((x - c)/h)^k = sum_m A_m x^m."""
    xp = jnp if isinstance(c, jax.Array) or isinstance(h, jax.Array) else np  # NumPy in, NumPy out
    binom = xp.asarray(_binom_table(size))  # [m, k] = C(k, m)
    k = xp.arange(size)
    m = xp.arange(size)
    expo = k[None, :] - m[:, None]
    powc = xp.where(expo >= 0, (-c) ** xp.maximum(expo, 0), 0.0)
    return binom * powc * h ** (-k[None, :].astype(xp.result_type(h)))


def hermite_interpolate(
    nodes: Float[Array, " n"],
    taylor: Float[Array, "n orders"],
    order: Int[Array, " n"],
):
    """Global polynomial from Taylor coefficients at several points (Eqs. 15-18, 19-20).

    **Arguments:**

    - `nodes`: the equilibria x_i (n,).
    - `taylor`: a_ij, coefficient of (x - x_i)^j, j = 0..r (n, r + 1).
    - `order`: r_i, the highest order known at each point (coefficients above are unknown).

    **Returns:** `(coeffs, degree, cond)`: monomial coefficients A_0..A_{n(r+1)-1} (zero above
    the degree), the degree K = n - 1 + sum r_i (Eq. 18), and the 1-norm condition number of
    the scaled system.
    """
    n, rp1 = taylor.shape
    size = n * rp1
    c, h = scaling(nodes)
    s = (nodes - c) / h
    vand = confluent_vandermonde(s, rp1 - 1, size)
    jpow = jnp.arange(rp1)
    rhs = (taylor * h ** jpow[None, :].astype(taylor.dtype)).reshape(size)
    row_active = (jpow[None, :] <= order[:, None]).reshape(size)
    degree = n - 1 + jnp.sum(order)
    perm = jnp.argsort(~row_active, stable=True)
    p = jnp.arange(size)
    active = p <= degree
    colmask = p[None, :] <= degree
    mat = jnp.where(active[:, None], jnp.where(colmask, vand[perm], 0.0), jnp.eye(size))
    b = jnp.where(active, rhs[perm], 0.0)
    # Householder QR and back substitution (`_fit/_householder.py`), not a LAPACK batch kernel under vmap;
    # the coefficients from a direct solve (not inverse @ b), the inverse only for the condition number
    coef_s = back_substitute(*householder_qr(mat, b))
    cond = jnp.linalg.norm(mat, 1) * jnp.linalg.norm(inverse(jax.lax.stop_gradient(mat)), 1)
    return monomial_map(c, h, size) @ coef_s, degree, cond
