"""The truncation of the local Taylor series as a variance of the coordination's conditions (issue 15).

A local fit of order r takes the next Taylor term q^(r+1) as zero. Where the data carry it, the kept
coefficients absorb it: on the tri-stable NES (paper orders 3, 3, 60 dB, seed 0) the local F'' at two
wells is 3-4 standard errors off for want of q^4, the chi-squared test of `hermite_gls` rejects the
true degree 7 and the law is 0.29 % off the truth instead of 0.04 %. The sensitivity of the kept
coefficients to that term, delta = (their least-squares values with q^(r+1) in the support) - (without
it), is the size of that error; delta delta' added to a well's covariance lets the test see it.

It is used for the degree choice only (`reconstruct`'s auto coordination): the law is then fitted, at
the degree chosen, with the local covariances as they were (the calibrated band is unchanged). NumPy,
on `reconstruct`'s padded per-well arrays.
"""

import jax.numpy as jnp
import numpy as np

from .._fit._library import STIFFNESS, Library
from .._fit._local_fit import LocalFit


def sensitivity(coef: np.ndarray, q: np.ndarray, v: np.ndarray, y: np.ndarray, w: np.ndarray,
                library: Library) -> np.ndarray:
    """delta (terms,) of one well: the change of its kept coefficients (`coef`'s support) when the
    restoring term one order above its highest joins them, both fitted by weighted least squares on the
    well's samples (q = x - equilibrium); zeros where that fit is rank-deficient."""
    coef = np.asarray(coef, float)
    support = coef != 0
    orders = library.orders(STIFFNESS)
    idx = library.indices(STIFFNESS)
    kept = orders[support[idx]]
    top = int(kept.max()) if kept.size else 0
    on = w > 0
    if top < 1 or np.count_nonzero(on) <= np.count_nonzero(support) + 1:
        return np.zeros_like(coef)
    theta = np.asarray(library(jnp.asarray(q[on]), jnp.asarray(v[on])))[:, support]
    extra = q[on, None] ** (top + 1)
    sw = np.sqrt(w[on])[:, None]
    a1, b = np.hstack([theta, extra]) * sw, y[on] * sw[:, 0]
    norm = np.linalg.norm(a1, axis=0)
    if not np.all(norm > 0):
        return np.zeros_like(coef)
    a1 = a1 / norm  # columns of unit norm: q^(r+1) is many decades below 1 on small vibrations
    if np.linalg.matrix_rank(a1) < a1.shape[1]:
        return np.zeros_like(coef)
    b0 = np.linalg.lstsq(a1[:, :-1], b, rcond=None)[0] / norm[:-1]
    b1 = np.linalg.lstsq(a1, b, rcond=None)[0][:-1] / norm[:-1]
    out = np.zeros_like(coef)
    out[support] = b1 - b0
    return out


def with_truncation(fits: LocalFit, xs, vs, ys, w, library: Library) -> LocalFit:
    """`fits` with delta delta' (`sensitivity`) added to each well's covariance."""
    coef = np.asarray(fits.coef, float)
    eq = np.asarray(fits.equilibrium, float)
    xs, vs, ys, w = (np.asarray(a, float) for a in (xs, vs, ys, w))
    deltas = np.stack([sensitivity(coef[k], xs[k] - eq[k], vs[k], ys[k], w[k], library)
                       for k in range(coef.shape[0])])
    cov = np.asarray(fits.covariance, float) + deltas[:, :, None] * deltas[:, None, :]
    return LocalFit(equilibrium=fits.equilibrium, coef=fits.coef, covariance=jnp.asarray(cov),
                    threshold=fits.threshold, rss=fits.rss, n_samples=fits.n_samples)
