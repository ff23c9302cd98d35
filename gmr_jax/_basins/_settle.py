"""How long a model takes to settle into a well: the settle time that every command classifying
final states uses unless told otherwise."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np

#: the slowest linearised mode decays by e^-7 (about a thousandfold) in the settle time
DECAYS = 7.0


def slowest_decay(model, wells, max_configs: int = 64, configurations=None) -> tuple[float, float]:
    """(sigma, scale): the slowest decay rate sigma (1/s) of the model's free motion about its
    stable configurations (each DOF at one of its wells, at most `max_configs` configurations;
    or the coordinates `configurations` given, e.g. a `Graph`'s node displacements), the smallest
    -Re(lambda) over the eigenvalues lambda of the linearised equations of motion, and the
    largest |lambda| (for judging sigma = 0 against rounding)."""
    d = model.n_dof
    per_dof = [w[~np.isnan(w)] for w in np.asarray(wells, float)]
    configs = (itertools.islice(itertools.product(*per_dof), max_configs) if configurations is None
               else [np.asarray(c, float) for c in configurations])

    def field(state):
        x, v = state[:d], state[d:]
        return jnp.concatenate([v, model.accelerations(x, v, 0.0, jnp.zeros(d))])

    jac = jax.jit(jax.jacfwd(field))
    rates, scale = [], 0.0
    for conf in configs:
        state = jnp.concatenate([jnp.asarray(conf, float), jnp.zeros(d)])
        ev = np.linalg.eigvals(np.asarray(jac(state)))
        rates.append(float(np.min(-ev.real)))
        scale = max(scale, float(np.max(np.abs(ev))))
    return (min(rates) if rates else float("nan")), scale


def model_settle_time(model, wells, floor: float = 10.0, configurations=None) -> float | None:
    """The free time after the load in which the model's slowest linearised mode about its wells
    decays by e^-7, 7 / sigma (`slowest_decay`), rounded up to two significant digits and at
    least `floor`; None where the model's free motion does not decay (sigma = 0 to rounding:
    no settle time will do)."""
    sigma, scale = slowest_decay(model, wells, configurations=configurations)
    if not np.isfinite(sigma) or sigma <= 1e-9 * scale:
        return None
    need = DECAYS / sigma
    digits = 10.0 ** (np.floor(np.log10(need)) - 1)
    return float(max(floor, np.ceil(need / digits) * digits))
