"""Local fits around one equilibrium, paper Eqs. (2)-(8) (Algorithm 1, stage 1)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .._solution import RESULTS, Solution, error_if_failed
from .._trace_cache import disk_traced
from ._library import STIFFNESS, Library
from ._errors_in_variables import corrected_qr, shifted_qr
from ._stls import STLS, coefficient_covariance, compress, dropped_variance, residual_sum_of_squares, stls_qr
from ._target_noise import TargetNoise, structured_covariance
from ._threshold import default_thresholds, select_threshold


class AutoThreshold(eqx.Module):
    """Choose the STLS threshold per dataset by blocked cross-validation with the
    one-standard-error rule (`select_threshold`) over `n_grid` thresholds from `lo`·||y|| to
    ||y||, geometrically spaced."""

    n_grid: int = eqx.field(static=True, default=40)
    n_folds: int = eqx.field(static=True, default=5)
    lo: float = eqx.field(static=True, default=1e-6)


class BandRows(eqx.Module):
    """One well's regression rows without the slow band of an integrated x:
    the library columns (at the centre the fit takes, the weighted mean of x) and the target, each
    with its content between 0 and the record's drift cut-off removed (the mean kept)."""

    theta: Float[Array, "samples terms"]
    y: Float[Array, " samples"]
    #: the expected product of each column's noise with the target's, summed with the weights, where both
    #: hold the noise of one sensor (x, differentiated for the target): Θ'Wy's bias, taken off (None: none)
    cross: Float[Array, " terms"] | None = None


class LocalFit(eqx.Module):
    """A local model around one equilibrium (Eq. 10): `coef` of the library in the shifted
    coordinate q = x - `equilibrium`, its covariance, and the threshold used."""

    equilibrium: Float[Array, ""]
    coef: Float[Array, " terms"]
    covariance: Float[Array, "terms terms"]
    threshold: Float[Array, ""]
    rss: Float[Array, ""]
    n_samples: Float[Array, ""]
    #: the variance each term STLS removed would have had, kept beside the others (`dropped_variance`;
    #: zeros on the support; None: unknown, the coordination then takes removed terms as exact zeros)
    dropped: Float[Array, " terms"] | None = None


@disk_traced  # eqx.filter_jit, its traced program kept on disk by the CLI
def fit_local(
    x: Float[Array, " samples"],
    v: Float[Array, " samples"],
    y: Float[Array, " samples"],
    library: Library = Library(),
    solver: STLS = STLS(),
    select: AutoThreshold | None = AutoThreshold(),
    *,
    weights: Float[Array, " samples"] | None = None,
    keep: Bool[Array, " terms"] | None = None,
    support: Bool[Array, " terms"] | None = None,
    noise: TargetNoise | None = None,
    x_noise: Float[Array, ""] | None = None,
    band: BandRows | None = None,
    throw: bool = True,
) -> Solution:
    """Fit the local model of one equilibrium (Algorithm 1, steps 1.1-1.4).

    The equilibrium is the (weighted) mean of `x` (step 1.1), q = x - x_i (Eq. 2), Θ(q, v) the
    library (Eqs. 5-7), and y = Θ ξ is solved by STLS (Eq. 8), y being the force carried by
    the DOF: input force minus (H a) (Eq. 9). With `select`, the threshold is chosen by
    cross-validation; otherwise `solver.threshold` is used. Terms flagged in `keep` are never
    thresholded away: after STLS the model is refitted (least squares, no ridge) on the STLS
    support plus `keep`. `support` restricts the fit to the flagged terms (default: the whole
    library); it bounds `keep` too (with `select`, the threshold is still chosen on the whole
    library). `noise`: the target's noise where it holds a differentiated signal; the
    covariance is then the sandwich with that noise's structure (`structured_covariance`; its
    residual-to-noise ratio in `stats["noise_ratio"]`), not sigma² (Θ'Θ)^-1. `x_noise`: the
    variance of white noise on the measured x; the regression is then corrected for it (errors in
    variables, `_errors_in_variables`: the corrected score; `stats["eiv_applied"]` says whether it
    could be), while the covariance and `rss` stay those of the recorded samples. `band`: the
    rows without the slow band of an integrated x (`BandRows`): the fit (threshold, support,
    coefficients, covariance, `rss`) runs on them.

    **Returns:** a `Solution` whose value is a `LocalFit`.
    """
    w = jnp.ones_like(x) if weights is None else weights
    xe = jnp.sum(w * x) / jnp.sum(w)
    theta = library(x - xe, v)
    if band is not None:
        theta, y = band.theta, band.y
    if select is not None:
        grid = default_thresholds(theta, y, select.n_grid, select.lo, weights)
        sel = select_threshold(theta, y, grid, solver, n_folds=select.n_folds, weights=weights)
        solver = eqx.tree_at(lambda s: s.threshold, solver, sel.value)
        cv = {("" if k.startswith("cv_") else "cv_") + k: v for k, v in sel.stats.items()}
    else:
        cv = {}
    qr = compress(theta, y, weights)
    extra = {"eiv_applied": jnp.asarray(False)}  # in every fit's stats: wells with and without stack alike
    fit_qr = qr if band is None or band.cross is None else shifted_qr(qr, band.cross)
    if x_noise is not None:
        fit_qr, extra["eiv_applied"] = corrected_qr(fit_qr, x - xe, v, y, w, library, jnp.asarray(x_noise, float))
    sol = stls_qr(fit_qr, solver, initial_mask=support)
    if keep is not None:
        refit = eqx.tree_at(lambda s: (s.threshold, s.alpha), solver, (jnp.zeros(()), jnp.zeros(())))
        mask = sol.stats["support"] | keep
        sol = stls_qr(fit_qr, refit, initial_mask=mask if support is None else mask & support)
    if fit_qr is not qr:  # the recorded samples' residual (the corrected problem's is smaller)
        sol.stats["rss"] = residual_sum_of_squares(qr, sol.value)
    cov = coefficient_covariance(qr, sol.value, sol.stats["support"])
    dropped = dropped_variance(qr, sol.value, sol.stats["support"])
    if noise is not None:
        ols = jnp.diagonal(cov)
        cov, extra["noise_ratio"] = structured_covariance(theta, y, w, sol.value, sol.stats["support"], noise)
        # the removed terms' variances scaled as the kept ones' are by the noise's structure (their mean ratio)
        ratio = jnp.where(ols > 0, jnp.diagonal(cov) / jnp.where(ols > 0, ols, 1.0), 0.0)
        dropped = dropped * jnp.sum(ratio) / jnp.maximum(jnp.sum(ols > 0), 1)
    fit = LocalFit(
        equilibrium=xe,
        coef=sol.value,
        covariance=cov,
        threshold=jnp.asarray(solver.threshold, float),
        rss=sol.stats["rss"],
        n_samples=sol.stats["n_samples"],
        dropped=dropped,
    )
    out = Solution(value=fit, result=sol.result, stats={**sol.stats, **cv, **extra})
    return error_if_failed(out, throw)


def with_constant(support: np.ndarray, library: Library) -> np.ndarray:
    """`support` (terms,) with the restoring constant q^0 restored. The local coordinate is
    q = x - mean(x), not x - x_eq, so the force at the mean is not 0 but about -a_2 var(q)
    (the mean force vanishes): where `reconstruct`'s t-screen dropped that small constant, a refit without
    it biases a_2 by a third to two thirds of itself (Kresling truss cells, v from x: a_2 16-26 %
    low, 3.9-14.5 % restoring error; with the constant 0-5 %)."""
    out = np.array(support, bool)
    out[library.indices(STIFFNESS)[0]] = True
    return out


def r2_nrmse(y, yhat):
    """Coefficient of determination and NRMSE (RMS error / RMS of y about its mean)."""
    resid = jnp.sum((y - yhat) ** 2)
    total = jnp.sum((y - jnp.mean(y)) ** 2)
    return 1.0 - resid / total, jnp.sqrt(resid / total)


__all__ = ["AutoThreshold", "BandRows", "LocalFit", "fit_local", "r2_nrmse", "RESULTS", "jax"]
