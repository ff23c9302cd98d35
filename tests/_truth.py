"""Independent measures for the tests: a fitted law against the truth, by NumPy (not `gmr.metrics`)."""

import jax
import jax.numpy as jnp
import numpy as np


def restoring_l2(system, stiffness, n: int = 401):
    """Relative L2 of a single-DOF system's fitted restoring polynomial (ascending `stiffness`)
    against its truth over the metrics box `x_range`, on `n` points: `(error, model, truth)`."""
    xs = np.linspace(*system.x_range[0], n)
    truth = np.array([float(system.truth.restoring(jnp.asarray([x]))[0]) for x in xs])
    model = np.polynomial.polynomial.polyval(xs, np.asarray(stiffness, float))
    return float(np.linalg.norm(model - truth) / np.linalg.norm(truth)), model, truth


def damping_coverage(model, system, level: float = 0.95, dof: int = 0) -> float:
    """Share of the grid span x v_range (41 x 40 points, v != 0) of DOF `dof` where the band of level `level` on
    the model's damping force holds the truth's, as `studies/coverage.py` measures it (the other DOFs at 0)."""
    import gmr_jax as g

    eq = system.equilibria[:, dof]
    vs = np.linspace(*system.v_range[dof], 41)
    xx, vv = (a.ravel() for a in np.meshgrid(np.linspace(eq.min(), eq.max(), 41), vs[vs != 0], indexing="ij"))
    d = system.equilibria.shape[1]
    x = jnp.zeros((xx.size, d)).at[:, dof].set(jnp.asarray(xx))
    v = jnp.zeros((vv.size, d)).at[:, dof].set(jnp.asarray(vv))
    band = jax.vmap(lambda p, q: g.force_band(model, p, q, part="damping", level=level))(x, v)
    truth = np.asarray(jax.vmap(system.truth.damping)(x, v))[:, dof]
    return float(np.mean((truth >= np.asarray(band.lower)[:, dof]) & (truth <= np.asarray(band.upper)[:, dof])))
