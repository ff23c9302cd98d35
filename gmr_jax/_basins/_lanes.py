"""A sweep's points integrated in lanes ("lanes" batching, the default): a queue of points
driven through diffrax's own solver and step-size controller, per-point step control inside
one loop.

`B` lanes advance together. At every attempt each lane takes one step of the diffrax solver
(`solver.step`, e.g. `diffrax.Tsit5()`) from its own t0 to its own t1 and asks diffrax's
`PIDController.adapt_step_size` whether to keep it and what to try next, so each lane keeps its
own time, step size, controller state, solver state (first-same-as-last) and accept/reject
decision, exactly as one `diffeqsolve` of that point would: a point's step count is its own,
not its hardest neighbour's (the cost of `vmap(diffeqsolve)`, whose members wait in lockstep
for the slowest). The lanes sit on the last axis of every array: an explicit Runge-Kutta step
is elementwise in the lanes, so it runs once on the lane-batched state (its stages' buffers
with the lanes on the fast axis; measured 3x cheaper than `vmap` of the one-point step at 10
cells), the controller's RMS norm is taken per lane, and any other solver (an implicit one
solves a nonlinear system per step) is `vmap`ped lane by lane. A lane whose point is done
(reached its t1, left the divergence box, ran out of steps or failed) writes its final state
and takes the next point of the queue, so lanes stay busy until the queue is empty; the only
idle work is the tail of the last points.

Each point is the Eq. (25) half-sine actuation of `basin_map`: load on for t <= t_off = 1/(2f),
then free until t1 = t_off + settle_time. A step never crosses t_off: the scheduler clips it to
land there (as diffrax's `ClipStepSizeController(jump_ts=...)` does); the half-sine is
continuous there (sin(pi) = 0), so a first-same-as-last value stays valid across it, and the
step proposed before the clip is kept for the step after it. A point starts at rest with the
load at sin(0) = 0, so its first-same-as-last value f(0, y0) is its model's: a fresh lane enters
with it (the solver state diffrax leaves after any step), and the lanes never re-evaluate a first
stage because one of them is new.

With several models (`basin_probability`'s drawn models) every point also names its model:
the lanes carry their point's coefficients, divergence box and start, so one compiled loop
sweeps models x grid points.

Result per point: `successful`; `diverged` (some x left the box: stopped there);
`max_steps_reached` (the point used `Integrator.max_steps` step attempts); `simulation_failed`
(the step size collapsed below the floating-point resolution of t, or the state went non-finite
inside the box); a diffrax code the solver or controller returned (e.g. an implicit solver's
`nonlinear_divergence`), promoted to `RESULTS`.
"""

import dataclasses
import math

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._model._model import GlobalModel
from .._solution import RESULTS
from .._topology import Chain, Independent

# the explicit pairs the native kernel also runs (its tableaus are diffrax's)
SOLVERS = {"tsit5": dfx.Tsit5, "dopri5": dfx.Dopri5, "dopri8": dfx.Dopri8}
_ORDER = {"tsit5": 5, "dopri5": 5, "dopri8": 8}  # error exponent q: local error ~ h^q
SAFETY, FACTOR_MIN, FACTOR_MAX = 0.9, 0.2, 10.0


def as_solver(solver) -> dfx.AbstractSolver:
    """A diffrax solver from itself or its name ("tsit5", "dopri5", "dopri8")."""
    return SOLVERS[solver]() if isinstance(solver, str) else solver


def solver_name(solver) -> str | None:
    """The name of an explicit pair the native kernel runs ("tsit5", ...), None for other solvers."""
    if isinstance(solver, str):
        return solver
    for name, cls in SOLVERS.items():
        if type(solver) is cls:
            return name
    return None


def _tableau(solver: str):
    """(c, a rows, b_sol, b_error, fsal) as Python floats, for the native kernel's generator."""
    t = SOLVERS[solver].tableau
    c = [0.0] + [float(v) for v in np.asarray(t.c)]
    a = [[float(v) for v in np.asarray(row)] for row in t.a_lower]
    return c, a, [float(v) for v in np.asarray(t.b_sol)], [float(v) for v in np.asarray(t.b_error)], bool(t.fsal)


_COS_TAYLOR = [(-1) ** n / math.factorial(2 * n) for n in range(11, -1, -1)]  # highest power first


def _half_period_sin(theta):
    """sin(theta) for theta in [0, pi] (clipped there): cos(theta - pi/2) as its Taylor series to
    degree 22, an even polynomial in (theta - pi/2)^2 with |error| < 4e-16 on the whole range.
    No range reduction: one chain of multiply-adds that vectorises over the lanes (XLA's general
    `sin` cost as much as the rest of a 3-cell field)."""
    u = jnp.clip(theta, 0.0, jnp.pi) - jnp.pi / 2
    u2 = u * u
    out = _COS_TAYLOR[0]
    for coef in _COS_TAYLOR[1:]:
        out = out * u2 + coef
    return out


def _pulse(t, f, amp, t_off):
    """The Eq. (25) half-sine A sin(2 pi f t) for t <= t_off = 1/(2f), then 0."""
    return jnp.where(t <= t_off, amp * _half_period_sin(2 * jnp.pi * f * t), 0.0)


def node_of(load: str) -> int | None:
    """K of a load "node:K" (a force on mass K, K a whole number); None for any other string."""
    head, _, k = load.partition(":")
    return int(k) if head == "node" and k.isdigit() else None


def load_node(load: str, d: int) -> int | None:
    """The mass (node) a half-sine force acts on: "tip" the last, "node:K" mass K; None for "base"."""
    return d - 1 if load == "tip" else node_of(load)


def half_sine_field(load: str, d: int):
    """`field(t, y, args)` of the Eq. (25) half-sine for one point: y = (x, v) (dof,), args =
    (model, f, amp, t_off)."""
    node = load_node(load, d)

    def field(t, y, args):
        model, f, amp, t_off = args
        x, v = y
        pulse = _pulse(t, f, amp, t_off)
        zero = jnp.zeros_like(pulse)
        if node is not None:
            acc = model.accelerations(x, v, zero, jnp.zeros(d, x.dtype).at[node].set(pulse))
        else:
            acc = model.accelerations(x, v, pulse, jnp.zeros(d, x.dtype))
        return v, acc

    return field


def explicit_field(model) -> bool:
    """Whether the lanes field is written out for this model (a `GlobalModel` on a chain or
    independent DOFs) rather than the model's own `accelerations` vmapped."""
    return isinstance(model, GlobalModel) and isinstance(model.topology, (Chain, Independent))


def lanes_field(model, load: str, d: int, per_lane: bool):
    """`field(t, y, args)` of the half-sine for lanes on the last axis: t (B,), y = (x, v) each
    (dof, B), args = (model, f, amp, t_off), the model's arrays with a trailing lane axis when
    `per_lane` (each lane its own model). Element for element the one-point field
    (`half_sine_field`) of each lane."""
    one = half_sine_field(load, d)
    if not explicit_field(model):
        model_axes = -1 if per_lane else None
        return lambda t, y, args: jax.vmap(one, in_axes=(-1, -1, (model_axes, -1, -1, -1)), out_axes=-1)(
            jnp.broadcast_to(t, args[1].shape), y, args)
    chain = isinstance(model.topology, Chain)
    # the chain's carried forces as constant matrices on the DOF axis: (D F)_i = F_{i+1} - F_i and
    # (S a)_i = a_i - a_{i-1}; a product materialises F once (shifted copies made XLA evaluate the
    # polynomials once per neighbour)
    eye = np.eye(d)
    carry = jnp.asarray(np.eye(d, k=1) - eye)
    relative = jnp.asarray(eye - np.eye(d, k=-1))
    node = load_node(load, d)
    loaded = d - 1 if node is None else node
    tip_row = jnp.asarray(np.eye(d)[:, loaded:loaded + 1])  # (dof, 1): the loaded mass
    base_row = jnp.asarray(np.eye(d)[:, :1]) if chain else jnp.ones((d, 1))
    load_rel = relative @ tip_row  # S e_K: the loaded mass's acceleration in the relative coordinates

    def horner(coef, z):
        """sum_k coef[:, k] z^k, highest power first (one multiply-add per order)."""
        out = coef[:, -1] + jnp.zeros_like(z)
        for k in range(coef.shape[1] - 2, -1, -1):
            out = out * z + coef[:, k]
        return out

    def field(t, y, args):
        m, f, amp, t_off = args
        x, v = y
        lane = (lambda a: a) if per_lane else (lambda a: a[..., None])
        K, B, C, masses = (lane(a) for a in (m.stiffness, m.velocity_damping, m.position_damping, m.masses))
        dtype = x.dtype
        force = horner(K, x) + horner(C, x) * v
        if B.shape[1]:
            # sum_j B_j sgn(v)|v|^j = sgn(v) sum_j B_j |v|^j (sgn smoothed to tanh(v / eps) when eps > 0)
            s = jnp.sign(v) if m.sign_eps == 0.0 else jnp.tanh(v / m.sign_eps)
            force = force + s * horner(B, jnp.abs(v))
        pulse = _pulse(t, f, amp, t_off)
        tip, base = (pulse, 0.0) if node is not None else (0.0, pulse)
        precision = jax.lax.Precision.HIGHEST
        if chain and per_lane:
            # m_i a_i = force_i - F_i + F_{i+1}; x_i'' = a_i - a_{i-1} (a_{-1}: the base); a is two
            # operations on a product, cheap to evaluate for each neighbour
            a = (jnp.matmul(carry.astype(dtype), force, precision=precision) + tip_row.astype(dtype) * tip) / masses
            acc = a - jnp.concatenate([jnp.zeros_like(a[:1]) + base, a[:-1]])
        elif chain:
            # the same with the masses shared by the lanes: one matrix S diag(1/m) D (S e_last = e_last)
            inv = 1.0 / m.masses
            acc = (jnp.matmul(relative.astype(dtype) @ (inv[:, None] * carry.astype(dtype)), force, precision=precision)
                   + load_rel.astype(dtype) * (inv[loaded] * tip) - base_row.astype(dtype) * base)
        else:
            acc = (tip_row.astype(dtype) * tip - force) / masses - base_row.astype(dtype) * base
        return v, acc

    return field


def _stacked(field, d: int):
    """`field` on the state (x; v) as one array (2 dof, ...) instead of the pair (x, v)."""
    return lambda t, y, args: jnp.concatenate(field(t, (y[:d], y[d:]), args))


def _lane_rms(tree):
    """RMS over the components of each lane (leaves shaped (..., B)): (B,)."""
    leaves = jax.tree.leaves(tree)
    total = sum(jnp.sum(jnp.reshape(leaf, (-1, leaf.shape[-1])) ** 2, axis=0) for leaf in leaves)
    return jnp.sqrt(total / sum(leaf.size // leaf.shape[-1] for leaf in leaves))


def _promote(result):
    return RESULTS.promote(result)._value


def lanes_final_states(*args, **kwargs):
    """Final states of N half-sine actuations in lanes (`_lanes_final_states`); per-lane scalars
    (B,) broadcast against states (dof, B) on purpose, diffrax's own `dt * k` included."""
    with jax.numpy_rank_promotion("allow"):
        return _lanes_final_states(*args, **kwargs)


def _lanes_final_states(models, settings, solver, x0s, fs, amps, mids, lo, hi, lanes: int, unroll: int = 4):
    """Final states of N half-sine actuations (fs[k], amps[k]) of models[mids[k]], `lanes` at a
    time, each point with its own diffrax step-size control (module docstring).

    **Arguments:** `models`: one model (`mids` None), or models stacked on a leading axis;
    `solver`: a diffrax solver; `x0s`, `lo`, `hi` (M, dof): per model its start and divergence
    box; `fs`, `amps`, `mids` (N,).

    **Returns:** `x1`, `v1` (N, dof), `code` (N,) RESULTS values and `steps` (N,) step attempts
    (accepted and rejected) of each point.
    """
    n, d = fs.shape[0], x0s.shape[1]
    b = int(min(lanes, n))
    dtype = x0s.dtype
    ensemble = mids is not None
    rtol = jnp.asarray(settings.integrator.rtol).astype(dtype)
    atol = jnp.asarray(settings.integrator.atol).astype(dtype)
    settle = jnp.asarray(settings.settle_time).astype(dtype)
    max_steps = settings.integrator.max_steps
    ok_, div_, maxs_, fail_ = (RESULTS.successful._value, RESULTS.diverged._value,
                               RESULTS.max_steps_reached._value, RESULTS.simulation_failed._value)
    # diffrax's controller with its RMS norm taken per lane (over the lane's own components, axis
    # 0): every quantity it computes is then elementwise in the lanes, each lane its own decision
    controller = dfx.PIDController(rtol=rtol, atol=atol, norm=_lane_rms)
    # an explicit Runge-Kutta step is elementwise in the lanes: it runs once on the lane-batched
    # state (each lane its own t0, t1), the stages' buffers with the lanes on the fast axis; any
    # other solver (an implicit one solves a nonlinear system per step) is vmapped lane by lane
    batched_step = isinstance(solver, dfx.AbstractERK)
    per_lane = ensemble
    # the state of a lane is one array (x; v) (2 dof, B): each stage's combination, the error
    # estimate and the controller's norm are one array operation, not one per component
    bterm = dfx.ODETerm(_stacked(lanes_field(models, settings.load, d, per_lane), d))
    term1 = dfx.ODETerm(_stacked(half_sine_field(settings.load, d), d))
    error_order = solver.error_order(bterm)
    if isinstance(solver, dfx.AbstractRungeKutta) and solver.scan_kind is None:
        # the stages in a plain loop (the same arithmetic): forward-mode derivatives pass through it
        solver = dataclasses.replace(solver, scan_kind="lax")
    if isinstance(solver, dfx.AbstractImplicitSolver):
        # as `diffeqsolve` does: a root finder's tolerances left to the step-size controller take its own
        from diffrax._root_finder import use_stepsize_tol

        attrs = [a for a in ("rtol", "atol", "norm") if getattr(solver.root_finder, a) is use_stepsize_tol]
        # (the norm: the plain RMS of the one lane the vmapped step sees)
        own = {"rtol": controller.rtol, "atol": controller.atol, "norm": optx.rms_norm}
        solver = eqx.tree_at(lambda s: tuple(getattr(s.root_finder, a) for a in attrs), solver,
                             tuple(own[a] for a in attrs))
    last = lambda a: jnp.moveaxis(a, 0, -1)  # noqa: E731
    # every per-lane quantity has the lanes on its last axis; models stacked on the last axis too
    models_l = jax.tree.map(last, models) if ensemble else models
    mids = jnp.zeros(n, jnp.int32) if mids is None else mids
    m_count = x0s.shape[0]
    x0_l, lo_l, hi_l = last(x0s), last(lo), last(hi)  # (dof, M)
    lane_axes = -1 if per_lane else None

    def step(t0, t1, y, args, ss):
        if batched_step:
            return solver.step(bterm, t0, t1, y, args, ss, False)
        return jax.vmap(lambda t0, t1, y, args, ss: solver.step(term1, t0, t1, y, args, ss, False),
                        in_axes=(-1, -1, -1, (lane_axes, -1, -1, -1), -1), out_axes=-1)(t0, t1, y, args, ss)

    def init(t0, t1, y, args):
        if batched_step:
            return solver.init(bterm, t0, t1, y, args)
        return jax.vmap(lambda t0, t1, y, args: solver.init(term1, t0, t1, y, args),
                        in_axes=(-1, -1, -1, (lane_axes, -1, -1, -1)), out_axes=-1)(t0, t1, y, args)

    def adapt(t0, t1, y0, y1, y_err, cs):
        return controller.adapt_step_size(t0, t1, y0, y1, None, y_err, error_order, cs)

    # every point starts at rest in its model's x0 with its load at sin(0) = 0: the solver's and the
    # controller's first states depend on the model only (one per model, gathered into the lanes)
    ones, zeros = jnp.ones(m_count, dtype), jnp.zeros(m_count, dtype)
    y_m = jnp.concatenate([x0_l, jnp.zeros_like(x0_l)])
    start_args = ((models_l if ensemble else models), ones, zeros, ones)
    ss_m = init(zeros, ones, y_m, start_args)
    # a first-same-as-last pair's state (first-step flag, f at the step's start): a fresh point's
    # f(0, x0) is its model's (at rest, load sin(0) = 0), so every lane enters with the flag down
    # (the state diffrax leaves after any step) and no attempt re-evaluates the first stage for all
    fsal = batched_step and isinstance(ss_m, tuple) and len(ss_m) == 2 and jnp.ndim(ss_m[0]) == 0
    if fsal:
        ss_m = bterm.vf(zeros, y_m, start_args)
    cs_m = controller.init(bterm, zeros, ones, y_m, ones, None, None, error_order)[1]

    def gather(tree, m):
        # a scalar of the solver's state (a first-same-as-last solver's "first step" flag) is per lane
        return jax.tree.map(lambda a: a[..., m] if jnp.ndim(a) else jnp.broadcast_to(a, m.shape), tree)

    def fresh(idx):
        """Per-lane start of the points `idx` (clipped into range)."""
        k = jnp.clip(idx, 0, n - 1)
        f, m = fs[k], mids[k]
        t_off = 0.5 / f
        h0 = settings.integrator.dt0
        h0 = 1e-2 * jnp.minimum(t_off, 1.0) if h0 is None else jnp.full_like(f, h0)
        x = x0_l[:, m]
        lane = dict(idx=idx, y=jnp.concatenate([x, jnp.zeros_like(x)]), ss=gather(ss_m, m), cs=gather(cs_m, m), t=jnp.zeros_like(f),
                    h=h0, steps=jnp.zeros(idx.shape, jnp.int32), f=f, amp=amps[k], t_off=t_off, t1=t_off + settle,
                    lo=lo_l[:, m], hi=hi_l[:, m], fin=jnp.zeros(idx.shape, bool),
                    code=jnp.full(idx.shape, fail_, jnp.int32))
        if ensemble:
            lane["model"] = gather(models_l, m)
        return lane

    def attempt(ln):
        """One step attempt of every running lane (finished ones are frozen)."""
        t, h_prop = ln["t"], ln["h"]
        active = (ln["idx"] >= 0) & ~ln["fin"]
        # the step: up to the lane's next stop (its switch-off time, then its t1); the half-sine is
        # continuous at t_off (sin(pi) = 0), so a first-same-as-last value stays valid across it
        stop = jnp.where(t < ln["t_off"], ln["t_off"], ln["t1"])
        clipped = t + h_prop >= stop
        t_next = jnp.where(clipped, stop, t + h_prop)
        args = (ln["model"] if ensemble else models, ln["f"], ln["amp"], ln["t_off"])
        y1, y_err, _, ss1, s_res = step(t, t_next, ln["y"], args, (False, ln["ss"]) if fsal else ln["ss"])
        if fsal:
            ss1 = ss1[1]
        y_err = jnp.where(jnp.isnan(y_err), jnp.inf, y_err)
        # (the controller scales the error by y0 alone where y1 is NaN: decided lane by lane)
        y1_scale = jnp.where(jnp.any(jnp.isnan(y1), axis=0), ln["y"], y1)
        keep, nt0, nt1, _, cs1, c_res = adapt(t, t_next, ln["y"], y1_scale, y_err, ln["cs"])
        keep = keep & active
        h_next = nt1 - nt0
        # a step cut short by a stop does not shrink the next one
        h_next = jnp.where(keep & clipped, jnp.maximum(h_next, h_prop), h_next)
        sel = lambda new, old: jax.tree.map(lambda a, o: jnp.where(keep, a, o), new, old)  # noqa: E731
        y = jnp.where(keep, y1, ln["y"])
        t_new = jnp.where(keep, t_next, t)
        steps = ln["steps"] + active.astype(jnp.int32)
        x = y[:d]
        left = jnp.any((x < ln["lo"]) | (x > ln["hi"]), axis=0)
        finite = jnp.all(jnp.isfinite(y), axis=0)
        bad = ~finite | (t_new + h_next <= t_new)
        res = jnp.where(keep, _promote(s_res), ok_)
        res = jnp.where(res == ok_, _promote(c_res), res)
        reached = t_new >= ln["t1"]
        code = jnp.where(left, div_, jnp.where(res != ok_, res, jnp.where(bad, fail_, jnp.where(reached, ok_,
                                                                                                  maxs_))))
        done = active & (left | bad | reached | (res != ok_) | (steps >= max_steps))
        act = lambda new, old: jax.tree.map(lambda a, o: jnp.where(active, a, o), new, old)  # noqa: E731
        return dict(ln, y=y, ss=sel(ss1, ln["ss"]), cs=act(cs1, ln["cs"]), t=t_new, h=act(h_next, h_prop),
                    steps=steps, fin=ln["fin"] | done, code=jnp.where(done, code.astype(jnp.int32), ln["code"]))

    lane0 = fresh(jnp.arange(b))
    out0 = (jnp.zeros((n, d), dtype), jnp.zeros((n, d), dtype), jnp.full((n,), fail_, jnp.int32),
            jnp.zeros((n,), jnp.int32))

    def cond(state):
        return jnp.any(state[0]["idx"] >= 0)

    def body(state):
        lane, nxt, out = state
        for _ in range(unroll):  # several attempts per pass: the book-keeping below is paid once
            lane = attempt(lane)
        fin = lane["fin"]
        # finished points write their answer (other lanes write nowhere: index n is dropped)
        where = jnp.where(fin, lane["idx"], n)
        x, v = lane["y"][:d], lane["y"][d:]
        out = (out[0].at[where].set(x.T, mode="drop"), out[1].at[where].set(v.T, mode="drop"),
               out[2].at[where].set(lane["code"], mode="drop"), out[3].at[where].set(lane["steps"], mode="drop"))
        # free lanes take the next points of the queue
        free = fin | (lane["idx"] < 0)
        new = nxt + jnp.cumsum(free) - 1
        take = free & (new < n)
        lane = jax.tree.map(lambda a, o: jnp.where(take, a, o), fresh(jnp.where(take, new, -1)), lane)
        lane["idx"] = jnp.where(take, new, jnp.where(free, -1, lane["idx"]))
        lane["fin"] = jnp.zeros_like(fin)
        return lane, nxt + jnp.sum(take), out

    _, _, (x1, v1, code, steps) = jax.lax.while_loop(cond, body, (lane0, jnp.asarray(b), out0))
    return x1, v1, code, steps
