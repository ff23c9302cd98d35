"""Stable equilibria (wells) of each DOF of a model, for classifying final states."""

import jax
import jax.numpy as jnp
import numpy as np

from .._model._model import AbstractMechanicalModel


def stable_wells(model: AbstractMechanicalModel, x_range, n: int = 20001) -> np.ndarray:
    """Stable zeros of each DOF's restoring force, ordered by increasing deformation.

    `x_range`: (dof, 2) search interval per DOF. Returns (dof, max_wells), NaN-padded. With no
    external load each cell of a chain is at rest only where its own F_i(x_i) = 0."""
    x_range = np.asarray(x_range, float).reshape(-1, 2)
    d = model.n_dof
    out = []
    for i in range(d):
        xs = np.linspace(*x_range[i], n)

        def f(x, i=i):
            return model.restoring(jnp.zeros(d).at[i].set(x))[i]

        fx = np.asarray(jax.vmap(f)(jnp.asarray(xs)))
        idx = np.nonzero((fx[:-1] < 0) & (fx[1:] >= 0))[0]  # increasing crossing: stable
        roots = xs[idx] - fx[idx] * (xs[idx + 1] - xs[idx]) / (fx[idx + 1] - fx[idx])
        out.append(roots)
    width = max(1, max(len(r) for r in out))
    wells = np.full((d, width), np.nan)
    for i, r in enumerate(out):
        wells[i, : len(r)] = r
    return wells
