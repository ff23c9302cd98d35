"""Time integration of a mechanical model with diffrax."""

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._solution import RESULTS, Solution, error_if_failed
from ..model._model import AbstractMechanicalModel
from ._inputs import AbstractInput


class Integrator(eqx.Module):
    """ODE solver settings: Tsit5 with a PID step-size controller (the jump times of the input
    are declared to the controller), `max_steps`, and a divergence bound on |x| (a state
    beyond it stops the solve and is flagged `RESULTS.diverged`)."""

    rtol: float = 1e-8
    atol: float = 1e-10
    max_steps: int = eqx.field(static=True, default=200_000)
    bound: float = 1e6
    dt0: float | None = None


def _vector_field(model: AbstractMechanicalModel, inputs: AbstractInput):
    def f(t, y, args):
        x, v = y
        b, force = inputs(t)
        return v, model.accelerations(x, v, b, force)

    return f


@eqx.filter_jit
def simulate(
    model: AbstractMechanicalModel,
    inputs: AbstractInput,
    ts: Float[Array, " times"],
    x0: Float[Array, " dof"],
    v0: Float[Array, " dof"] | None = None,
    integrator: Integrator = Integrator(),
    *,
    throw: bool = True,
) -> Solution:
    """Integrate the model's equation of motion (paper Eq. 1) from (x0, v0) at ts[0].

    **Returns:** a `Solution` with `value = (x (times, dof), v (times, dof))`, `result` (a
    failed or diverged solve is flagged, its values NaN), `stats` with the step counts.
    """
    x0 = jnp.asarray(x0, float)
    v0 = jnp.zeros_like(x0) if v0 is None else jnp.asarray(v0, float)
    jumps = inputs.jump_times()
    ctrl = dfx.PIDController(rtol=integrator.rtol, atol=integrator.atol)
    if jumps is not None:
        ctrl = dfx.ClipStepSizeController(ctrl, jump_ts=jumps)

    def cond_fn(t, y, args, **kw):
        return jnp.max(jnp.abs(y[0])) > integrator.bound

    sol = dfx.diffeqsolve(
        dfx.ODETerm(_vector_field(model, inputs)),
        dfx.Tsit5(),
        ts[0],
        ts[-1],
        integrator.dt0,
        (x0, v0),
        saveat=dfx.SaveAt(ts=ts),
        stepsize_controller=ctrl,
        max_steps=integrator.max_steps,
        event=dfx.Event(cond_fn),
        throw=False,
    )
    xs, vs = sol.ys
    diverged = sol.result == dfx.RESULTS.event_occurred
    ok = sol.result == dfx.RESULTS.successful
    finite = jnp.all(jnp.isfinite(xs)) & jnp.all(jnp.isfinite(vs))
    result = RESULTS.where(ok & finite, RESULTS.successful, RESULTS.simulation_failed)
    result = RESULTS.where(diverged | (ok & ~finite), RESULTS.diverged, result)
    good = result == RESULTS.successful
    xs = jnp.where(good, xs, jnp.nan)
    vs = jnp.where(good, vs, jnp.nan)
    stats = {"num_steps": sol.stats["num_steps"], "num_rejected_steps": sol.stats["num_rejected_steps"]}
    return error_if_failed(Solution(value=(xs, vs), result=result, stats=stats), throw)
