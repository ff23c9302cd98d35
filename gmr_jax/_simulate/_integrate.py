"""The one ODE kernel: every solve of gmr_jax (simulate, transmissibility, basin chunks, refinement
windows, actuation) goes through `integrate`, so the solver, the step-size control, the
declared discontinuities, the divergence box and the mapping of diffrax's outcome to a
`RESULTS` code live in one place.

- Solver: Tsit5 (explicit 5(4) pair; the systems here are not stiff) with a PID step-size
  controller at `Integrator.rtol`/`atol`.
- Discontinuities: `jump_ts` (the input jumps there: the controller steps up to each and
  restarts; e.g. the switch-off time 1/(2f) of the Eq. 25 half-sine) and `step_ts` (a step ends
  on each: the kinks of a linearly interpolated recorded input).
- Divergence box: with `box=(lo, hi)` the solve stops as soon as a displacement leaves
  [lo, hi] and the result is `RESULTS.diverged`: a model that escapes is flagged, never
  returned as a number.
- Outcome: `successful`; `diverged` (left the box, or non-finite values); otherwise diffrax's
  own code promoted into `RESULTS` (`max_steps_reached`, `dt_min_reached`, ...), whose message
  says what to change.
"""

from typing import Any, NamedTuple

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, PyTree

from .._solution import RESULTS


class Integrator(eqx.Module):
    """ODE solver settings shared by every solve: Tsit5 with PID step-size control.

    **Attributes:**

    - `rtol`, `atol`: tolerances of the PID controller (arrays are fine: a sweep over
      tolerances does not recompile).
    - `max_steps`: step budget of one solve (static: fixes the compiled loop); reaching it gives
      `RESULTS.max_steps_reached`.
    - `dt0`: first step (None: chosen by diffrax).
    """

    rtol: float = 1e-8
    atol: float = 1e-10
    max_steps: int = eqx.field(static=True, default=200_000)
    dt0: float | None = None


class Trajectory(NamedTuple):
    """What `integrate` returns: `ys` at the save times (as diffrax gives them), `result` a
    `RESULTS` code, `stats` diffrax's step counts."""

    ys: PyTree
    result: RESULTS
    stats: dict[str, Any]


def integrate(
    field,
    t0,
    t1,
    y0: tuple[Float[Array, "..."], Float[Array, "..."]],
    integrator: Integrator,
    *,
    saveat: dfx.SaveAt,
    box: tuple[Array, Array] | None = None,
    jump_ts: Float[Array, " jumps"] | None = None,
    step_ts: Float[Array, " steps"] | None = None,
    norm=None,
    adjoint: dfx.AbstractAdjoint = dfx.RecursiveCheckpointAdjoint(),
) -> Trajectory:
    """Integrate y' = field(t, y, args) for y = (x, v) from t0 to t1 (see the module docstring).

    **Arguments:**

    - `field`: the vector field `(t, (x, v), args) -> (x', v')`.
    - `t0`, `t1`, `y0`: the interval and the initial state (x, v).
    - `integrator`: an `Integrator` (tolerances, step budget, first step).
    - `saveat`: a diffrax `SaveAt`.
    - `box`: `(lo, hi)` bounds on x (broadcast against it): leaving them stops the solve with
      `RESULTS.diverged`.
    - `jump_ts`, `step_ts`: discontinuities declared to the step-size controller.
    - `norm`: error norm of the controller (default diffrax's RMS norm).
    - `adjoint`: how to differentiate through the solve (`ForwardMode` for Jacobians by
      forward mode, the default checkpointed adjoint for reverse mode).
    """
    kw = {} if norm is None else {"norm": norm}
    ctrl = dfx.PIDController(rtol=integrator.rtol, atol=integrator.atol, **kw)
    if jump_ts is not None or step_ts is not None:
        ctrl = dfx.ClipStepSizeController(ctrl, jump_ts=jump_ts, step_ts=step_ts)
    event = None
    if box is not None:
        lo, hi = box

        def outside(t, y, args, **kwargs):
            return jnp.any((y[0] < lo) | (y[0] > hi))

        event = dfx.Event(outside)
    sol = dfx.diffeqsolve(
        dfx.ODETerm(field), dfx.Tsit5(), t0, t1, integrator.dt0, y0, saveat=saveat,
        stepsize_controller=ctrl, max_steps=integrator.max_steps, event=event, adjoint=adjoint,
        throw=False,
    )
    finite = jnp.all(jnp.asarray([jnp.all(jnp.isfinite(y)) for y in sol.ys]))
    ok = sol.result == dfx.RESULTS.successful
    result = RESULTS.where(ok & finite, RESULTS.successful, RESULTS.promote(sol.result))
    left = (sol.result == dfx.RESULTS.event_occurred) | (ok & ~finite)
    result = RESULTS.where(left, RESULTS.diverged, result)
    stats = {"num_steps": sol.stats["num_steps"], "num_rejected_steps": sol.stats["num_rejected_steps"]}
    return Trajectory(sol.ys, result, stats)


def vector_field(model, inputs):
    """The model's equation of motion (paper Eq. 1) under `inputs` as a first-order field."""

    def f(t, y, args):
        x, v = y
        b, force = inputs(t)
        return v, model.accelerations(x, v, b, force)

    return f
