"""Errors in variables: the local regression (Eq. 8) when the displacement itself is measured
with noise (issue 15; beyond the paper, which takes x as exact).

The local library is a polynomial in q = x - x_i times a function of v (Eqs. 5-7). Least
squares on the columns of a *noisy* q is biased: the noise attenuates the slope and leaks into
the higher powers. Measured, 2-cell cubic chain at 30 dB on every channel (8 seeds, both wells of
both cells): F' 0.14-0.23 % low, on average 4.1 standard errors, q^3 +2.1 standard errors; the
same records with a noise-free x: 0.0 and 0.0. The coordination then takes the biased Taylor
coefficients as exact, and its band (from their noise) misses the truth.

The corrected score (Nakamura 1990; for polynomial regressions Cheng & Schneeweiss 1998, JRSS B
60) makes the normal equations unbiased: with white Gaussian noise of variance s² on q, the
scaled Hermite polynomial He_n(q; s²) = s^n He_n(q / s) has E[He_n(q + e; s²)] = q^n. Θ'Θ holds
the products q^(m_a + m_b) g_a(v) g_b(v) and Θ'y the sums q^(m_a) g_a(v) y (g = 1, sgn(v)|v|^j
or v); each power of the noisy q is replaced by its Hermite polynomial. On the records above:
F' bias -4.1 -> -0.1 standard errors (scatter 1.1 of them), q^3 +2.1 -> +0.1.

Where it holds: the noise on x is white (the Welch floor measures its variance,
`_reconstruct/_noise.channel_variance`) and independent of the target's (accelerations measured,
or estimated from v); the v-factors are taken as measured (the noise of v does not bias the
restoring terms: 0.0 standard errors in the same test). The correction enters the compressed
problem (`QRData`), so STLS, its refits and the covariance code are unchanged; the covariance
stays the ordinary one of the noisy columns (to first order in s² it is the corrected
estimator's: scatter 1.08 standard errors in the test above).
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._householder import cholesky, forward_substitute, triangular_inverse
from ._library import POSITION_DAMPING, STIFFNESS, VELOCITY_DAMPING, Library, signed_power
from ._stls import QRData, column_norms, compress


def powers_and_factors(library: Library, v: Float[Array, " samples"]):
    """Each library column as q^m g(v): the powers m (static, NumPy) and the factors g
    (samples, terms)."""
    m, g = [], []
    for p, k in library.terms():
        if p == STIFFNESS:
            m.append(k), g.append(jnp.ones_like(v))
        elif p == VELOCITY_DAMPING:
            m.append(0), g.append(signed_power(v, k))
        elif p == POSITION_DAMPING:
            m.append(k), g.append(v)
    return np.asarray(m, int), jnp.stack(g, axis=-1)


def hermite_excess(q: Float[Array, " samples"], variance, n_max: int) -> Float[Array, "samples n"]:
    """q^n - He_n(q; s²) for n = 0..`n_max` (what a power of the noisy q holds beyond the power of
    the true one, in expectation), by the recurrences He_(n+1) = q He_n - n s² He_(n-1) and
    D_(n+1) = q D_n + n s² He_(n-1) (no cancellation for small s²)."""
    he = [jnp.ones_like(q), q]
    d = [jnp.zeros_like(q), jnp.zeros_like(q)]
    for n in range(1, n_max):
        he.append(q * he[n] - n * variance * he[n - 1])
        d.append(q * d[n] + n * variance * he[n - 1])
    return jnp.stack(d[: n_max + 1], axis=-1)


def corrected_qr(
    qr: QRData,
    q: Float[Array, " samples"],
    v: Float[Array, " samples"],
    y: Float[Array, " samples"],
    weights: Float[Array, " samples"],
    library: Library,
    variance: Float[Array, ""],
) -> tuple[QRData, Float[Array, ""]]:
    """The compressed local problem (`compress(library(q, v), y, weights)`) with its normal
    equations corrected for white noise of `variance` on q (module docstring).

    With M = R'R and b = R'z, the corrected M - Δ, b - δ are factorised without forming M:
    E = R^-T Δ R^-1 (column-scaled), L L' = I - E, R_c = L' R, z_c = L^-1 (z - R^-T δ). Then
    ||y - Θc||² and yy - ||z_c||² + ||z_c - R_c c||² differ by a constant in c, the corrected one.

    **Returns:** `(qr_c, ok)`: the corrected problem, or `qr` itself where the correction is not
    positive definite or not finite (`ok` False: noise too large for the records, or a zero
    column).
    """
    m, g = powers_and_factors(library, v)
    n_max = int(2 * m.max())
    dq = hermite_excess(q, variance, n_max)  # (samples, n_max + 1)
    wg = weights[:, None] * g
    pair = m[:, None] + m[None, :]
    delta = sum(jnp.where(jnp.asarray(pair == n), jnp.einsum("t,ta,tb->ab", dq[:, n], wg, g), 0.0)
                for n in np.unique(pair) if n >= 2)  # D_0 = D_1 = 0
    small = jnp.einsum("ta,ta,t->a", dq[:, m], wg, y)
    return _moment_corrected(qr, delta, small, variance)


def shifted_qr(qr: QRData, cross: Float[Array, " terms"]) -> QRData:
    """The compressed problem with its normal equations' right side Θ'Wy less `cross` (the expected
    product of the columns' noise with the target's, where both hold the same sensor's noise);
    `qr` where that is not finite."""
    out, _ = _moment_corrected(qr, jnp.zeros((cross.size, cross.size), qr.r.dtype), cross, jnp.zeros(()))
    return out


def _moment_corrected(qr: QRData, delta, small, variance):
    """`qr` with M = R'R, b = R'z corrected to M - delta, b - small (`corrected_qr`), and whether it
    could be."""
    norms = column_norms(qr)
    norms = jnp.where(norms > 0, norms, 1.0)
    rn = qr.r / norms[None, :]
    rinv = triangular_inverse(rn, lower=False)
    e = rinv.T @ (delta / jnp.outer(norms, norms)) @ rinv
    e = 0.5 * (e + e.T)
    low = cholesky(jnp.eye(e.shape[0], dtype=e.dtype) - e)
    r_c = (low.T @ rn) * norms[None, :]
    z_c = forward_substitute(low, qr.z - rinv.T @ (small / norms))
    ok = jnp.all(jnp.isfinite(r_c)) & jnp.all(jnp.isfinite(z_c)) & jnp.isfinite(variance) & (variance >= 0)
    out = QRData(r=jnp.where(ok, r_c, qr.r), z=jnp.where(ok, z_c, qr.z), yy=qr.yy, n=qr.n)
    return out, ok


@eqx.filter_jit
def compressed_problem(
    q: Float[Array, " samples"],
    v: Float[Array, " samples"],
    y: Float[Array, " samples"],
    weights: Float[Array, " samples"],
    library: Library,
    variance: Float[Array, ""] | None = None,
) -> QRData:
    """`compress(library(q, v), y, weights)`, corrected for white noise of `variance` on q
    where given (`corrected_qr`; uncorrected where that fails): the local regression's data as
    the refits outside `fit_local` take them (`_reconstruct/_shape_prior.refit_with_prior`)."""
    qr = compress(library(q, v), y, weights)
    return qr if variance is None else corrected_qr(qr, q, v, y, weights, library, variance)[0]


__all__ = ["compressed_problem", "corrected_qr", "hermite_excess", "powers_and_factors", "shifted_qr"]
