"""Time integration of a mechanical model (paper Eq. 1) under an input, with diffrax."""

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._model._model import AbstractMechanicalModel
from .._solution import RESULTS, Solution, error_if_failed
from ._inputs import AbstractInput
from ._integrate import Integrator, integrate, vector_field

#: Default divergence box of `simulate`: a displacement beyond +-1e6 (model units) is divergence.
DEFAULT_BOX = 1e6


@eqx.filter_jit
def simulate(
    model: AbstractMechanicalModel,
    inputs: AbstractInput,
    ts: Float[Array, " times"],
    x0: Float[ArrayLike, " dof"],
    v0: Float[ArrayLike, " dof"] | None = None,
    integrator: Integrator = Integrator(),
    *,
    box: float | tuple = DEFAULT_BOX,
    throw: bool = True,
) -> Solution:
    """Integrate the model's equation of motion (paper Eq. 1) from (x0, v0) at ts[0].

    **Arguments:**

    - `model`, `inputs`: any mechanical model and an input (`BaseChirp`, `HalfSineTip`,
      `Sampled`, ...); the input's jump times are declared to the step-size controller.
    - `ts`: save times (the first is the start time).
    - `x0`, `v0`: initial displacements and velocities (default at rest).
    - `integrator`: tolerances and step budget (`Integrator`).
    - `box`: divergence box on x: a number b (|x| <= b) or `(lo, hi)` arrays; leaving it stops
      the solve with `RESULTS.diverged`.
    - `throw`: raise on failure (use `False` under vmap and read `result`).

    **Returns:** a `Solution` with `value = (x (times, dof), v (times, dof))`, `result` (a
    failed or diverged solve is flagged, its values NaN), `stats` with the step counts.
    """
    x0 = jnp.asarray(x0, float)
    v0 = jnp.zeros_like(x0) if v0 is None else jnp.asarray(v0, float)
    lo, hi = (-box, box) if not isinstance(box, tuple) else box
    traj = integrate(vector_field(model, inputs), ts[0], ts[-1], (x0, v0), integrator,
                     saveat=dfx.SaveAt(ts=ts), box=(lo, hi), jump_ts=inputs.jump_times())
    good = traj.result == RESULTS.successful
    xs, vs = (jnp.where(good, y, jnp.nan) for y in traj.ys)
    return error_if_failed(Solution(value=(xs, vs), result=traj.result, stats=traj.stats), throw)

