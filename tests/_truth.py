"""Independent measures for the tests: a fitted law against the truth, by NumPy (not `gmr.metrics`)."""

import jax.numpy as jnp
import numpy as np


def restoring_l2(system, stiffness, n: int = 401):
    """Relative L2 of a single-DOF system's fitted restoring polynomial (ascending `stiffness`)
    against its truth over the metrics box `x_range`, on `n` points: `(error, model, truth)`."""
    xs = np.linspace(*system.x_range[0], n)
    truth = np.array([float(system.truth.restoring(jnp.asarray([x]))[0]) for x in xs])
    model = np.polynomial.polynomial.polyval(xs, np.asarray(stiffness, float))
    return float(np.linalg.norm(model - truth) / np.linalg.norm(truth)), model, truth
