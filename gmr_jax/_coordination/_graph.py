"""The evidence model of a graph: every element's law from every node's force balance.

Node i's balance in record r, multiplied by the test functions of `_bayes.weak_rows` and
integrated, is y_ri = sum_e B[e, i] (weak-form columns of element e's deformation) . theta_g(e):
each element contributes its own columns (its deformation d_e = x_b - x_a, its rate), signed by
the incidence, and the elements of one design g share one coefficient vector theta_g (the
families of `_bayes`: Chebyshev restoring law, velocity and position damping, each design scaled
to its own elements' span and speed). Columns of the elements of a design at a node add up.

The prior is `_bayes`'s per design (a scale and a geometric decay per family and design); each
(record, node) has its own noise variance. The hyperparameters maximise the evidence times the
hyperprior, for each restoring degree K = 1..`degree` (one K for every design), and the degrees
are weighted by p(K | rows), as `_bayes.posterior`. The evidence is `_bayes`'s, from the groups'
square-root factors (`_bayes._gaussian`); only the prior's scales and decays per design differ.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._solution import RESULTS, Solution, as_result
from ._bayes import HYPER_SD, OFF, Basis, _covariance, _gaussian, _minimise, _weighted


class GraphHyper(eqx.Module):
    """Per design and family (designs, 3): log scale and logit decay; per row group: log noise variance."""

    log_scale: Float[Array, "designs 3"]
    logit_decay: Float[Array, "designs 3"]
    log_noise: Float[Array, " groups"]


class GraphPosterior(eqx.Module):
    """The posterior of all designs' scaled coefficients (designs * P,), a mixture over the
    restoring degree: `mean` and `covariance` of the mixture; per degree the hyperparameters, the
    log evidence (times the hyperprior) and the weight p(K | rows)."""

    mean: Float[Array, " q"]
    covariance: Float[Array, "q q"]
    hyper: GraphHyper
    log_evidence: Float[Array, " degrees"]
    weight: Float[Array, " degrees"]


def prior_sd(h: GraphHyper, basis: Basis):
    """The prior's standard deviation of every column (designs * P,), s_gf rho_gf^power."""
    fam = jnp.asarray(basis.family())
    power = jnp.asarray(basis.decay_power())
    sd = jnp.exp(h.log_scale[:, fam] + power[None, :] * jax.nn.log_sigmoid(h.logit_decay)[:, fam])
    return sd.reshape(-1)


def _solve(h: GraphHyper, stats, basis: Basis, active):
    F, n = stats
    sq = prior_sd(h, basis) * active
    X, t, log_beta = _weighted(F, h.log_noise)
    p = F.shape[-1]
    mean, chol, log_ev = _gaussian(sq, X.reshape(-1, p - 1), t.reshape(-1), jnp.sum(n * log_beta), jnp.sum(n))
    return mean, chol, sq, log_ev


def log_hyperprior(h: GraphHyper):
    """`_bayes.log_hyperprior` for every design and family: normals of sd `HYPER_SD` on the log
    scales and logit decays, flat on the log noise variances."""
    return -0.5 * (jnp.sum((h.log_scale / HYPER_SD[0]) ** 2) + jnp.sum((h.logit_decay / HYPER_SD[1]) ** 2))


def _initial(stats, n_designs: int, decay: float) -> GraphHyper:
    F, n = stats
    var = jnp.sum(F[..., -1] ** 2, axis=-1) / jnp.maximum(n, 1.0)
    return GraphHyper(jnp.zeros((n_designs, 3)), jnp.full((n_designs, 3), jnp.log(decay / (1.0 - decay))),
                      jnp.log(1e-2 * var + 1e-30))


def _optimise(stats, basis: Basis, n_designs: int, active, max_steps: int):
    def loss(h, args):
        return -(_solve(h, args, basis, active)[3] + log_hyperprior(h)) / jnp.maximum(jnp.sum(args[1]), 1.0)

    h, code = _minimise(loss, [_initial(stats, n_designs, decay) for decay in (0.3, 0.7)], stats, max_steps)
    mean, chol, sq, log_ev = _solve(h, stats, basis, active)
    return h, mean, _covariance(chol, sq), log_ev + log_hyperprior(h), code._value


def graph_posterior(stats, basis: Basis, n_designs: int, *, max_steps: int = 1024) -> Solution:
    """Posterior of every design's scaled coefficients from per-group factors `(F, n)`
    (`_bayes.group_factors` of the node rows, columns design-major), a mixture over the
    restoring degree as `_bayes.posterior`. Jittable (`n_designs` static). **Returns:** a
    `Solution` with a `GraphPosterior` and the optimiser's `RESULTS` code (at the most probable
    degree)."""
    fam = np.tile(basis.family(), n_designs)
    order = np.tile(np.concatenate([np.arange(k) for k in basis.sizes]), n_designs)
    degrees = np.arange(1, basis.degree + 1)
    active = jnp.asarray(np.stack([np.where(fam == 0, order <= k, True) for k in degrees]).astype(float))
    # the degrees one after another (`jax.lax.map`): a batch of LAPACK factorisations over them can hang the
    # CPU thread pool (`_fit/_householder.py`)
    h, means, covs, log_ev, codes = jax.lax.map(lambda a: _optimise(stats, basis, n_designs, a, max_steps), active)
    weight = jax.nn.softmax(jnp.where(jnp.isfinite(log_ev), log_ev, -jnp.inf))
    best = jnp.argmax(weight)
    mean = jnp.einsum("k,ki->i", weight, means)
    dev = means - mean[None, :]
    cov = jnp.einsum("k,kij->ij", weight, covs) + jnp.einsum("k,ki,kj->ij", weight, dev, dev)
    absent = (jnp.diagonal(cov) < OFF**2) & (jnp.abs(mean) < OFF)
    mean = jnp.where(absent, 0.0, mean)
    cov = jnp.where(absent[:, None] | absent[None, :], 0.0, cov)
    code = RESULTS.where(jnp.all(jnp.isfinite(mean)), as_result(codes[best]), RESULTS.nonfinite)
    return Solution(GraphPosterior(mean, cov, h, log_ev, weight), code, {})
