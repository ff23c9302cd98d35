"""Basin maps drawn from the model distribution (issue 15): per grid point, the probability of
each final configuration when the coefficients are drawn from N(coefficients, covariance)."""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, Int, PRNGKeyArray

from .._config import relieve_map_pressure
from .._model._admissible import damping_faults, fall_speed
from .._errors import GMRInputError
from .._model._model import GlobalModel
from .._model._uncertainty import sample_models
from .._solution import RESULTS, Solution, code_name
from ._sweep import SweepSettings, _check_inputs, ensemble_configs, friction_smoothing
from ._wells import stable_wells


class BasinProbability(eqx.Module):
    """`configs` (c,): the configurations met (codes as `BasinMap.config`: bit fields for
    bistable cells, base-K digits with K wells; -1: not settled
    or failed), ascending; `probability` (NA, NF, c): per grid point, the share of the used
    samples that ended in each; `most_likely` (NA, NF): the configuration of highest
    probability; `confidence` (NA, NF): its probability; `mean_config` (NA, NF): the
    configuration the model itself (the distribution's mean) ends in; `unsettled` (NA, NF): the
    share of the used samples that had not settled in a well by t1 (`not_settled`: counted in
    configuration -1 with the ones that failed or diverged; a longer settle time decides them)."""

    f: Float[Array, " nf"]
    A: Float[Array, " na"]
    configs: Int[Array, " c"]
    probability: Float[Array, "na nf c"]
    most_likely: Int[Array, "na nf"]
    confidence: Float[Array, "na nf"]
    mean_config: Int[Array, "na nf"]
    unsettled: Float[Array, "na nf"]


def feeds_energy(model: GlobalModel, wells: np.ndarray, x_range) -> list[str]:
    """Why `model`'s damping is not dissipative where its basin map is read, or [] (`damping_faults`
    per DOF: D(x, v) v >= 0 over the span of the DOF's wells widened by half of it on either side, or
    `x_range` so widened with one well, and |v| up to the speed of a fall from anywhere in `x_range` to
    its lowest-lying well, sqrt(2 max(V - V_well) / m_i), V = ∫ F dx). A DOF without a well is not
    read. The bound leaves out the energy the load puts in and, in a chain, the masses a cell moves
    beyond its own: a check of the span of use, not a proof of passivity."""
    x_range = np.broadcast_to(np.asarray(x_range, float), (model.n_dof, 2))
    out = []
    for i in range(model.n_dof):
        w = np.asarray(wells[i], float)
        w = w[np.isfinite(w)]
        if w.size == 0:
            continue
        speed = fall_speed(model.stiffness[i], w, float(model.masses[i]), *x_range[i])
        if not speed > 0:
            continue
        span = w if w.size > 1 else x_range[i]
        out += [f"DOF {i}: {why}" for why in damping_faults(np.asarray(model.velocity_damping[i]),
                                                             np.asarray(model.position_damping[i]), span, speed)]
    return out


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
    max_draws: int | None = None,
) -> Solution:
    """Basin map (`basin_map`, Eq. 25 load) propagated through the model's uncertainty: `n`
    models drawn from N(coefficients, `GlobalModel.covariance`) (`sample_models`), each swept
    over the (f, A) grid from its own wells, and per grid point the probability of each final
    configuration.

    **Arguments:**

    - `model`: a `GlobalModel` with a covariance (from `reconstruct`).
    - `f`, `A`, `x0`, `settings`, `chunk`: as `basin_map`. Under "lanes" batching (the default)
      the models are data: the model and its n samples over the grid are one batch of
      (n + 1) x NA x NF points through one compiled lanes loop, each lane carrying its point's
      coefficients and wells; other batchings sweep them one after another.
    - `key`, `n`: the `jax.random` key and the number of samples the probabilities average over.
    - `x_range`: (lo, hi) or (dof, 2), the interval of each DOF in which each sample's stable
      wells are searched (`stable_wells`), e.g. the span of the training data.
    - `progress`: optional `progress(used, n)` after each draw (the draws are checked before the
      one sweep).
    - `max_draws`: at most this many draws (default 8 n) to find the n samples.

    **Returns:** a `Solution` whose `value` is a `BasinProbability`. A sample whose number of
    stable wells in `x_range` differs from the model's (the distribution puts weight on a
    different landscape) cannot be read in the model's configurations: it is left out of the
    probabilities and counted in `stats["samples_other_wells"]`. A sample whose damping feeds
    energy in where the map is read (`feeds_energy`: the tail of the distribution past
    D(x, v) v = 0, a structure that is not passive) is left out and counted in
    `stats["samples_non_dissipative"]` (the model's own faults, if any, in
    `stats["mean_non_dissipative"]`): the probabilities are those of the distribution restricted
    to passive structures with the model's landscape. Draws go on until n samples are used or
    `max_draws` were drawn (`stats["samples_drawn"]`); `stats["samples_used"]` is the number the
    probabilities average over (`result` is `RESULTS.nonfinite` when none is).
    A point where a sample failed or did not settle counts for configuration -1 (the sweep runs
    without raising; `stats["counts"]` counts the samples' codes). A Coulomb term is smoothed as
    in `basin_map`, with the eps of the model's own wells for every sample.
    """
    relieve_map_pressure()  # a long session's compiled programs (`_config.map_pressure`)
    n = int(n)
    if n < 1:
        raise GMRInputError(f"basin_probability: n must be >= 1, got {n}")
    max_draws = 8 * n if max_draws is None else int(max_draws)
    if max_draws < 1:
        raise GMRInputError(f"basin_probability: max_draws must be >= 1, got {max_draws}")
    first = sample_models(model, key, min(n, max_draws))  # refuses a model without a covariance first
    wells0 = stable_wells(model, x_range)
    f_np, a_np, wells0, x0_np = _check_inputs(model, f, A, wells0, x0)
    n_wells = np.sum(np.isfinite(wells0), axis=1)
    used, drawn, other, passive, batch = [], 0, 0, 0, 0
    # the draws are filtered first (host-side: wells and passivity of each), then swept together
    while len(used) < n and drawn < max_draws:
        # the first n draws are `sample_models(model, key, n)`; more batches, where some were left out
        size = min(n, max_draws - drawn)
        samples = first if batch == 0 else sample_models(model, jax.random.fold_in(key, batch), size)
        batch += 1
        for k in range(size):
            if len(used) == n:
                break
            drawn += 1
            m = jax.tree.map(lambda a, k=k: a[k] if eqx.is_array(a) else a, samples)
            w = stable_wells(m, x_range)
            if w.shape != wells0.shape or np.any(np.sum(np.isfinite(w), axis=1) != n_wells):
                other += 1
            elif feeds_energy(m, w, x_range):
                passive += 1
            else:
                used.append((m, w))
            if progress is not None:
                progress(len(used), n)
    # the model itself first, then the used draws: one ensemble, one sweep
    smooth, _ = friction_smoothing(model, settings, wells0)
    members = [smooth] + [m for m, _ in used]
    stack = GlobalModel(masses=jnp.stack([jnp.asarray(m.masses) for m in members]),
                        stiffness=jnp.stack([jnp.asarray(m.stiffness) for m in members]),
                        velocity_damping=jnp.stack([jnp.asarray(m.velocity_damping) for m in members]),
                        position_damping=jnp.stack([jnp.asarray(m.position_damping) for m in members]),
                        topology=model.topology, sign_eps=smooth.sign_eps)
    wells_m = np.stack([wells0] + [w for _, w in used])
    x0s = wells_m[:, :, 0] if x0_np is None else np.broadcast_to(x0_np, wells_m.shape[:2])
    configs, codes = ensemble_configs(stack, f_np, a_np, wells_m, x0s, settings, chunk=chunk)
    values_c, counts_c = np.unique(codes[1:], return_counts=True)
    counts = {code_name(v): int(c) for v, c in zip(values_c, counts_c)}
    n_used = len(used)
    mean_config = jnp.asarray(configs[0])
    fj, aj = jnp.asarray(f_np), jnp.asarray(a_np)
    stats = {"samples_used": n_used, "samples_drawn": drawn, "samples_other_wells": other,
             "samples_non_dissipative": passive, "mean_non_dissipative": feeds_energy(model, wells0, x_range),
             "counts": counts}
    if not n_used:
        shape = mean_config.shape
        value = BasinProbability(f=fj, A=aj, configs=jnp.zeros(0, int), probability=jnp.zeros(shape + (0,)),
                                 most_likely=jnp.full(shape, -1), confidence=jnp.zeros(shape), mean_config=mean_config,
                                 unsettled=jnp.zeros(shape))
        return Solution(value=value, result=RESULTS.nonfinite, stats=dict(stats, samples_used=0))
    stack_c = configs[1:]  # (used, NA, NF)
    values = np.unique(stack_c)
    prob = np.stack([np.mean(stack_c == c, axis=0) for c in values], axis=-1)
    best = np.argmax(prob, axis=-1)
    value = BasinProbability(f=fj, A=aj, configs=jnp.asarray(values), probability=jnp.asarray(prob),
                             most_likely=jnp.asarray(values[best]), confidence=jnp.asarray(np.max(prob, axis=-1)),
                             mean_config=mean_config,
                             unsettled=jnp.asarray(np.mean(codes[1:] == RESULTS.not_settled._value, axis=0)))
    return Solution(value=value, result=RESULTS.successful, stats=stats)
