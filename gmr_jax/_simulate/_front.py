"""Transition fronts: a snap that runs from element to element of a multi-stable lattice."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from .._errors import GMRInputError
from .._model._model import AbstractMechanicalModel
from ..metrics._metrics import equilibria
from .._solution import RESULTS
from .._topology import as_graph, as_topology
from ._inputs import AbstractInput
from ._simulate import simulate


class TransitionFront(eqx.Module):
    """A front's passage through the watched elements (`transition_front`).

    **Attributes:**

    - `times`: (E,) time each element's deformation first passes its saddle (linear between the
      saved times); NaN for an element not watched or never passing.
    - `levels`: (E,) the level of each element (-1: not watched), as given.
    - `propagated`: every watched element passed its saddle and ends within a quarter of its
      start-to-target distance of its target deformation.
    - `reached`: the highest level that, with every level below it, passed entirely (-1: none).
    - `speed`: levels per unit time, the inverse of the median spacing of successive levels'
      crossing times (a level's time: the mean over its elements), over the levels strictly
      between the lowest (the loaded one) and the highest (the free end; all levels when fewer
      than two lie between); the median leaves out a dwell of the front at its launch. NaN
      unless `propagated`.
    - `ts`, `x`: the saved times (T,) and node displacements (T, D).
    - `result`: the simulation's `RESULTS` code (a failed or diverged run: NaN values, nothing
      passed, not propagated).
    """

    times: Float[Array, " elements"]
    levels: Int[Array, " elements"]
    propagated: Bool[Array, ""]
    reached: Int[Array, ""]
    speed: Float[Array, ""]
    ts: Float[Array, " times"]
    x: Float[Array, "times dof"]
    result: RESULTS


def transition_front(
    model: AbstractMechanicalModel,
    start: Float[ArrayLike, " dof"],
    target: Float[ArrayLike, " dof"],
    load: AbstractInput,
    t1: float,
    levels: Int[ArrayLike, " elements"],
    *,
    dt: float = 0.02,
) -> TransitionFront:
    """Simulate the model from rest at `start` under `load` for `t1` and follow a transition
    front from `start` to `target` through the watched elements.

    Element e's saddle is the unstable zero of its restoring law between its deformations d_e
    in `start` and in `target` (the midpoint where the law has none there); e passes when
    d_e(t) first crosses it.

    **Arguments:**

    - `model`: a mechanical model on any topology (a chain's elements are its cells, independent
      DOFs each one element).
    - `start`, `target`: node displacements (D,) of the configurations the front leaves and
      makes (`gmr.configuration`).
    - `load`: the input that starts the front (e.g. `HalfSineNodes` on the first level's nodes).
    - `t1`: duration; `dt`: spacing of the saved times.
    - `levels`: (E,) whole numbers, each element's level counted from the load; -1 for an
      element not watched (couplers, rungs).

    **Returns:** a `TransitionFront`.
    """
    d = model.n_dof
    n_elements = as_graph(model.topology, d).n_elements
    deformations = as_topology(model.topology).deformations  # a chain's x are its cells' deformations
    start, target = (np.asarray(u, float) for u in (start, target))
    levels = np.asarray(levels)
    if start.shape != (d,) or target.shape != (d,):
        raise GMRInputError(f"start and target must be node displacements of shape ({d},), got {start.shape} and "
                            f"{target.shape}; build them with gmr.configuration(model, wells, pattern)")
    if levels.shape != (n_elements,) or not np.issubdtype(levels.dtype, np.integer) or np.all(levels < 0):
        raise GMRInputError(f"levels must be one whole number per element ({n_elements}), -1 for an element "
                            f"not watched, with at least one watched; got shape {levels.shape}")
    if not (np.isfinite(t1) and t1 > dt > 0):
        raise GMRInputError(f"t1 must exceed dt > 0, got t1 = {t1}, dt = {dt}")
    d0, d1 = (np.asarray(deformations(jnp.asarray(u))) for u in (start, target))
    watched = np.nonzero(levels >= 0)[0]
    if np.any(np.abs(d1[watched] - d0[watched]) == 0):
        raise GMRInputError("a watched element has the same deformation in start and target: nothing to cross; "
                            "watch only the elements the front switches")
    saddle = 0.5 * (d0 + d1)
    for e in watched:
        lo, hi = sorted((d0[e], d1[e]))
        zeros = [x for x, stable in equilibria(model, int(e), (lo, hi)) if not stable]
        if zeros:
            saddle[e] = zeros[0]
    ts = jnp.arange(int(np.floor(t1 / dt)) + 1) * dt
    sol = simulate(model, load, ts, jnp.asarray(start), throw=False)
    x = np.asarray(sol.value[0])
    dfm = np.asarray(deformations(jnp.asarray(x)))
    side = np.sign(d1 - d0)
    gap = (dfm - saddle) * side
    passed = gap > 0
    k = np.argmax(passed, axis=0)  # first sample past the saddle; the crossing is interpolated before it
    cols = np.arange(dfm.shape[1])
    before, after = gap[np.maximum(k - 1, 0), cols], gap[k, cols]
    frac = np.where((k > 0) & (after > before), -before / np.where(after > before, after - before, 1.0), 1.0)
    times = np.where(passed.any(0), np.asarray(ts)[k] - (1.0 - frac) * dt, np.nan)
    times[levels < 0] = np.nan
    ended = np.abs(dfm[-1] - d1) < 0.25 * np.abs(d1 - d0)
    crossed = np.isfinite(times)
    propagated = bool(np.all(crossed[watched]) and np.all(ended[watched]))
    ranks = np.unique(levels[watched])
    whole = np.array([np.all(crossed[levels == k]) for k in ranks])
    first_short = int(np.argmin(whole)) if not np.all(whole) else ranks.size
    reached = int(ranks[first_short - 1]) if first_short > 0 else -1
    speed = np.nan
    use = ranks[1:-1] if ranks.size >= 4 else ranks
    if propagated and use.size >= 2:
        level_times = np.array([np.mean(times[levels == k]) for k in use])
        speed = float(1.0 / np.median(np.diff(level_times) / np.diff(use)))
    return TransitionFront(times=jnp.asarray(times), levels=jnp.asarray(levels), propagated=jnp.asarray(propagated),
                           reached=jnp.asarray(reached), speed=jnp.asarray(speed), ts=ts, x=jnp.asarray(x),
                           result=sol.result)
