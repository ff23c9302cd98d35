"""Reconstruction on a `Graph`: every element's global law, jointly, from every node's balance.

1. Validate and complete the recordings (node displacements relative to the base: a = x'' +
   base_acc, as for independent DOFs), settle the masses (one per node).
2. Per record and node, the force balance's target p + s'' (p = force - m a where a is
   measured, else p = force - m base_acc and s = -m x); per element, its deformation and rate.
3. Weak-form columns of every element, signed by the incidence and summed per node and design;
   the evidence posterior of every design's law (`_coordination._graph`).
4. The posterior mapped to each element's monomial coefficients (its design's), with its
   covariance, as a `GlobalModel` on the graph.
"""

import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._coordination import _bayes
from .._coordination._graph import graph_posterior
from .._custom_types import Array, Bool, Float
from .._errors import GMRInputError
from .._solution import RESULTS, Solution
from .._topology import Graph
from ._estimator import ReconstructSettings, balances, model_from, window


def graph_arrays(
    dx: Float[Array, "elements records samples"],
    dv: Float[Array, "elements records samples"],
    p: Float[Array, "records nodes samples"],
    s: Float[Array, "records nodes samples"],
    mask: Bool[Array, "records samples"],
    incidence: Float[Array, "elements nodes"],
    design: Float[Array, "elements designs"],
    *,
    width: int,
    dt: float,
    settings: ReconstructSettings = ReconstructSettings(),
):
    """The reconstruction on a graph as a pure function of arrays.

    **Arguments:** element deformations `dx` and rates `dv`; the node balances' `p`, `s`
    (y = p + s''); `mask` False on padding; `incidence` B (E, D); `design` (E, G) one-hot: the
    design of each element; `width` samples per test-function window, `dt`, `settings` (degree,
    damping order).

    **Returns:** `(coef (G, Q), covariance (G, Q, Q), solution)`: each design's monomial
    coefficients in the order stiffness x^0..x^K, velocity damping sgn(v)|v|^0..d, position
    damping x^0..x^d v, their covariance, and the posterior's `Solution`."""
    basis = _bayes.Basis(settings.degree, settings.damping_order)
    n_designs = design.shape[1]
    on = design > 0
    m = mask[None, :, :]
    lo_e = jnp.min(jnp.where(m, dx, jnp.inf), axis=(1, 2))
    hi_e = jnp.max(jnp.where(m, dx, -jnp.inf), axis=(1, 2))
    sp_e = jnp.max(jnp.where(m, jnp.abs(dv), 0.0), axis=(1, 2))
    lo = jnp.min(jnp.where(on, lo_e[:, None], jnp.inf), axis=0)
    hi = jnp.max(jnp.where(on, hi_e[:, None], -jnp.inf), axis=0)
    speed = jnp.max(jnp.where(on, sp_e[:, None], 0.0), axis=0)
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    c_e, h_e, s_e = (design @ a for a in (centre, half, speed))
    zeros = jnp.zeros_like(dx[0])

    def element_rows(x, v, c, h, sp):
        return _bayes.weak_rows(x, v, zeros, zeros, mask, c, h, sp, basis, width, dt)[0]

    rows = jax.vmap(element_rows)(dx, dv, c_e, h_e, s_e)  # (E, R, M, P)
    r_, d_ = p.shape[:2]
    node_rows = jnp.einsum("ed,eg,ermp->rdmgp", incidence, design, rows)
    node_rows = node_rows.reshape(r_ * d_, rows.shape[2], n_designs * basis.n)
    phi, _, d2 = (jnp.asarray(f) for f in _bayes.test_functions(width)[0])
    win = lambda a: _bayes._windows(a, width)  # noqa: E731
    target = (jnp.einsum("rdmn,n->rdm", win(p), phi) + jnp.einsum("rdmn,n->rdm", win(s), d2) / dt**2)
    valid = jnp.all(win(mask), axis=-1)  # (R, M)
    valid = jnp.broadcast_to(valid[:, None, :], target.shape).reshape(r_ * d_, -1)
    target = target.reshape(r_ * d_, -1)
    scale = jnp.sqrt(jnp.sum(valid * target**2) / jnp.maximum(jnp.sum(valid), 1.0))
    groups = r_ * d_
    stats = _bayes.well_statistics(node_rows, target / scale, valid, jnp.arange(groups), groups)
    sol = graph_posterior(stats, basis, n_designs)
    M = jax.vmap(lambda c, h, sp: _bayes.to_monomials(basis, c, h, sp, scale))(centre, half, speed)  # (G, Q, P)
    mean = sol.value.mean.reshape(n_designs, basis.n)
    cov = sol.value.covariance.reshape(n_designs, basis.n, n_designs, basis.n)
    cov_g = jnp.einsum("gqp,gpgr,gsr->gqs", M, cov, M)  # each design's block
    return jnp.einsum("gqp,gp->gq", M, mean), cov_g, sol


@eqx.filter_jit
def _fit(dx, dv, p, s, mask, incidence, design, width, dt, settings):
    return graph_arrays(dx, dv, p, s, mask, incidence, design, width=width, dt=dt, settings=settings)


def check_designs(designs, graph: Graph) -> np.ndarray:
    """(E,) integer design labels 0..G-1 (None: every element its own design)."""
    e = graph.n_elements
    if designs is None:
        return np.arange(e)
    lab = np.asarray(designs)
    if lab.shape != (e,) or lab.dtype.kind not in "iu":
        raise GMRInputError(f"designs must be one integer label per element ({e} of them), got "
                            f"{np.shape(lab)} {lab.dtype}; elements with the same label share one law")
    _, lab = np.unique(lab, return_inverse=True)
    return lab.reshape(e)


def reconstruct_graph(recs, masses, graph: Graph, designs, settings: ReconstructSettings, say) -> Solution:
    """Stages 2-4 for completed recordings of the graph's nodes (see the module docstring)."""
    d = graph.nodes
    if recs[0].n_dof != d:
        raise GMRInputError(f"the recordings have {recs[0].n_dof} columns of x but the graph has {d} nodes; record "
                            f"every node's displacement relative to the base, one column per node")
    labels = check_designs(designs, graph)
    n_designs = int(labels.max()) + 1
    t0 = time.perf_counter()
    n = max(r.n_samples for r in recs)
    pad = lambda a: np.pad(a, [(0, 0)] * (a.ndim - 1) + [(0, n - a.shape[-1])])  # noqa: E731
    dx = np.stack([pad(np.asarray(graph.deformations(r.x)).T) for r in recs], axis=1)  # (E, R, N)
    dv = np.stack([pad(np.asarray(graph.deformations(r.v)).T) for r in recs], axis=1)
    p, s = zip(*[(pad(a.T), pad(b.T)) for a, b in (balances(r, masses, graph) for r in recs)])
    mask = np.stack([np.arange(n) < r.n_samples for r in recs])
    width = window([r_ for e in dx for r_ in e], recs[0].dt, min(r.n_samples for r in recs), settings)
    say(f"graph of {d} nodes, {graph.n_elements} elements, {n_designs} design(s): posterior of every law")
    design = np.eye(n_designs)[labels]
    coef, cov, sol = _fit(*(jnp.asarray(a) for a in (dx, dv, np.stack(p), np.stack(s), mask, graph.incidence,
                                                     design)), width, recs[0].dt, settings)
    coef, cov = np.asarray(coef), np.asarray(cov)
    k, dd = settings.degree, settings.damping_order
    blocks = [(coef[g][: k + 1], coef[g][k + 1: k + dd + 2], coef[g][k + dd + 2:]) for g in labels]
    model = model_from(masses, graph, blocks, [cov[g] for g in labels])
    post = sol.value
    h = post.hyper
    stats = {
        "method": "GMR", "coordination": "evidence", "topology": graph.to_dict(),
        "designs": labels.tolist(), "width": width,
        "degree": int(np.argmax(np.asarray(post.weight))) + 1,
        "degree_weight": np.asarray(post.weight).tolist(),
        "prior_scale": np.exp(np.asarray(h.log_scale)).tolist(),
        "prior_decay": np.asarray(jax.nn.sigmoid(h.logit_decay)).tolist(),
        "data_range": [[float(a.min()), float(a.max())] for a in dx],
        "speed_range": [[float(a.min()), float(a.max())] for a in dv],
        "seconds": time.perf_counter() - t0,
        "warnings": [],
    }
    result = sol.result
    if result != RESULTS.successful:
        stats["warnings"].append(f"evidence maximisation: {RESULTS[result]}")
    return Solution(model, result, stats)
