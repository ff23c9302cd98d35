"""The truncation of the local Taylor series in the coordination's degree choice (issue 15).

A local fit of order r takes the next Taylor term q^(r+1) as zero. Where the data carry it, the kept
coefficients absorb it: on the tri-stable NES (paper orders 3, 3, 60 dB, seed 0) the local F'' at two
wells is 3-4 standard errors off for want of q^4, the chi-squared test of `hermite_gls` rejects the
true degree 7 and the law is 0.29 % off the truth instead of 0.03 %. The q^4 term itself is not
resolved (q^4 and q^2 are nearly collinear on small vibrations): its effect on F'' is below the noise of
a fit that includes it, yet above the noise of one that does not.

`with_truncation` gives each well's coefficients as the fit one order higher has them: moved by
delta = (their least-squares values with q^(r+1) in the support) - (without it), their covariance grown
by delta's own, delta delta' / t^2 (delta = g c for the new coefficient c, t its t statistic). The
chi-squared test on those is valid where the series one order higher suffices. `reconstruct`'s auto
coordination uses it for the degree choice only: the law is then fitted at that degree from the local
fits as they were, its band widened by the spread to the next odd degree (`_truncation_degree`).
NumPy, on `reconstruct`'s padded per-well arrays.
"""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._fit._library import STIFFNESS, Library
from .._fit._local_fit import LocalFit


def sensitivity(coef: np.ndarray, q: np.ndarray, v: np.ndarray, y: np.ndarray, w: np.ndarray,
                library: Library, band=None):
    """(delta, t2) of one well: delta (terms,) the change of its kept coefficients (`coef`'s support)
    when the restoring term one order above its highest joins them, both fitted by weighted least squares
    on the well's samples (q = x - equilibrium), and t2 that term's squared t statistic (OLS); delta
    delta' / t2 is then the covariance delta adds (delta = g c, c the new coefficient). Zeros (t2 = inf)
    where that fit is rank-deficient. `band`: the well's rows above an integrated x's drift cut-off
    (`BandRows`): the fits run on them; zeros where q^(r+1) is beyond the library (no band column)."""
    coef = np.asarray(coef, float)
    zero = (np.zeros_like(coef), np.inf)
    support = coef != 0
    orders = library.orders(STIFFNESS)
    idx = library.indices(STIFFNESS)
    kept = orders[support[idx]]
    top = int(kept.max()) if kept.size else 0
    on = w > 0
    if top < 1 or np.count_nonzero(on) <= np.count_nonzero(support) + 1:
        return zero
    if band is not None:
        if top + 1 > int(orders.max()):
            return zero
        full = np.asarray(band.theta, float)[on]
        theta, extra, y = full[:, support], full[:, idx[top + 1], None], np.asarray(band.y, float)
    else:
        theta = np.asarray(library(jnp.asarray(q[on]), jnp.asarray(v[on])))[:, support]
        extra = q[on, None] ** (top + 1)
    sw = np.sqrt(w[on])[:, None]
    a1, b = np.hstack([theta, extra]) * sw, y[on] * sw[:, 0]
    norm = np.linalg.norm(a1, axis=0)
    if not np.all(norm > 0):
        return zero
    a1 = a1 / norm  # columns of unit norm: q^(r+1) is many decades below 1 on small vibrations
    if np.linalg.matrix_rank(a1) < a1.shape[1]:
        return zero
    b0 = np.linalg.lstsq(a1[:, :-1], b, rcond=None)[0] / norm[:-1]
    sol1 = np.linalg.lstsq(a1, b, rcond=None)[0]
    b1 = sol1[:-1] / norm[:-1]
    sigma2 = float(np.sum((a1 @ sol1 - b) ** 2)) / (a1.shape[0] - a1.shape[1])
    var_c = sigma2 * np.linalg.inv(a1.T @ a1)[-1, -1]
    out = np.zeros_like(coef)
    out[support] = b1 - b0
    return out, (sol1[-1] ** 2 / var_c if var_c > 0 and sol1[-1] != 0 else np.inf)  # c = 0: delta = 0


def with_truncation(fits: LocalFit, xs, vs, ys, w, library: Library, band=None) -> LocalFit:
    """`fits` as the next restoring order would have them: each well's coefficients moved by delta and
    its covariance grown by delta delta' / t2 (`sensitivity`)."""
    coef = np.asarray(fits.coef, float)
    eq = np.asarray(fits.equilibrium, float)
    xs, vs, ys, w = (np.asarray(a, float) for a in (xs, vs, ys, w))
    band = band or [None] * coef.shape[0]
    out = [sensitivity(coef[k], xs[k] - eq[k], vs[k], ys[k], w[k], library, band[k]) for k in range(coef.shape[0])]
    deltas = np.stack([d for d, _ in out])
    t2 = np.array([t for _, t in out])
    cov = np.asarray(fits.covariance, float) + deltas[:, :, None] * deltas[:, None, :] / t2[:, None, None]
    new = coef + deltas
    return eqx.tree_at(lambda f: (f.coef, f.covariance), fits, (jnp.asarray(new), jnp.asarray(cov)))
