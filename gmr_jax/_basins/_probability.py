"""Basin maps drawn from the model distribution (issue 15): per grid point, the probability of
each final configuration when the coefficients are drawn from N(coefficients, covariance)."""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int, PRNGKeyArray

from .._errors import GMRInputError
from .._model._model import GlobalModel
from .._model._uncertainty import sample_models
from .._solution import RESULTS, Solution
from ._sweep import SweepSettings, basin_map
from ._wells import stable_wells


class BasinProbability(eqx.Module):
    """`configs` (c,): the configurations met (bit fields as `BasinMap.config`; -1: not settled
    or failed), ascending; `probability` (NA, NF, c): per grid point, the share of the used
    samples that ended in each; `most_likely` (NA, NF): the configuration of highest
    probability; `confidence` (NA, NF): its probability; `mean_config` (NA, NF): the
    configuration the model itself (the distribution's mean) ends in."""

    f: Float[Array, " nf"]
    A: Float[Array, " na"]
    configs: Int[Array, " c"]
    probability: Float[Array, "na nf c"]
    most_likely: Int[Array, "na nf"]
    confidence: Float[Array, "na nf"]
    mean_config: Int[Array, "na nf"]


def basin_probability(
    model: GlobalModel,
    f: Float[ArrayLike, " nf"],
    A: Float[ArrayLike, " na"],
    key: PRNGKeyArray,
    n: int = 16,
    *,
    x_range: Float[ArrayLike, "dof 2"],
    x0: Float[ArrayLike, " dof"] | None = None,
    settings: SweepSettings = SweepSettings(),
    chunk: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Solution:
    """Basin map (`basin_map`, Eq. 25 load) propagated through the model's uncertainty: `n`
    models drawn from N(coefficients, `GlobalModel.covariance`) (`sample_models`), each swept
    over the (f, A) grid from its own wells, and per grid point the probability of each final
    configuration.

    **Arguments:**

    - `model`: a `GlobalModel` with a covariance (from `reconstruct`).
    - `f`, `A`, `x0`, `settings`, `chunk`: as `basin_map` (every sample is swept with the same
      compiled function: coefficients are traced, so the n sweeps compile once).
    - `key`, `n`: the `jax.random` key and number of samples.
    - `x_range`: (lo, hi) or (dof, 2), the interval of each DOF in which each sample's stable
      wells are searched (`stable_wells`), e.g. the span of the training data.
    - `progress`: optional `progress(done, n)` after each sample.

    **Returns:** a `Solution` whose `value` is a `BasinProbability`. A sample whose number of
    stable wells in `x_range` differs from the model's (the distribution puts weight on a
    different landscape) cannot be read in the model's configurations: it is left out of the
    probabilities and counted in `stats["samples_other_wells"]`; `stats["samples_used"]` is the
    number the probabilities average over (`result` is `RESULTS.nonfinite` when none is).
    A point where a sample failed or did not settle counts for configuration -1 (each sweep
    runs with `throw=False`; `stats["counts"]` sums the sweeps' codes).
    """
    n = int(n)
    if n < 1:
        raise GMRInputError(f"basin_probability: n must be >= 1, got {n}")
    samples = sample_models(model, key, n)  # refuses a model without a covariance first
    wells0 = stable_wells(model, x_range)
    mean_map = basin_map(model, f, A, wells0, x0=x0, settings=settings, chunk=chunk, throw=False)
    n_wells = np.sum(np.isfinite(wells0), axis=1)
    configs, used, other, counts = [], 0, 0, {}
    for k in range(n):
        m = jax.tree.map(lambda a, k=k: a[k] if eqx.is_array(a) else a, samples)
        w = stable_wells(m, x_range)
        if w.shape != wells0.shape or np.any(np.sum(np.isfinite(w), axis=1) != n_wells):
            other += 1
        else:
            sol = basin_map(m, f, A, w, x0=x0, settings=settings, chunk=chunk, throw=False)
            configs.append(np.asarray(sol.value.config))
            used += 1
            for name, c in sol.stats["counts"].items():
                counts[name] = counts.get(name, 0) + c
        if progress is not None:
            progress(k + 1, n)
    bm0 = mean_map.value
    if not configs:
        shape = np.asarray(bm0.config).shape
        value = BasinProbability(f=bm0.f, A=bm0.A, configs=jnp.zeros(0, int), probability=jnp.zeros(shape + (0,)),
                                 most_likely=jnp.full(shape, -1), confidence=jnp.zeros(shape),
                                 mean_config=bm0.config)
        return Solution(value=value, result=RESULTS.nonfinite,
                        stats={"samples_used": 0, "samples_other_wells": other, "counts": counts})
    stack = np.stack(configs)  # (used, NA, NF)
    values = np.unique(stack)
    prob = np.stack([np.mean(stack == c, axis=0) for c in values], axis=-1)
    best = np.argmax(prob, axis=-1)
    value = BasinProbability(f=bm0.f, A=bm0.A, configs=jnp.asarray(values),
                             probability=jnp.asarray(prob), most_likely=jnp.asarray(values[best]),
                             confidence=jnp.asarray(np.max(prob, axis=-1)), mean_config=bm0.config)
    return Solution(value=value, result=RESULTS.successful,
                    stats={"samples_used": used, "samples_other_wells": other, "counts": counts})
