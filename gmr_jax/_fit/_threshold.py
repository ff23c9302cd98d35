"""Automatic choice of the STLS threshold: blocked cross-validation with the one-standard-error
rule (Hastie, Tibshirani & Friedman, *Elements of Statistical Learning*, Sec. 7.10).

The record is cut into `n_folds` contiguous blocks (contiguous, because samples of a time
series are correlated). For each threshold of a grid, STLS is fitted on all blocks but one and
scored on the one left out. The chosen threshold is the largest (sparsest model) whose mean
validation error is within one standard error of the best mean. Every (fold, threshold) fit is
one vmapped STLS on the (terms x terms) QR factors, so the sweep costs little more than a fit.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._solution import RESULTS, Solution
from ._householder import householder_qr
from ._stls import STLS, QRData, column_norms, compress, stls_qr


def _block_qr(theta, y, n_folds: int, weights=None) -> QRData:
    n = theta.shape[0]
    size = n // n_folds
    theta = theta[: size * n_folds].reshape(n_folds, size, -1)
    y = y[: size * n_folds].reshape(n_folds, size)
    if weights is None:
        return jax.vmap(compress)(theta, y)
    w = weights[: size * n_folds].reshape(n_folds, size)
    return jax.vmap(compress)(theta, y, w)


def _stack(blocks: QRData, keep) -> QRData:
    """Combine block factors (TSQR): R of the stacked kept blocks."""
    k, p, _ = blocks.r.shape
    r = jnp.where(keep[:, None, None], blocks.r, 0.0).reshape(k * p, p)
    z = jnp.where(keep[:, None], blocks.z, 0.0).reshape(k * p)
    r2, z2 = householder_qr(r, z)
    return QRData(r=r2, z=z2, yy=jnp.sum(jnp.where(keep, blocks.yy, 0.0)), n=jnp.sum(jnp.where(keep, blocks.n, 0.0)))


def _validation_sse(block: QRData, coef):
    resid = block.r @ coef - block.z
    return jnp.maximum(block.yy - jnp.sum(block.z**2), 0.0) + jnp.sum(resid**2)


def default_thresholds(theta, y, n: int = 40, lo: float = 1e-6, weights=None):
    """Grid for normalised-coefficient thresholds: geometric from `lo` to 1 times ||y||
    (a normalised coefficient is the norm of that term's contribution to y)."""
    ynorm = jnp.sqrt(jnp.sum(y**2 if weights is None else weights * y**2))
    return ynorm * jnp.geomspace(lo, 1.0, n)


@eqx.filter_jit
def select_threshold(
    theta: Float[Array, "samples terms"],
    y: Float[Array, " samples"],
    thresholds: Float[Array, " grid"],
    solver: STLS = STLS(),
    *,
    n_folds: int = 5,
    weights: Float[Array, " samples"] | None = None,
) -> Solution:
    """Pick the STLS threshold by blocked cross-validation and the one-standard-error rule.

    **Returns:** a `Solution` with `value` the chosen threshold, and `stats` holding the grid
    (`thresholds`), mean and standard error of the validation MSE per threshold (`cv_mean`,
    `cv_se`), the number of active terms on the full data (`n_active`) and the index chosen.
    Thresholds are on normalised coefficients when `solver.normalize_columns` (the default).
    """
    blocks = _block_qr(theta, y, n_folds, weights)
    full = _stack(blocks, jnp.ones(n_folds, bool))
    norms = column_norms(full)

    def fold_errors(k):
        keep = jnp.arange(n_folds) != k
        train = _stack(blocks, keep)
        held = jax.tree_util.tree_map(lambda a: a[k], blocks)

        def one(th):
            sol = stls_qr(train, eqx.tree_at(lambda s: s.threshold, solver, th), norms)
            return _validation_sse(held, sol.value) / jnp.maximum(held.n, 1.0)

        return jax.vmap(one)(thresholds)

    errs = jax.vmap(fold_errors)(jnp.arange(n_folds))  # (folds, grid)
    mean = jnp.mean(errs, axis=0)
    se = jnp.std(errs, axis=0, ddof=1) / jnp.sqrt(n_folds)
    best = jnp.argmin(mean)
    ok = mean <= mean[best] + se[best]
    idx = jnp.max(jnp.where(ok, jnp.arange(thresholds.shape[0]), -1))
    chosen = thresholds[idx]

    def n_act(th):
        return jnp.sum(stls_qr(full, eqx.tree_at(lambda s: s.threshold, solver, th), norms).stats["support"])

    stats = {
        "thresholds": thresholds,
        "cv_mean": mean,
        "cv_se": se,
        "index": idx,
        "n_active": jax.vmap(n_act)(thresholds),
    }
    result = RESULTS.where(jnp.isfinite(mean[best]), RESULTS.successful, RESULTS.nonfinite)
    return Solution(value=chosen, result=result, stats=stats)
