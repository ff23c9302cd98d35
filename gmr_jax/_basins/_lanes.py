"""A sweep's points integrated in lanes ("lanes" batching): per-point step control inside one
vectorised loop.

`B` lanes advance together, one Runge-Kutta step attempt per iteration, every stage evaluated for
all lanes at once (state shaped (dof, B): the lanes on the fast axis, no gather in the stages),
but each lane keeps its own time, step size, error norm and accept/reject decision, exactly as
a scalar solver would: a point's step count is its own, not its hardest neighbour's (the cost
of "joint" batching, where a chunk shares one step size, and of `vmap(diffeqsolve)`, whose
members wait in lockstep for the slowest). A lane whose point is done (reached its t1, left the
divergence box, or ran out of steps) writes its final state and takes the next point of the
queue, so lanes stay busy until the queue is empty; the only idle work is the tail of the last
points.

Each point is the Eq. (25) half-sine actuation of `basin_map`: load on for t <= t_off = 1/(2f),
then free until t1 = t_off + settle_time. A step never crosses t_off (it is clipped to land on
it, the scalar solver's stop-and-restart at a declared jump), and the step proposed before the
clip is kept for the step after it.

Pair and controller: an explicit embedded Runge-Kutta pair taken from diffrax's Butcher tableaus
("tsit5" default, "dopri5", "dopri8"; first-same-as-last where the pair has it), error as the
RMS over the lane's (x, v) components of err / (atol + rtol max(|y|, |y_new|)), integral
controller h_new = h · clip(0.9 · err^(-1/q), 0.2, 10) (q = order + 1; at most 0.9 after a
rejection): diffrax's `PIDController` defaults with `pcoeff = 0, icoeff = 1`.

Result per point: `successful`; `diverged` (some x left the box: stopped there); `max_steps_reached`
(the point used `Integrator.max_steps` step attempts); `simulation_failed` (the step size
collapsed below the floating-point resolution of t, or the state went non-finite inside the box).
"""

import math

import diffrax as dfx
import jax
import jax.numpy as jnp
import numpy as np
from .._fit._library import signed_power
from .._model._model import GlobalModel
from .._solution import RESULTS
from .._topology import Chain, Independent

SOLVERS = {"tsit5": dfx.Tsit5, "dopri5": dfx.Dopri5, "dopri8": dfx.Dopri8}
_ORDER = {"tsit5": 5, "dopri5": 5, "dopri8": 8}  # error exponent q: local error ~ h^q
SAFETY, FACTOR_MIN, FACTOR_MAX = 0.9, 0.2, 10.0
_EXPLICIT = True


def _tableau(solver: str):
    """(c, a rows, b_sol, b_error, fsal) as Python floats (weak types: float32 runs stay float32)."""
    t = SOLVERS[solver].tableau
    c = [0.0] + [float(v) for v in np.asarray(t.c)]
    a = [[float(v) for v in np.asarray(row)] for row in t.a_lower]
    return c, a, [float(v) for v in np.asarray(t.b_sol)], [float(v) for v in np.asarray(t.b_error)], bool(t.fsal)


def _combine(y, h, coeffs, ks):
    """y + h · sum_j coeffs[j] ks[j] (zero coefficients skipped)."""
    acc = None
    for cj, kj in zip(coeffs, ks):
        if cj != 0.0:
            acc = cj * kj if acc is None else acc + cj * kj
    return y if acc is None else y + h[None] * acc


_COS_TAYLOR = [(-1) ** n / math.factorial(2 * n) for n in range(11, -1, -1)]  # highest power first


def _half_period_sin(theta):
    """sin(theta) for theta in [0, pi] (clipped there): cos(theta - pi/2) as its Taylor series to
    degree 22, an even polynomial in (theta - pi/2)^2 with |error| < 4e-16 on the whole range.
    No range reduction, one chain of multiply-adds that XLA vectorises over the lanes; XLA's
    general `sin` cost as much as the rest of a 3-cell field (measured: 31 vs 16 ns per lane and
    evaluation)."""
    u = jnp.clip(theta, 0.0, jnp.pi) - jnp.pi / 2
    u2 = u * u
    out = _COS_TAYLOR[0]
    for coef in _COS_TAYLOR[1:]:
        out = out * u2 + coef
    return out


def _batched_force(model, x, v):
    """F(x, v) of a `GlobalModel` for states shaped (dof, lanes), lanes on the fast axis (the
    model's own `force` vmapped puts them on the slow one and transposes at every stage)."""
    def horner(coef, z):
        out = jnp.zeros_like(z)
        for k in range(coef.shape[1] - 1, -1, -1):
            out = out * z + coef[:, k, None]
        return out

    out = horner(model.stiffness, x) + horner(model.position_damping, x) * v
    for j in range(model.velocity_damping.shape[1]):
        out = out + model.velocity_damping[:, j, None] * signed_power(v, j, model.sign_eps)
    return out


def _batched_accelerations(model, force, x, v, base_acc, tip_force):
    """Relative accelerations (dof, lanes) of a chain or independent model (`_topology`)."""
    f = force
    if isinstance(model.topology, Chain):
        f_next = jnp.concatenate([f[1:], jnp.zeros_like(f[:1])])
        load = jnp.zeros_like(f).at[-1].set(tip_force)
        a = (load - f + f_next) / model.masses[:, None]
        a_prev = jnp.concatenate([jnp.broadcast_to(base_acc, f[:1].shape), a[:-1]])
        return a - a_prev
    load = jnp.zeros_like(f).at[-1].set(tip_force)
    return (load - f) / model.masses[:, None] - base_acc[None]


def lane_field(model, load: str, d: int, dtype):
    """`field(t, x, v, f, amp, t_off) -> (2 dof, lanes)` of the Eq. (25) half-sine for states
    shaped (dof, lanes): explicit for a `GlobalModel` on a chain or independent DOFs (lanes on
    the fast axis throughout), the model's own `accelerations` vmapped otherwise."""
    explicit = _EXPLICIT and isinstance(model, GlobalModel) and isinstance(model.topology, (Chain, Independent))
    cols = (1, 1, None, 1) if load == "tip" else (1, 1, 0, None)
    vmapped = jax.vmap(model.accelerations, in_axes=cols, out_axes=1)

    def field(t, x, v, f, amp, t_off):
        # the load is on only for t <= t_off = 1/(2f), where its phase 2 pi f t is in [0, pi]
        pulse = jnp.where(t <= t_off, amp * _half_period_sin(2 * jnp.pi * f * t), 0.0)
        zero = jnp.zeros_like(pulse)
        if explicit:
            force = _batched_force(model, x, v)
            acc = (_batched_accelerations(model, force, x, v, zero, pulse) if load == "tip"
                   else _batched_accelerations(model, force, x, v, pulse, zero))
        elif load == "tip":
            acc = vmapped(x, v, jnp.zeros((), dtype), jnp.concatenate([jnp.zeros((d - 1, pulse.shape[0]), dtype),
                                                                        pulse[None]]))
        else:
            acc = vmapped(x, v, pulse, jnp.zeros(d, dtype))
        return jnp.concatenate([v, acc])

    return field


def lanes_final_states(model, settings, x0, fs, amps, centre, span, lanes: int, solver: str = "tsit5",
                       unroll: int = 4):
    """Final states of N half-sine actuations (fs[k], amps[k]), `lanes` at a time, each point with
    its own step-size control (module docstring).

    **Returns:** `x1`, `v1` (N, dof), `code` (N,) RESULTS values and `steps` (N,) step attempts
    (accepted and rejected) of each point.
    """
    n, d = fs.shape[0], x0.shape[0]
    b = int(min(lanes, n))
    dtype = x0.dtype
    c, a, b_sol, b_err, fsal = _tableau(solver)
    stages = len(c)
    q = _ORDER[solver]
    rtol = jnp.asarray(settings.integrator.rtol).astype(dtype)
    atol = jnp.asarray(settings.integrator.atol).astype(dtype)
    settle = jnp.asarray(settings.settle_time).astype(dtype)
    max_steps = settings.integrator.max_steps
    box = jnp.asarray(settings.box_spans).astype(dtype)
    lo, hi = (centre - box * span)[:, None], (centre + box * span)[:, None]
    ok_, div_, maxs_, fail_ = (RESULTS.successful._value, RESULTS.diverged._value,
                               RESULTS.max_steps_reached._value, RESULTS.simulation_failed._value)

    field = lane_field(model, settings.load, d, dtype)
    y_start = jnp.concatenate([x0, jnp.zeros_like(x0)])[:, None]  # (2 dof, 1)
    # every point starts at rest in x0 with its load at sin(0) = 0: one derivative serves them all
    k_start = field(jnp.zeros(1, dtype), y_start[:d], y_start[d:], jnp.ones(1, dtype), jnp.zeros(1, dtype),
                    jnp.ones(1, dtype))

    def point(idx):
        f = fs[jnp.clip(idx, 0, n - 1)]
        t_off = 0.5 / f
        h0 = settings.integrator.dt0
        h0 = 1e-2 * jnp.minimum(t_off, 1.0) if h0 is None else jnp.full_like(f, h0)
        return f, amps[jnp.clip(idx, 0, n - 1)], t_off, t_off + settle, h0

    idx0 = jnp.arange(b)
    f0, a0, toff0, t10, h00 = point(idx0)
    out0 = (jnp.zeros((n, d), dtype), jnp.zeros((n, d), dtype), jnp.full((n,), fail_, jnp.int32),
            jnp.zeros((n,), jnp.int32))
    lane0 = dict(idx=idx0, y=jnp.broadcast_to(y_start, (2 * d, b)), k=jnp.broadcast_to(k_start, (2 * d, b)),
                 t=jnp.zeros(b, dtype), h=h00, steps=jnp.zeros(b, jnp.int32), f=f0, amp=a0, t_off=toff0, t1=t10,
                 fin=jnp.zeros(b, bool), code=jnp.full((b,), fail_, jnp.int32))
    state0 = (lane0, jnp.asarray(b), out0)

    def cond(state):
        return jnp.any(state[0]["idx"] >= 0)

    def attempt(lane):
        """One step attempt of every running lane (finished ones are frozen)."""
        t, y, h_prop, k1 = lane["t"], lane["y"], lane["h"], lane["k"]
        active = (lane["idx"] >= 0) & ~lane["fin"]
        # the step: up to the lane's next stop (its switch-off time, then its t1)
        stop = jnp.where(t < lane["t_off"], lane["t_off"], lane["t1"])
        clipped = t + h_prop >= stop
        h = jnp.where(clipped, stop - t, h_prop)
        args = (lane["f"], lane["amp"], lane["t_off"])
        ks = [k1]
        for i in range(1, stages):
            yi = _combine(y, h, a[i - 1], ks)
            # a stage at the stop itself belongs to the piece before it (the load's own value there)
            ti = jnp.where(clipped, stop, t + h) if c[i] == 1.0 else t + c[i] * h
            ks.append(field(ti, yi[:d], yi[d:], *args))
        y_new = _combine(y, h, b_sol, ks)
        err = h[None] * sum(ej * kj for ej, kj in zip(b_err, ks) if ej != 0.0)
        scale = atol + rtol * jnp.maximum(jnp.abs(y), jnp.abs(y_new))
        norm = jnp.sqrt(jnp.mean((err / scale) ** 2, axis=0))
        norm = jnp.where(jnp.isfinite(norm), norm, jnp.inf)
        accept = active & (norm <= 1.0)
        factor = jnp.where(norm == 0.0, FACTOR_MAX, SAFETY * norm ** (-1.0 / q))
        factor = jnp.clip(factor, FACTOR_MIN, jnp.where(accept, FACTOR_MAX, SAFETY))
        # a step cut short by a stop does not shrink the next one
        h_next = jnp.where(accept & clipped, jnp.maximum(h * factor, h_prop), h * factor)
        k_new = ks[-1] if fsal else field(t + h, y_new[:d], y_new[d:], *args)
        t_new = jnp.where(accept, jnp.where(clipped, stop, t + h), t)
        y = jnp.where(accept[None], y_new, y)
        k = jnp.where(accept[None], k_new, k1)
        steps = lane["steps"] + active.astype(jnp.int32)
        x = y[:d]
        left = jnp.any((x < lo) | (x > hi), axis=0)
        bad = ~jnp.all(jnp.isfinite(y), axis=0) | (t + h_next <= t)
        reached = t_new >= lane["t1"]
        code = jnp.where(left, div_, jnp.where(bad, fail_, jnp.where(reached, ok_, maxs_)))
        done = active & (left | bad | reached | (steps >= max_steps))
        keep = lambda new, old: jnp.where(active, new, old)  # noqa: E731
        return dict(lane, y=y, k=k, t=keep(t_new, t), h=keep(h_next, h_prop), steps=steps,
                    fin=lane["fin"] | done, code=jnp.where(done, code.astype(jnp.int32), lane["code"]))

    def body(state):
        lane, nxt, out = state
        for _ in range(unroll):  # several attempts per pass: the book-keeping below is paid once
            lane = attempt(lane)
        fin = lane["fin"]
        # finished points write their answer (other lanes write nowhere: index n is dropped)
        where = jnp.where(fin, lane["idx"], n)
        y = lane["y"]
        out = (out[0].at[where].set(y[:d].T, mode="drop"), out[1].at[where].set(y[d:].T, mode="drop"),
               out[2].at[where].set(lane["code"], mode="drop"), out[3].at[where].set(lane["steps"], mode="drop"))
        # free lanes take the next points of the queue
        free = fin | (lane["idx"] < 0)
        rank = jnp.cumsum(free) - 1
        new = nxt + rank
        take = free & (new < n)
        idx = jnp.where(take, new, jnp.where(free, -1, lane["idx"]))
        nf, na, ntoff, nt1, nh = point(new)
        sel = lambda fresh, old: jnp.where(take, fresh, old)  # noqa: E731
        lane = dict(idx=idx, y=jnp.where(take[None], y_start, y), k=jnp.where(take[None], k_start, lane["k"]),
                    t=sel(jnp.zeros_like(lane["t"]), lane["t"]), h=sel(nh, lane["h"]),
                    steps=sel(jnp.zeros_like(lane["steps"]), lane["steps"]), f=sel(nf, lane["f"]),
                    amp=sel(na, lane["amp"]), t_off=sel(ntoff, lane["t_off"]), t1=sel(nt1, lane["t1"]),
                    fin=jnp.zeros_like(fin), code=lane["code"])
        return lane, nxt + jnp.sum(take), out

    _, _, (x1, v1, code, steps) = jax.lax.while_loop(cond, body, state0)
    return x1, v1, code, steps

