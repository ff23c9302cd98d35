"""A chunk of a basin sweep integrated as one ODE ("joint" batching).

`jax.vmap(diffeqsolve)` runs the members of a batch in lockstep anyway (the loop runs until the
slowest member is done), and pays for every member's own step-size controller, event and
book-keeping at every step. Here the chunk is one ODE system instead: the state is (dof, B), one
step size is shared, and the error norm is the *largest* of the members' own RMS norms, so
every member meets the tolerance it would meet alone (its steps are never longer than it would
take by itself). Each member keeps its own time axis through a piecewise-linear time map of the
common pseudo-time s in [0, 2]:

    t = s · t_off               for s <= 1   (the half-sine is on, t_off = 1 / (2 f))
    t = t_off + (s - 1) · T     for s > 1    (free settling for T = `settle_time`)

so every member ends exactly at its own t1 = t_off + T, and the switch-off of every member's load
is at s = 1, the one jump declared to the step-size controller.

A member that leaves the box |x - centre| <= bound · span is frozen there (its derivative is set
to zero) and reported `diverged`; it cannot drag the shared step size down to nothing.
"""

import diffrax as dfx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .._solution import RESULTS


def max_member_rms(y) -> Float[Array, ""]:
    """Error norm of a joint chunk: the largest per-member RMS over that member's (x, v)
    components (leaves shaped (dof, B)); NaN counts as infinitely large (step rejected)."""
    x, v = y
    per = jnp.sqrt((jnp.sum(x**2, axis=0) + jnp.sum(v**2, axis=0)) / (x.shape[0] + v.shape[0]))
    return jnp.max(jnp.where(jnp.isnan(per), jnp.inf, per))


def _inside(x, v, centre, span, bound):
    far = jnp.abs(x - centre) > bound * span
    return ~jnp.any(far) & jnp.all(jnp.isfinite(x)) & jnp.all(jnp.isfinite(v))


def joint_final_states(model, settings, x0, fs, amps, centre, span):
    """Final states of B half-sine actuations (fs[k], amps[k]) integrated as one ODE.

    **Returns:** `x1`, `v1` (B, dof), `code` (B,) RESULTS values (`successful`, `diverged`, or
    `simulation_failed` for every member when the joint solve failed), `steps` (the joint
    solve's accepted steps) and `ok` (whether the joint solve succeeded).
    """
    d, b = x0.shape[0], fs.shape[0]
    t_off = 0.5 / fs
    settle = settings.settle_time

    cols = (1, 1, None, 1) if settings.load == "tip" else (1, 1, 0, None)
    accelerations = jax.vmap(model.accelerations, in_axes=cols, out_axes=1)
    lo, hi = (centre - settings.bound * span)[:, None], (centre + settings.bound * span)[:, None]

    def field(s, y, args):
        # loads built for the whole chunk at once (no per-member scatter): measured 1.35x
        x, v = y
        on = s <= 1.0
        rate = jnp.where(on, t_off, settle)
        t = jnp.where(on, s * t_off, t_off + (s - 1.0) * settle)
        pulse = jnp.where(on, amps * jnp.sin(2 * jnp.pi * fs * t), 0.0)
        if settings.load == "tip":
            acc = accelerations(x, v, jnp.zeros(()), jnp.concatenate([jnp.zeros((d - 1, b)), pulse[None]]))
        else:
            acc = accelerations(x, v, pulse, jnp.zeros(d))
        # a member outside the box is frozen (NaN compares False: frozen too)
        alive = jnp.all((x >= lo) & (x <= hi), axis=0)
        rate = jnp.where(alive, rate, 0.0)
        return rate * v, rate * jnp.where(alive, acc, 0.0)

    ctrl = dfx.ClipStepSizeController(
        dfx.PIDController(rtol=settings.rtol, atol=settings.atol, norm=max_member_rms),
        jump_ts=jnp.ones(1),
    )
    y0 = (jnp.broadcast_to(x0[:, None], (d, b)), jnp.zeros((d, b)))
    sol = dfx.diffeqsolve(
        dfx.ODETerm(field), dfx.Tsit5(), 0.0, 2.0, None, y0, saveat=dfx.SaveAt(t1=True),
        stepsize_controller=ctrl, max_steps=settings.max_steps, throw=False,
    )
    x1, v1 = sol.ys[0][-1].T, sol.ys[1][-1].T
    ok = sol.result == dfx.RESULTS.successful
    alive = jax.vmap(lambda x, v: _inside(x, v, centre, span, settings.bound))(x1, v1)
    code = jnp.where(ok, jnp.where(alive, RESULTS.successful._value, RESULTS.diverged._value),
                     RESULTS.simulation_failed._value)
    steps: Int[Array, ""] = sol.stats["num_steps"]
    return x1, v1, code, steps, ok
