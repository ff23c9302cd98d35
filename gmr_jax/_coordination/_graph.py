"""The evidence model of a graph: every element's law from every node's force balance.

Node i's balance in record r, multiplied by the test functions of `_bayes.weak_rows` and
integrated, is y_ri = sum_e B[e, i] (weak-form columns of element e's deformation) . theta_g(e):
each element contributes its own columns (its deformation d_e = x_b - x_a, its rate), signed by
the incidence, and the elements of one design g share one coefficient vector theta_g (the
families of `_bayes`: Chebyshev restoring law, velocity and position damping, each design scaled
to its own elements' span and speed). Columns of the elements of a design at a node add up.

The prior is `_bayes`'s per design (a scale and a geometric decay per family and design); each
(record, node) has its own noise variance. The hyperparameters maximise the evidence, for each
restoring degree K = 1..`degree` (one K for every design), and the degrees are weighted by
p(K | rows): the mean of the most probable K, the mixture's covariance about it, as `_bayes`.
`_solve` is `_bayes`'s with the prior's scales and decays per design; the optimiser is `_bayes._minimise`.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._solution import RESULTS, Solution, as_result
from ._bayes import OFF, Basis, _minimise


class GraphHyper(eqx.Module):
    """Per design and family (designs, 3): log scale and logit decay; per row group: log noise variance."""

    log_scale: Float[Array, "designs 3"]
    logit_decay: Float[Array, "designs 3"]
    log_noise: Float[Array, " groups"]


class GraphPosterior(eqx.Module):
    """The posterior of all designs' scaled coefficients (designs * P,): `mean` at the most probable
    restoring degree, `covariance` of the mixture over the degrees about it; per degree the
    hyperparameters, the log evidence and the weight p(K | rows)."""

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
    G, b, yy, n = stats
    beta = jnp.exp(-h.log_noise)
    sq = prior_sd(h, basis) * active
    Gs = jnp.einsum("w,wij->ij", beta, G)
    bs = jnp.einsum("w,wi->i", beta, b)
    A = jnp.eye(sq.shape[0]) + sq[:, None] * Gs * sq[None, :]
    chol = jnp.linalg.cholesky(A)
    z = jax.scipy.linalg.cho_solve((chol, True), sq * bs)
    logdet = 2.0 * jnp.sum(jnp.log(jnp.diag(chol)))
    fit = jnp.sum(beta * yy) - jnp.dot(sq * bs, z)
    log_ev = 0.5 * (jnp.sum(n * jnp.log(beta)) - fit - logdet - jnp.sum(n) * jnp.log(2.0 * jnp.pi))
    return sq * z, chol, sq, log_ev


def _initial(stats, n_designs: int, decay: float) -> GraphHyper:
    _, _, yy, n = stats
    var = yy / jnp.maximum(n, 1.0)
    return GraphHyper(jnp.zeros((n_designs, 3)), jnp.full((n_designs, 3), jnp.log(decay / (1.0 - decay))),
                      jnp.log(1e-2 * var + 1e-30))


def _optimise(stats, basis: Basis, n_designs: int, active, max_steps: int):
    def loss(h, args):
        return -_solve(h, args, basis, active)[3] / jnp.maximum(jnp.sum(args[3]), 1.0)

    h, code = _minimise(loss, [_initial(stats, n_designs, decay) for decay in (0.3, 0.7)], stats, max_steps)
    mean, chol, sq, log_ev = _solve(h, stats, basis, active)
    inv = jax.scipy.linalg.cho_solve((chol, True), jnp.eye(sq.shape[0]))
    return h, mean, sq[:, None] * inv * sq[None, :], log_ev, code._value


def graph_posterior(stats, basis: Basis, n_designs: int, *, max_steps: int = 1024) -> Solution:
    """Posterior of every design's scaled coefficients from per-group statistics `(G, b, yy, n)`
    (`_bayes.well_statistics` of the node rows, columns design-major). Jittable (`n_designs`
    static). **Returns:** a `Solution` with a `GraphPosterior` and the optimiser's `RESULTS` code."""
    fam = np.tile(basis.family(), n_designs)
    order = np.tile(np.concatenate([np.arange(k) for k in basis.sizes]), n_designs)
    degrees = np.arange(1, basis.degree + 1)
    active = jnp.asarray(np.stack([np.where(fam == 0, order <= k, True) for k in degrees]).astype(float))
    # one degree after another: a batch of LAPACK factorisations over the degrees can hang the CPU
    # thread pool (`_fit/_householder.py`), and run apart they are no slower here
    h, means, covs, log_ev, codes = jax.lax.map(lambda a: _optimise(stats, basis, n_designs, a, max_steps), active)
    weight = jax.nn.softmax(jnp.where(jnp.isfinite(log_ev), log_ev, -jnp.inf))
    best = jnp.argmax(weight)
    mean = means[best]
    dev = means - mean[None, :]
    cov = jnp.einsum("k,kij->ij", weight, covs) + jnp.einsum("k,ki,kj->ij", weight, dev, dev)
    absent = (jnp.diagonal(cov) < OFF**2) & (jnp.abs(mean) < OFF)
    mean = jnp.where(absent, 0.0, mean)
    cov = jnp.where(absent[:, None] | absent[None, :], 0.0, cov)
    code = RESULTS.where(jnp.all(jnp.isfinite(mean)), as_result(codes[best]), RESULTS.nonfinite)
    return Solution(GraphPosterior(mean, cov, h, log_ev, weight), code, {})
