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
    the model's damping force holds the truth's, as `studies/coverage.py` measures it (the other DOFs at 0). The
    band is computed here with NumPy and SciPy from `model.covariance` (not `gmr.force_band`): rows sgn(v)|v|^j
    and x^j v against the DOF's velocity and position damping, z the normal quantile."""
    from scipy.stats import norm

    eq = system.equilibria[:, dof]
    vs = np.linspace(*system.v_range[dof], 41)
    xx, vv = (a.ravel() for a in np.meshgrid(np.linspace(eq.min(), eq.max(), 41), vs[vs != 0], indexing="ij"))
    b = np.asarray(model.velocity_damping, float)[dof]
    c = np.asarray(model.position_damping, float)[dof]
    ns = np.asarray(model.stiffness).shape[-1]
    rows = np.column_stack([np.sign(vv) * np.abs(vv) ** j for j in range(b.size)]
                           + [xx**j * vv for j in range(c.size)])
    cov = np.asarray(model.covariance, float)[dof][ns:, ns:]
    mean = rows @ np.concatenate([b, c])
    half = norm.ppf(0.5 + level / 2) * np.sqrt(np.maximum(np.einsum("ip,pq,iq->i", rows, cov, rows), 0.0))
    d = system.equilibria.shape[1]
    x = jnp.zeros((xx.size, d)).at[:, dof].set(jnp.asarray(xx))
    v = jnp.zeros((vv.size, d)).at[:, dof].set(jnp.asarray(vv))
    truth = np.asarray(jax.vmap(system.truth.damping)(x, v))[:, dof]
    return float(np.mean((truth >= mean - half) & (truth <= mean + half)))
