"""Deployment-basin sweeps over actuation grids (paper Fig. 11, load of Eq. 25): a queue of
points driven through diffrax's solvers in lanes (`_lanes`) and sharded over all devices, or
opt-in the model's own C kernel (`_native`); every point's result code kept."""

import dataclasses
import functools
from collections.abc import Callable

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh
from jax.sharding import PartitionSpec as P
from jaxtyping import Array, ArrayLike, Float, Int

from .._config import relieve_map_pressure
from .._errors import GMRInputError, check_real, describe, is_tracer
from .._model._model import AbstractMechanicalModel
from .._topology import Graph
from .._simulate._inputs import half_sine
from .._simulate._integrate import Integrator, integrate, vector_field
from .._simulate._simulate import has_coulomb
from .._solution import RESULTS, Solution, as_result, code_name, error_if_failed, raise_if_failed, value_of
from . import _native
from ._joint import joint_final_states
from ._lanes import SOLVERS as LANE_SOLVERS, as_solver, lanes_final_states, node_of

LOADS = ("tip", "base")
BATCHINGS = ("auto", "native", "lanes", "joint", "member")
SOLVERS = tuple(LANE_SOLVERS)
PRECISIONS = {"float64": jnp.float64, "float32": jnp.float32}


class SweepSettings(eqx.Module):
    """How each grid point is simulated and judged.

    - `settle_time`: free time after the actuation ends (t1 = 1/(2f) + settle_time).
    - `integrator`: tolerances (the same for every point; Tsit5 with PID control, the
      switch-off time 1/(2f) declared to the controller) and `max_steps`, the step budget of
      one solve (a chunk in "joint" batching, a point in "member").
    - `x_tol`: a cell is in a well when |x - x_well| < x_tol · (span of that cell's wells).
    - `v_tol`: ... and |v| < v_tol · span · (1 s⁻¹).
    - `box_spans`: divergence box: a point whose x leaves centre ± box_spans · span (centre and
      span of each cell's wells) is stopped there and flagged `diverged`.
    - `load`: "tip" (default, Eq. 25: force A sin(2πft) on the last mass for t <= 1/(2f)),
      "node:K" (the same force on mass K, counted from 0: a node of a `Graph`; "lanes" batching)
      or "base" (the same half-sine as base acceleration, A in m/s²).
    - `batching`: "lanes" (default; "auto" is the same): diffrax's `solver.step` and
      `PIDController` on `chunk` lanes at once inside one loop (`_lanes`), each point with its
      own time, step size, controller state and accept/reject decision, and a lane whose point
      is done takes the next point of the queue (the step count per point is one
      `diffeqsolve`'s; no member waits for the slowest); runs on every device, under `jax.jit`.
      "native" (opt-in, a CPU accelerator): the same queue as a C kernel generated from the
      model and built with the system's C compiler (`_native`: every stage and the step decision
      of 16 points at a time in vector registers, all CPU cores through one shared queue, an
      integral controller of its own; `chunk` and `devices` do not apply). It needs a C compiler
      (`$CC`, cc, gcc or clang), a `GlobalModel` on a chain or independent DOFs, float64, one
      process and an explicit pair (Tsit5, Dopri5, Dopri8); measured 3-5x faster than
      "lanes" on a CPU (`results/basins_diffrax.md`). "joint": each
      chunk integrated as one ODE with one step size and a max-over-members error norm (every
      member meets the tolerance; see `_joint`), a chunk whose joint solve fails re-run member
      by member; "member": `vmap` of one `diffeqsolve` per point (lockstep: a chunk runs as long
      as its slowest member).
    - `solver` ("lanes", "native"): the diffrax solver each point is integrated with, as in
      `diffeqsolve`: `diffrax.Tsit5()` (default), `Dopri5()`, `Dopri8()`, an implicit one such
      as `Kvaerno5()` for a stiff chain (any adaptive diffrax ODE solver under "lanes"; "native"
      runs the explicit pairs Tsit5, Dopri5, Dopri8); the names "tsit5", "dopri5", "dopri8" are
      accepted. "joint" and "member" use the integrator's Tsit5.
    - `attempts_per_pass` ("lanes" only): step attempts per pass of the loop; finished points
      are collected and lanes refilled once per pass (measured on 2 CPU cores: 4 is about 5-10 %
      faster than 1; compile time grows with it).
    - `precision`: "float64" (default) or "float32" (model, states and grid cast to float32: for
      accelerators; at rtol 1e-6 float32 needs about 3.5x the steps, `results/bench_basins_gpu.md`).
    - `sign_eps`: how a `GlobalModel`'s Coulomb friction (`velocity_damping` order 0, sgn(v)) is
      integrated. With the exact sgn(v) an adaptive solver chatters around v = 0 once a cell
      stops, and every point ends `max_steps_reached`. None (default): when the model has such a
      term and its own `sign_eps` is 0, sgn(v) becomes tanh(v / eps) with
      eps = 0.1 · `v_tol` · (smallest span of the wells), so the friction is exact (to 4e-9)
      at every speed above a tenth of the settled-speed test: only motion already counted as
      settled is smoothed (it creeps instead of sticking). The value used is
      `stats["sign_eps"]`. A number: that eps (0.0: the exact sgn).
    """

    settle_time: float = 10.0
    integrator: Integrator = Integrator(rtol=1e-6, atol=1e-8, max_steps=100_000)
    x_tol: float = 0.1
    v_tol: float = 0.05
    box_spans: float = 20.0
    load: str = eqx.field(static=True, default="tip")
    batching: str = eqx.field(static=True, default="lanes")
    solver: dfx.AbstractSolver = dfx.Tsit5()
    attempts_per_pass: int = eqx.field(static=True, default=4)
    precision: str = eqx.field(static=True, default="float64")
    sign_eps: float | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        # plain Python on concrete values; tracers (settings built inside jit) are not inspected
        if not isinstance(self.load, str) or not (self.load in LOADS or node_of(self.load) is not None):
            raise GMRInputError(f"SweepSettings.load must be one of {LOADS} or 'node:K' (a force on mass K, from 0), "
                                f"got {describe(self.load)}")
        if not isinstance(self.batching, str) or self.batching not in BATCHINGS:
            raise GMRInputError(f"SweepSettings.batching must be one of {BATCHINGS}, got {describe(self.batching)}")
        if self.precision not in PRECISIONS:
            raise GMRInputError(f"SweepSettings.precision must be one of {tuple(PRECISIONS)}, got "
                                f"{describe(self.precision)}")
        if not isinstance(self.attempts_per_pass, int) or self.attempts_per_pass < 1:
            raise GMRInputError(f"SweepSettings.attempts_per_pass must be an integer >= 1, got "
                                f"{describe(self.attempts_per_pass)}")
        if isinstance(self.solver, str) and self.solver not in SOLVERS:
            raise GMRInputError(f"SweepSettings.solver must be one of {SOLVERS} or a diffrax solver (e.g. "
                                f"diffrax.Tsit5()), got {describe(self.solver)}")
        if not isinstance(self.solver, (str, dfx.AbstractAdaptiveSolver)):
            raise GMRInputError(f"SweepSettings.solver must be an adaptive diffrax solver with an error estimate "
                                f"(diffrax.Tsit5(), Dopri5(), Dopri8(), Kvaerno5(), ...), got "
                                f"{type(self.solver).__name__}")
        check_real(self.settle_time, "SweepSettings.settle_time", lo=0.0, lo_open=True,
                   fix="give the free time after the actuation in seconds, > 0 (e.g. 10.0)")
        check_real(self.x_tol, "SweepSettings.x_tol", lo=0.0, lo_open=True,
                   fix="give the well tolerance as a fraction of the wells' span, > 0 (e.g. 0.1)")
        check_real(self.v_tol, "SweepSettings.v_tol", lo=0.0, lo_open=True,
                   fix="give the settling velocity tolerance as a fraction of span/s, > 0 (e.g. 0.05)")
        check_real(self.box_spans, "SweepSettings.box_spans", lo=0.5, lo_open=True,
                   fix="the divergence box must contain the wells (they lie within 0.5 span of the "
                       "centre); e.g. 20.0")
        if self.sign_eps is not None:
            check_real(self.sign_eps, "SweepSettings.sign_eps", lo=0.0,
                       fix="give the velocity scale of the tanh that replaces sgn(v), >= 0 (0: the exact sgn), "
                           "or None for the automatic one")
        if not isinstance(self.integrator, Integrator):
            raise GMRInputError(f"SweepSettings.integrator must be a gmr_jax.Integrator, got "
                                f"{type(self.integrator).__name__}")


class BasinMap(eqx.Module):
    """`wells` (NA, NF, cells): index of the well each cell (each element of a `Graph`) ended in
    (ordered by deformation),
    -1 when not settled or failed; `config` (NA, NF): for bistable cells, bit i set = cell i in
    its second well; with K well slots per cell (a tri-stable DOF: K = 3), the sum of cell i's
    well index times K^i (`plots.config_label(config, dof, K)` writes it); -1 as above; `result` (NA, NF) RESULTS codes; `x_final`, `v_final` (NA, NF, dof);
    `steps` (NA, NF): accepted integrator steps of the solve that produced the point (its
    chunk's, under "joint" batching)."""

    f: Float[Array, " nf"]
    A: Float[Array, " na"]
    wells: Int[Array, "na nf dof"]
    config: Int[Array, "na nf"]
    result: Int[Array, "na nf"]
    x_final: Float[Array, "na nf dof"]
    v_final: Float[Array, "na nf dof"]
    steps: Int[Array, "na nf"]

    def counts(self) -> Int[Array, "na nf"]:
        """Per point, the number of cells outside their first well (-1 where not settled): the
        class of a configuration of many elements (its pattern is `wells`)."""
        return jnp.where(jnp.all(self.wells >= 0, axis=-1), jnp.sum(self.wells > 0, axis=-1), -1)

    def miss(self, wells: Float[ArrayLike, "dof max_wells"], target) -> Float[Array, "na nf"]:
        """How far each point ended from the `target` configuration, a smooth quantity of the
        final state: mean over cells i of ((x_i - w_i) / s_i)^2 + (v_i / (s_i · 1 s⁻¹))^2, w_i the
        target's well of cell i, s_i the span of cell i's wells. Zero at rest in the target;
        differentiable with respect to the grid (`basin_map` under `jax.grad`).

        **Arguments:** `wells` as given to `basin_map`; `target` (dof,) the well index of each
        cell (e.g. `[0, 1, 1]`).
        """
        w = jnp.asarray(wells, self.x_final.dtype)
        span, _ = _geometry(w)
        goal = jnp.take_along_axis(w, jnp.asarray(target, int)[:, None], axis=1)[:, 0]
        goal, span = goal[None, None], span[None, None]
        return jnp.mean(((self.x_final - goal) / span) ** 2 + (self.v_final / span) ** 2, axis=-1)


def _member_final_state(model, settings: SweepSettings, x0, f, a, centre, span):
    """One point on its own (its own step size), stopped at the divergence box."""
    t_off = 0.5 / f
    box = (centre - settings.box_spans * span, centre + settings.box_spans * span)
    traj = integrate(vector_field(model, half_sine(settings.load, f, a, model.n_dof)), 0.0,
                     t_off + settings.settle_time, (x0, jnp.zeros_like(x0)), settings.integrator,
                     saveat=dfx.SaveAt(t1=True), box=box, jump_ts=jnp.reshape(t_off, (1,)))
    return traj.ys[0][-1], traj.ys[1][-1], traj.result._value, traj.stats["num_steps"]


def _final_state(model, settings: SweepSettings, x0, f, a, centre, span):
    """Final (x, v) and RESULTS code of one half-sine actuation (per-point solve)."""
    return _member_final_state(model, settings, x0, f, a, centre, span)[:3]


def classify(x1, v1, code, wells, span, settings: SweepSettings, couplers: bool = False):
    """Well index per cell (-1: not settled, failed, diverged) and the configuration code (sum of
    well index i times K^i over cells i, K = wells.shape[1]: the bit field for bistable cells).
    `couplers`: cells with one well (the couplers of a `Graph`, stressed by the others) are not
    judged by their position, only by their rate."""
    dist = jnp.abs(x1[:, None] - wells)  # (dof, max_wells)
    dist = jnp.where(jnp.isnan(wells), jnp.inf, dist)
    k = jnp.argmin(dist, axis=1)
    near = jnp.min(dist, axis=1) < settings.x_tol * span
    if couplers:
        near = near | (jnp.sum(~jnp.isnan(wells), axis=1) < 2)
    slow = jnp.abs(v1) < settings.v_tol * span
    settled = near & slow & jnp.isfinite(x1)
    good = code == RESULTS.successful._value
    idx = jnp.where(settled & good, k, -1)
    code = jnp.where(good & ~jnp.all(settled), RESULTS.not_settled._value, code)
    # one digit per cell in base K (the well slots): bit i for bistable cells (K = 2); a third well
    # of a tri-stable DOF is its own configuration, not the first well's (audit: it was)
    code_of = jnp.sum(jnp.where(idx >= 0, idx, 0) * wells.shape[1] ** jnp.arange(idx.shape[0]))
    config = jnp.where(jnp.all(idx >= 0), code_of, -1)
    return idx, config, code


def _geometry(wells):
    """Span and centre of each cell's wells ((..., dof, max_wells) -> (..., dof))."""
    span = jnp.nanmax(wells, axis=-1) - jnp.nanmin(wells, axis=-1)
    span = jnp.where(span > 0, span, 1.0)
    centre = 0.5 * (jnp.nanmax(wells, axis=-1) + jnp.nanmin(wells, axis=-1))
    return span, centre


def _chunk(model, settings, x0, wells, fs, amps):
    """Final states, wells, configurations, codes and steps of one chunk of B points."""
    span, centre = _geometry(wells)
    members = jax.vmap(lambda f, a: _member_final_state(model, settings, x0, f, a, centre, span))
    if settings.batching == "member":
        x1, v1, code, steps = members(fs, amps)
    else:
        x1, v1, code, joint_steps, ok = joint_final_states(model, settings, x0, fs, amps, centre, span)
        steps = jnp.broadcast_to(joint_steps, fs.shape)
        # a failed joint solve (max_steps, step-size collapse) is re-run point by point, so one
        # hard point costs its chunk time but not its neighbours' answers
        x1, v1, code, steps = jax.lax.cond(ok, lambda: (x1, v1, code, steps), lambda: members(fs, amps))
    idx, config, code = _classify_all(x1, v1, code, wells, span, settings)
    return idx, config, code, x1, v1, steps


def _box(topology, centre, span, box_spans, d: int):
    """The divergence box (lo, hi) of the coordinates from the wells' (M, classes) centre and span:
    each cell's centre +- box_spans spans; on a `Graph` every node within the sum over elements of
    |centre| + box_spans span (a node's displacement sums element deformations along a path)."""
    if not isinstance(topology, Graph):
        return centre - box_spans * span, centre + box_spans * span
    reach = jnp.sum(jnp.abs(centre) + box_spans * span, axis=-1, keepdims=True)
    reach = jnp.broadcast_to(reach, reach.shape[:-1] + (d,))
    return -reach, reach


def _lanes(models, settings, x0s, wells, fs, amps, mids, lanes: int, ensemble: bool):
    """Every point of this call through `lanes` lanes with per-point step control (`_lanes`);
    `wells`, `x0s` (M, ...) per model, point k of model `mids[k]` when `ensemble`. On a `Graph`
    the points are classified by their elements' deformations."""
    span, centre = _geometry(wells)  # (M, classes)
    topology = models.topology
    lo, hi = _box(topology, centre, span, settings.box_spans, x0s.shape[-1])
    x1, v1, code, steps = lanes_final_states(models, settings, as_solver(settings.solver), x0s, fs, amps,
                                             mids if ensemble else None, lo, hi, lanes, settings.attempts_per_pass)
    graph = isinstance(topology, Graph)
    cx, cv = (topology.deformations(x1), topology.deformations(v1)) if graph else (x1, v1)
    if ensemble:
        idx, config, code = jax.vmap(lambda x, v, c, m: classify(x, v, c, wells[m], span[m], settings, graph))(
            cx, cv, code, mids)
    else:
        idx, config, code = _classify_all(cx, cv, code, wells[0], span[0], settings, graph)
    return idx, config, code, x1, v1, steps


def _chunks(model, settings, x0s, wells, fs, amps, mids, chunk: int, ensemble: bool = False):
    if settings.batching == "lanes":
        return _lanes(model, settings, x0s, wells, fs, amps, mids, chunk, ensemble)
    out = jax.lax.map(lambda p: _chunk(model, settings, x0s[0], wells[0], p[0], p[1]),
                      (fs.reshape(-1, chunk), amps.reshape(-1, chunk)))
    return jax.tree.map(lambda o: o.reshape(-1, *o.shape[2:]), out)


_sweep_points = eqx.filter_jit(_chunks)


@functools.lru_cache(maxsize=32)
def _sharded(devices: tuple, chunk: int, ensemble: bool = False):
    """The points split over `devices` with shard_map; built once per (devices, chunk) so that
    later calls hit the jit cache."""
    mesh = Mesh(np.asarray(devices), ("grid",))

    @eqx.filter_jit
    def run(model, settings, x0s, wells, fs, amps, mids):
        def local(fs, amps, mids):
            return _chunks(model, settings, x0s, wells, fs, amps, mids, chunk, ensemble)

        return jax.shard_map(local, mesh=mesh, in_specs=(P("grid"), P("grid"), P("grid")), out_specs=P("grid"),
                             check_vma=False)(fs, amps, mids)

    return run


def friction_smoothing(model, settings: SweepSettings, wells) -> tuple:
    """(model, eps): the model with its sgn(v) as tanh(v / eps) where `settings.sign_eps` asks
    for it (see `SweepSettings`), and the eps in use (None: the model has no sgn(v) term or is
    not a `GlobalModel`; its own value where it set one)."""
    if not has_coulomb(model):
        return model, None
    if model.sign_eps != 0.0 and settings.sign_eps is None:
        return model, float(model.sign_eps)
    if settings.sign_eps is None:
        span = np.nanmax(wells, axis=1) - np.nanmin(wells, axis=1)
        span = span[span > 0]
        eps = 0.1 * float(settings.v_tol) * (float(span.min()) if span.size else 1.0)
    else:
        eps = float(settings.sign_eps)
    return model.with_sign_eps(eps), eps


def resolve_batching(model, settings: SweepSettings, devices) -> str:
    """The batching a sweep runs with ("auto" is "lanes"); "native" asked for where it cannot run
    is a `GMRInputError` naming why and the fix."""
    graph = isinstance(model.topology, Graph)
    if settings.batching in ("joint", "member") and (graph or node_of(settings.load) is not None):
        raise GMRInputError(f"batching={settings.batching!r} sweeps chains and independent DOFs under a tip or base load; "
                            f"a {'Graph' if graph else 'node:K load'} sweeps on batching='lanes' (the default)")
    if settings.batching != "native":
        return "lanes" if settings.batching == "auto" else settings.batching
    why = None
    if not _native.supports(model, settings):
        why = (f"the native kernel integrates a GlobalModel on a chain or independent DOFs in float64 with "
               f"Tsit5, Dopri5 or Dopri8 under a tip or base load (got {type(model).__name__} on "
               f"{type(model.topology).__name__}, precision {settings.precision}, solver "
               f"{type(as_solver(settings.solver)).__name__}, load {settings.load!r})")
    elif _native.compiler() is None:
        why = "GMR_NATIVE turns it off" if _native.disabled() else "no C compiler was found ($CC, cc, gcc, clang)"
    elif jax.process_count() > 1:
        why = "it runs in one process (use lanes across jax.distributed processes)"
    elif any(d.platform != "cpu" for d in devices):
        why = "accelerator devices were given (lanes runs on them)"
    if why is None:
        try:
            _native.kernel(model, settings)  # built (or loaded from disk) here, so a failure is seen here
            return "native"
        except (RuntimeError, OSError) as err:
            why = f"the C kernel did not build: {str(err)[-600:]}"
    raise GMRInputError(f"batching='native' cannot run here: {why}; use SweepSettings(batching='lanes')")


LANES_CPU = 256  # lanes per CPU device ("lanes"; measured in results/basins_diffrax_numba.md)
LANES_ACCELERATOR = 32_768  # lanes per GPU/TPU (H100, 5 cells, 1e5 points: 8192 1.6x slower, 1e5 1.2x)


def default_chunk(n_dof: int, batching: str = "joint", accelerator: bool = False) -> int:
    """Points per chunk ("joint", "member": a power of two near 1280 / dof, within [64, 512];
    measured on a CPU: 10 DOFs 240 us/point at 128 vs 261 at 256; 3 DOFs 42 at 512 vs 46 at 256)
    or lanes per device ("lanes": `LANES_CPU`, `LANES_ACCELERATOR`)."""
    if batching == "lanes":
        return LANES_ACCELERATOR if accelerator else LANES_CPU
    return int(np.clip(2 ** round(np.log2(1280 / max(n_dof, 1))), 64, 512))


def _traced(settings: SweepSettings) -> SweepSettings:
    """Every float setting as an array: new tolerances or settle times do not recompile (the
    solver is left as it is)."""
    dtype = PRECISIONS[settings.precision]
    arr = lambda v: None if v is None else jnp.asarray(v, dtype)  # noqa: E731
    integ = settings.integrator
    return dataclasses.replace(
        settings, settle_time=arr(settings.settle_time), x_tol=arr(settings.x_tol), v_tol=arr(settings.v_tol),
        box_spans=arr(settings.box_spans),
        integrator=dataclasses.replace(integ, rtol=arr(integ.rtol), atol=arr(integ.atol), dt0=arr(integ.dt0)))


def _cast(tree, dtype):
    """Floating arrays of a pytree (a model's coefficients) in `dtype`."""
    return jax.tree.map(lambda a: a.astype(dtype) if eqx.is_inexact_array(a) else a, tree)


def _check_inputs(model, f, A, wells, x0):
    if not isinstance(model, AbstractMechanicalModel):
        raise GMRInputError(f"basin_map needs a mechanical model (GlobalModel, KreslingChain, ...), got "
                            f"{type(model).__name__}; load a model file with gmr_jax.load_model")
    d, e = model.n_dof, model.n_elements
    f, A = np.asarray(f, float), np.asarray(A, float)
    for name, v in (("f", f), ("A", A)):
        if v.ndim != 1 or v.size == 0:
            raise GMRInputError(f"{name} must be a non-empty 1-D array of grid values, got shape {v.shape}")
        if not np.all(np.isfinite(v)):
            raise GMRInputError(f"{name} contains NaN or inf values")
    if np.any(f <= 0):
        raise GMRInputError("f must be > 0 (Hz): the half-sine lasts 1/(2f)")
    wells = np.asarray(wells, float)
    what = "elements" if isinstance(model.topology, Graph) else "dof"
    if wells.ndim != 2 or wells.shape[0] != e:
        raise GMRInputError(f"wells must be ({what}, max_wells) = ({e}, k) for this model, got shape "
                            f"{wells.shape}; compute them with gmr_jax.stable_wells(model, x_range)")
    if isinstance(model.topology, Graph) and x0 is None:
        raise GMRInputError("a Graph's sweep needs x0, the node displacements it starts from (a stable "
                            "configuration: gmr_jax.configuration(model, wells, pattern))")
    if np.any(np.all(np.isnan(wells), axis=1)):
        bad = np.nonzero(np.all(np.isnan(wells), axis=1))[0].tolist()
        raise GMRInputError(f"no stable well for DOF(s) {bad}: widen the x_range given to stable_wells")
    if x0 is not None:
        x0 = np.asarray(x0, float)
        if x0.shape != (d,) or not np.all(np.isfinite(x0)):
            raise GMRInputError(f"x0 must be {d} finite deformations (one per DOF), got {x0.tolist()}")
    return f, A, wells, x0


def _check_load(settings: SweepSettings, d: int):
    k = node_of(settings.load)
    if k is not None and k >= d:
        raise GMRInputError(f"SweepSettings.load={settings.load!r}: this model has {d} masses (nodes 0..{d - 1})")


def basin_map(
    model: AbstractMechanicalModel,
    f: Float[ArrayLike, " nf"],
    A: Float[ArrayLike, " na"],
    wells: Float[ArrayLike, "dof max_wells"],
    *,
    x0: Float[ArrayLike, " dof"] | None = None,
    settings: SweepSettings = SweepSettings(),
    chunk: int | None = None,
    devices=None,
    progress: Callable[[int, int], None] | None = None,
    throw: bool = True,
) -> Solution:
    """Final configuration of the chain under the Eq. (25) half-sine load, over an (f, A) grid.

    **Arguments:**

    - `model`: any mechanical model (reconstructed, hand-written or a truth system).
    - `f`, `A`: actuation frequencies (Hz) and amplitudes (force units; m/s² for
      `settings.load="base"`) of the grid.
    - `wells`: (dof, max_wells) stable equilibria per cell (`stable_wells`), ordered; on a `Graph`
      (elements, max_wells), each element's wells: final states are classified by the elements'
      deformations (`BasinMap.wells` per element, `config` the elements' well indices as digits).
    - `x0`: start (default: every cell in its first well, at rest; on a `Graph`, required: the
      node displacements of a stable configuration, `configuration`).
    - `settings`: `SweepSettings` (tolerances, settling, classification, load, batching).
    - `chunk`: (not for "native", which runs 16 points per group on every core) under "lanes"
      batching the number of lanes per device (default 128 on a CPU,
      32768 on a GPU/TPU); under "joint"/"member" the points integrated together (default
      `default_chunk(dof)`: 512, 256, 128 points for 3, 5, 10 DOFs). Points are ordered by
      (f, A) before chunking, so neighbouring lanes and chunks hold similar actuations. The integrator's memory is per chunk; what grows with the
      grid is the returned map and its copies, about 0.6-0.7 kB per point at peak (1e6 points:
      1.1 GB in all, `results/bench_basins_memory.md`).
    - `devices`: devices to shard the grid over (default: all of `jax.devices()`; "native" runs
      one thread per device given, every core of the host by default, and "auto" takes "lanes"
      when accelerators are given); chunks are
      dealt to a 1-D `shard_map` mesh in turn, so several CPU host devices, GPUs or TPUs (and
      several hosts after `jax.distributed.initialize()`) share the work evenly.
    - `progress`: optional `progress(done, total)` called after each block of chunks (the grid
      then runs in up to ~20 calls of one compiled function).

    - `throw`: raise `GMRComputationError` when the integrator failed on some point (its step
      budget or step size ran out): those points are not an answer about the model.

    **Returns:** a `Solution` whose `value` is a `BasinMap`. Nothing is silently classified:
    points that diverged, failed or had not settled at t1 are -1 with their own code in
    `BasinMap.result`. The Solution's `result` is `successful` unless the integrator failed on
    some point (then the first such code); a point that `diverged` (left the divergence box) or
    was `not_settled` is an outcome of the model, counted in `stats["counts"]` (points per
    code name). `stats["batching"]` is the path that ran ("lanes", "native", ...),
    `stats["solver"]` the diffrax solver's name (e.g. "Tsit5") and
    `stats["sign_eps"]` the smoothing of a Coulomb term (None: the model has none).

    Compiled shapes depend only on the number of points, `chunk`, the devices and the model's
    structure: new f, A, settle times, tolerances or coefficient values do not recompile.

    Under `jax.jit`, `jax.vmap` (e.g. over stacked models) or `jax.grad`, with `wells` and
    `settings` fixed (concrete), `basin_map` is a pure function of the model, `f`, `A` and
    `x0`: one "lanes" sweep on the default device, `stats` holding only `num_steps` (the
    points' total step attempts), a Coulomb term smoothed as outside jit (with traced
    coefficients, e.g. under `vmap` over models, only when `settings.sign_eps` says so), and
    `throw=True` an `eqx.error_if` check. `x_final` and `v_final` are differentiable with respect
    to `f` and `A` (each point's derivatives by forward mode through its own solve, a custom
    JVP linear in the grid's tangents: `jax.jvp` and `jax.grad` of any smooth function of them, e.g.
    `BasinMap.miss`); not with respect to the model's coefficients.
    """
    if any(is_tracer(leaf) for leaf in jax.tree.leaves((model, f, A, wells, x0, settings))):
        return _traced_map(model, f, A, wells, x0, settings, chunk, throw)
    relieve_map_pressure()  # a long session's compiled programs (`_config.map_pressure`)
    f_np, a_np, wells_np, x0_np = _check_inputs(model, f, A, wells, x0)
    _check_load(settings, model.n_dof)
    model, sign_eps = friction_smoothing(model, settings, wells_np)
    n_threads = None if devices is None else len(devices)  # native: one thread per device given, else every core
    devices = tuple(jax.devices() if devices is None else devices)
    batching = resolve_batching(model, settings, devices)
    if batching != settings.batching:
        settings = dataclasses.replace(settings, batching=batching)
    dtype = PRECISIONS[settings.precision]
    wells = jnp.asarray(wells_np, dtype)
    x0 = wells[:, 0] if x0_np is None else jnp.asarray(x0_np, dtype)
    settings_t = _traced(settings)
    if dtype != jnp.float64:
        model = _cast(model, dtype)
    ff, aa = np.meshgrid(f_np, a_np)  # (NA, NF)
    flat_f, flat_a = ff.ravel(), aa.ravel()
    order = np.lexsort((flat_a, flat_f))  # by f, then A: similar actuations share a chunk
    n = flat_f.size
    solver = type(as_solver(settings.solver)).__name__ if batching in ("lanes", "native") else "Tsit5"
    if batching == "native":
        cat = _native_sweep(model, settings, settings_t, x0, wells, flat_f[order], flat_a[order], progress, n_threads)
        first = np.empty(n, int)
        first[order] = np.arange(n)
        return _finish(cat, first, f_np, a_np, x0.shape[0], {"chunk": _native.LANES, "devices": 1,
                                                              "threads": n_threads or _native.threads(),
                                                              "sign_eps": sign_eps, "solver": solver},
                       batching, throw)
    cat, extra = _run_points(model, False, settings, settings_t, x0[None], wells[None], flat_f[order], flat_a[order],
                             None, chunk, devices, progress)
    first = np.empty(n, int)
    first[order] = np.arange(n)
    return _finish(cat, first, f_np, a_np, x0.shape[0], {**extra, "sign_eps": sign_eps, "solver": solver}, batching,
                   throw)


def _traced_map(model, f, A, wells, x0, settings: SweepSettings, chunk, throw: bool) -> Solution:
    """`basin_map` as a pure function of traced arrays (its docstring): one lanes sweep."""
    if is_tracer(wells) or not isinstance(settings, SweepSettings) or any(
            is_tracer(leaf) for leaf in jax.tree.leaves(settings)):
        raise GMRInputError("basin_map under jax.jit / vmap / grad needs the wells and the settings fixed (concrete "
                            "values, e.g. functools.partial(basin_map, wells=wells, settings=settings)): they decide "
                            "the classification and the compiled program")
    if settings.batching not in ("auto", "lanes"):
        raise GMRInputError(f"basin_map under jax.jit / vmap / grad runs batching='lanes' (got "
                            f"{settings.batching!r}: it runs outside jit); use SweepSettings(batching='lanes')")
    if not isinstance(model, AbstractMechanicalModel):
        raise GMRInputError(f"basin_map needs a mechanical model (GlobalModel, KreslingChain, ...), got "
                            f"{type(model).__name__}")
    wells_np = np.asarray(wells, float)
    d = model.n_dof
    if wells_np.ndim != 2 or wells_np.shape[0] != model.n_elements:
        raise GMRInputError(f"wells must be (cells, max_wells) = ({model.n_elements}, k) for this model (the "
                            f"elements of a Graph), got shape {wells_np.shape}")
    if x0 is None and isinstance(model.topology, Graph):
        raise GMRInputError("a Graph's sweep needs x0, the node displacements it starts from")
    _check_load(settings, d)
    if jnp.ndim(f) != 1 or jnp.ndim(A) != 1:
        raise GMRInputError(f"f and A must be 1-D arrays of grid values, got shapes {jnp.shape(f)}, {jnp.shape(A)}")
    settings = dataclasses.replace(settings, batching="lanes")
    if not any(is_tracer(leaf) for leaf in jax.tree.leaves(model)):
        model, _ = friction_smoothing(model, settings, wells_np)
    elif settings.sign_eps is not None and settings.sign_eps > 0:  # traced coefficients: smoothed when asked
        model = model.with_sign_eps(float(settings.sign_eps))
    dtype = PRECISIONS[settings.precision]
    wells_j = jnp.asarray(wells_np, dtype)
    x0 = wells_j[:, 0] if x0 is None else jnp.asarray(x0, dtype)
    f, A = jnp.asarray(f, dtype), jnp.asarray(A, dtype)
    ff, aa = jnp.meshgrid(f, A)
    fs, amps = ff.ravel(), aa.ravel()
    n = fs.shape[0]
    lanes = min(int(chunk) if chunk is not None else default_chunk(d, "lanes"), n)
    st = _traced(settings)
    mids = jnp.zeros(n, jnp.int32)

    def states(fs, amps):
        return _chunks(model, st, x0[None], wells_j[None], fs, amps, mids, lanes, False)

    def derivatives(fs, amps):
        # each point's final state depends on its own (f, A) only: one forward-mode pass with the two
        # tangents (all f, all A) gives every point's derivatives
        def one(t_f, t_a):
            out, tan = jax.jvp(states, (fs, amps), (t_f, t_a))
            return out, (tan[3], tan[4])

        ones, zeros = jnp.ones_like(fs), jnp.zeros_like(fs)
        return jax.vmap(one, out_axes=(None, 0))(jnp.stack([ones, zeros]), jnp.stack([zeros, ones]))

    @jax.custom_jvp
    def sweep(fs, amps):
        return states(fs, amps)

    @sweep.defjvp
    def _(primals, tangents):
        # the tangent is linear in (t_f, t_a) with the points' own derivatives: jvp and its transpose (grad)
        out, (dx, dv) = derivatives(*primals)
        t_f, t_a = (t[:, None] for t in tangents)
        none = lambda o: np.zeros(o.shape, jax.dtypes.float0)  # noqa: E731  (integer outputs)
        return out, (none(out[0]), none(out[1]), none(out[2]), dx[0] * t_f + dx[1] * t_a, dv[0] * t_f + dv[1] * t_a,
                     none(out[5]))

    idx, config, code, x1, v1, steps = sweep(fs, amps)
    na, nf = A.shape[0], f.shape[0]
    bm = BasinMap(f=f, A=A, wells=idx.reshape(na, nf, -1), config=config.reshape(na, nf),
                  result=code.reshape(na, nf), x_final=x1.reshape(na, nf, d), v_final=v1.reshape(na, nf, d),
                  steps=steps.reshape(na, nf))
    outcome = (code == RESULTS.successful._value) | (code == RESULTS.diverged._value) | (
        code == RESULTS.not_settled._value)
    first = jnp.argmax(~outcome)
    result = as_result(jnp.where(jnp.any(~outcome), code[first], RESULTS.successful._value))
    return error_if_failed(Solution(value=bm, result=result, stats={"num_steps": jnp.sum(steps)}), throw)


def _run_points(model, ensemble, settings, settings_t, x0s, wells, fs, amps, mids, chunk, devices, progress):
    """(idx, config, code, x1, v1, steps) of the points (fs, amps[, mids]) in the order given,
    sharded over `devices` in up to 20 calls of one compiled function when `progress` is given,
    and the stats (chunk, devices)."""
    n = fs.size
    dtype = PRECISIONS[settings.precision]
    nd = len(devices)
    if chunk is None:
        accelerator = devices[0].platform != "cpu"
        chunk = default_chunk(int(x0s.shape[1]), settings.batching, accelerator)
    chunk = int(chunk)
    if chunk < 1:
        raise GMRInputError(f"chunk must be >= 1, got {chunk}")
    chunk = min(chunk, -(-n // nd))
    per_dev = -(-n // (chunk * nd))  # chunks per device
    calls = 1 if progress is None else min(per_dev, 20)
    k = -(-per_dev // calls)  # chunks per device per call
    calls = -(-per_dev // k)
    total = calls * k * nd * chunk
    pad = np.concatenate([np.arange(n), np.full(total - n, n - 1)])
    # call c, device j, slot i holds chunk (c * k + i) * nd + j: devices take turns
    layout = pad.reshape(calls, k, nd, chunk).transpose(0, 2, 1, 3).reshape(calls, -1)
    run = None if nd == 1 else (_sharded(devices, chunk, True) if ensemble else _sharded(devices, chunk))
    multi = jax.process_count() > 1 and run is not None
    if multi:  # host values, identical in every process, are what a multi-process jit takes
        model, settings_t, x0s, wells = jax.tree.map(
            lambda a: np.asarray(a) if eqx.is_array(a) else a, (model, settings_t, x0s, wells))
    mids = np.zeros(n, np.int32) if mids is None else np.asarray(mids, np.int32)
    parts = []
    for c in range(calls):
        # NumPy: the same global input in every process
        f_c, a_c, m_c = fs[layout[c]].astype(dtype), amps[layout[c]].astype(dtype), mids[layout[c]]
        if run is None:
            out = _sweep_points(model, settings_t, x0s, wells, jnp.asarray(f_c), jnp.asarray(a_c), jnp.asarray(m_c),
                                chunk, ensemble)
        else:
            out = run(model, settings_t, x0s, wells, f_c, a_c, m_c)
        if multi:  # every process gets the whole map (jax.distributed)
            from jax.experimental import multihost_utils

            out = multihost_utils.process_allgather(out, tiled=True)
        parts.append(jax.tree.map(np.asarray, out))
        if progress is not None:
            progress(min(n, (c + 1) * k * nd * chunk), n)
    cat = [np.concatenate([p[j] for p in parts]) for j in range(6)]
    src = layout.ravel()
    first = np.full(n, -1)
    first[src[::-1]] = np.arange(src.size)[::-1]  # first slot holding each point
    return [o[first] for o in cat], {"chunk": chunk, "devices": nd}


def _native_sweep(model, settings, settings_t, x0, wells, fs, amps, progress, n_threads=None):
    """(idx, config, code, x1, v1, steps) of the points (fs, amps) by the native kernel on
    `n_threads` threads (default: every core), in up to 20 blocks when `progress` is given (one
    call otherwise)."""
    span, centre = (np.asarray(a) for a in _geometry(wells))
    n = fs.size
    nt = n_threads or _native.threads()
    blocks = 1 if progress is None else int(min(20, max(1, -(-n // (_native.LANES * nt)))))
    bounds = np.linspace(0, n, blocks + 1).astype(int)
    parts = []
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        parts.append(_native.native_final_states(model, settings, np.asarray(x0), fs[lo:hi], amps[lo:hi], centre,
                                                 span, n_threads=nt))
        if progress is not None:
            progress(int(hi), n)
    x1, v1, code, steps = (np.concatenate([p[j] for p in parts]) for j in range(4))
    idx, config, code = _classify_points(jnp.asarray(x1), jnp.asarray(v1), jnp.asarray(code), wells,
                                         jnp.asarray(span), settings_t)
    return [np.asarray(o) for o in (idx, config, code)] + [x1, v1, steps]


def _classify_all(x1, v1, code, wells, span, settings, couplers: bool = False):
    """`classify` over the points (leading axis of x1, v1, code)."""
    return jax.vmap(lambda x, v, c: classify(x, v, c, wells, span, settings, couplers))(x1, v1, code)


_classify_points = eqx.filter_jit(_classify_all)  # the native path's final states come from outside jit


def _finish(cat, first, f_np, a_np, d, stats, batching, throw):
    """The `Solution` of a sweep: per-point outputs `cat` (idx, config, code, x1, v1, steps)
    taken at `first` (the slot of each grid point, A-major), counts and the failure check."""
    idx, config, code, x1, v1, steps = (o[first] for o in cat)
    n = first.size
    na, nf = a_np.size, f_np.size
    bm = BasinMap(f=jnp.asarray(f_np), A=jnp.asarray(a_np), wells=jnp.asarray(idx.reshape(na, nf, -1)),
                  config=jnp.asarray(config.reshape(na, nf)), result=jnp.asarray(code.reshape(na, nf)),
                  x_final=jnp.asarray(x1.reshape(na, nf, d)), v_final=jnp.asarray(v1.reshape(na, nf, d)),
                  steps=jnp.asarray(steps.reshape(na, nf)))
    values, counts = np.unique(code, return_counts=True)
    stats = {"counts": {code_name(v): int(c) for v, c in zip(values, counts)}, "batching": batching, **stats}
    outcomes = {value_of(n) for n in ("successful", "diverged", "not_settled")}
    failed = code[~np.isin(code, list(outcomes))]
    result = as_result(int(failed[0])) if failed.size else RESULTS.successful
    detail = f"{failed.size} of {n} points: " + ", ".join(f"{k} {c}" for k, c in stats["counts"].items())
    if stats.get("sign_eps") == 0.0 and "max_steps_reached" in stats["counts"]:
        detail += ("; the model's exact sgn(v) (Coulomb friction) makes an adaptive solver chatter where a cell "
                   "stops: leave SweepSettings.sign_eps at None (tanh smoothing below the settled speed)")
    return raise_if_failed(Solution(value=bm, result=result, stats=stats), throw, "basin_map", detail)


def n_chunk_compiles() -> int:
    """Number of compiled single-device sweep functions (a trace counter for tests)."""
    return _sweep_points._cached._cache_size()



def ensemble_configs(models, f_np, a_np, wells_m, x0s, settings: SweepSettings, chunk=None, devices=None,
                     progress=None):
    """Configurations (M, NA, NF) and RESULTS codes (M, NA, NF) of M models of one structure
    (`models`: a `GlobalModel` whose arrays have a leading axis M, `wells_m` (M, dof, max_wells),
    `x0s` (M, dof)) over one (f, A) grid. Under "lanes" batching the models are data: every
    (model, grid point) pair goes through one compiled lanes loop (each lane carries its
    point's coefficients, wells and box), so M models cost one sweep of M x NA x NF points, not M
    sweeps; other batchings sweep the models one after another with `basin_map`."""
    m_count = wells_m.shape[0]
    devices = tuple(jax.devices() if devices is None else devices)
    batching = resolve_batching(jax.tree.map(lambda a: a[0] if eqx.is_array(a) else a, models), settings, devices)
    na, nf = a_np.size, f_np.size
    if batching != "lanes":
        configs, codes = [], []
        for k in range(m_count):
            mk = jax.tree.map(lambda a, k=k: a[k] if eqx.is_array(a) else a, models)
            sol = basin_map(mk, f_np, a_np, wells_m[k], x0=x0s[k], settings=settings, chunk=chunk, devices=devices,
                            throw=False)
            configs.append(np.asarray(sol.value.config))
            codes.append(np.asarray(sol.value.result))
            if progress is not None:
                progress(k + 1, m_count)
        return np.stack(configs), np.stack(codes)
    settings = dataclasses.replace(settings, batching="lanes")
    dtype = PRECISIONS[settings.precision]
    if dtype != jnp.float64:
        models = _cast(models, dtype)
    ff, aa = np.meshgrid(f_np, a_np)
    flat_f, flat_a = ff.ravel(), aa.ravel()
    order = np.lexsort((flat_a, flat_f))  # by f, then A; the models of one grid point side by side
    n_grid = flat_f.size
    fs = np.repeat(flat_f[order], m_count)
    amps = np.repeat(flat_a[order], m_count)
    mids = np.tile(np.arange(m_count), n_grid)
    report = None if progress is None else (lambda done, total: progress(done * m_count // total, m_count))
    cat, _ = _run_points(models, True, settings, _traced(settings), jnp.asarray(x0s, dtype),
                         jnp.asarray(wells_m, dtype), fs, amps, mids, chunk, devices, report)
    config, code = cat[1], cat[2]
    out_cfg, out_code = np.empty((m_count, n_grid), config.dtype), np.empty((m_count, n_grid), code.dtype)
    slot = np.arange(n_grid * m_count)
    out_cfg[mids, order[slot // m_count]] = config
    out_code[mids, order[slot // m_count]] = code
    return out_cfg.reshape(m_count, na, nf), out_code.reshape(m_count, na, nf)
