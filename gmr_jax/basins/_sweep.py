"""Deployment-basin sweeps over actuation grids (paper Fig. 11): vmapped diffrax, chunked,
sharded over all devices, every member's result code kept."""

import functools

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, PartitionSpec as P
from jaxtyping import Array, Float, Int

from .._solution import RESULTS
from ..model._model import AbstractMechanicalModel
from ..simulate._inputs import HalfSineTip
from ..simulate._simulate import _vector_field


class SweepSettings(eqx.Module):
    """How each grid point is simulated and judged.

    - `settle_time`: free time after the actuation ends (t1 = 1/(2f) + settle_time).
    - `rtol`, `atol`, `max_steps`: Tsit5 with PID control; the switch-off time 1/(2f) is
      declared to the controller (`jump_ts`).
    - `x_tol`: a cell is in a well when |x - x_well| < x_tol · (span of that cell's wells).
    - `v_tol`: ... and |v| < v_tol · span · (1 s⁻¹).
    - `bound`: |x| beyond bound · span (about the wells' centre) stops the solve: diverged.
    """

    settle_time: float = 10.0
    rtol: float = 1e-6
    atol: float = 1e-8
    max_steps: int = eqx.field(static=True, default=100_000)
    x_tol: float = 0.1
    v_tol: float = 0.05
    bound: float = 20.0


class BasinMap(eqx.Module):
    """`wells` (NA, NF, dof): index of the well each cell ended in (ordered by deformation),
    -1 when not settled or failed; `config` (NA, NF): bit i set = cell i in its second well
    (-1 as above); `result` (NA, NF) RESULTS codes; `x_final`, `v_final` (NA, NF, dof)."""

    f: Float[Array, " nf"]
    A: Float[Array, " na"]
    wells: Int[Array, "na nf dof"]
    config: Int[Array, "na nf"]
    result: Int[Array, "na nf"]
    x_final: Float[Array, "na nf dof"]
    v_final: Float[Array, "na nf dof"]


def _final_state(model, settings: SweepSettings, x0, f, a, centre, span):
    d = model.n_dof
    exc = HalfSineTip(f, a, n_dof=d)

    t_off = 0.5 / f
    ctrl = dfx.ClipStepSizeController(dfx.PIDController(rtol=settings.rtol, atol=settings.atol),
                                      jump_ts=jnp.reshape(t_off, (1,)))

    def cond_fn(t, y, args, **kw):
        return jnp.max(jnp.abs(y[0] - centre) / span) > settings.bound

    sol = dfx.diffeqsolve(
        dfx.ODETerm(_vector_field(model, exc)), dfx.Tsit5(), 0.0, t_off + settings.settle_time, None,
        (x0, jnp.zeros_like(x0)), saveat=dfx.SaveAt(t1=True), stepsize_controller=ctrl,
        max_steps=settings.max_steps, event=dfx.Event(cond_fn), throw=False,
    )
    x1, v1 = sol.ys[0][-1], sol.ys[1][-1]
    ok = sol.result == dfx.RESULTS.successful
    diverged = sol.result == dfx.RESULTS.event_occurred
    code = jnp.where(ok, RESULTS.successful._value,
                     jnp.where(diverged, RESULTS.diverged._value, RESULTS.simulation_failed._value))
    return x1, v1, code


def classify(x1, v1, code, wells, span, settings: SweepSettings):
    """Well index per cell (-1: not settled, failed, diverged) and the configuration bits."""
    dist = jnp.abs(x1[:, None] - wells)  # (dof, max_wells)
    dist = jnp.where(jnp.isnan(wells), jnp.inf, dist)
    k = jnp.argmin(dist, axis=1)
    near = jnp.min(dist, axis=1) < settings.x_tol * span
    slow = jnp.abs(v1) < settings.v_tol * span
    settled = near & slow & jnp.isfinite(x1)
    good = code == RESULTS.successful._value
    idx = jnp.where(settled & good, k, -1)
    code = jnp.where(good & ~jnp.all(settled), RESULTS.not_settled._value, code)
    bits = jnp.sum(jnp.where(idx == 1, 2 ** jnp.arange(idx.shape[0]), 0))
    config = jnp.where(jnp.all(idx >= 0), bits, -1)
    return idx, config, code


@eqx.filter_jit
def _sweep_points(model, settings, x0, fs, amps, wells, chunk: int):
    span = jnp.nanmax(wells, axis=1) - jnp.nanmin(wells, axis=1)
    span = jnp.where(span > 0, span, 1.0)
    centre = 0.5 * (jnp.nanmax(wells, axis=1) + jnp.nanmin(wells, axis=1))

    def one(fa):
        x1, v1, code = _final_state(model, settings, x0, fa[0], fa[1], centre, span)
        idx, config, code = classify(x1, v1, code, wells, span, settings)
        return idx, config, code, x1, v1

    pts = jnp.stack([fs, amps], axis=1)
    return jax.lax.map(one, pts, batch_size=chunk)


@functools.lru_cache(maxsize=32)
def _sharded(devices: tuple, chunk: int):
    """The grid split over `devices` with shard_map; built once per (devices, chunk) so that
    later calls hit the jit cache."""
    mesh = Mesh(np.asarray(devices), ("grid",))

    @eqx.filter_jit
    def run(model, settings, x0, wells, fs, amps):
        def local(fs, amps):
            return _sweep_points(model, settings, x0, fs, amps, wells, chunk)

        return jax.shard_map(local, mesh=mesh, in_specs=(P("grid"), P("grid")), out_specs=P("grid"),
                             check_vma=False)(fs, amps)

    return run


def basin_map(
    model: AbstractMechanicalModel,
    f: Float[Array, " nf"],
    A: Float[Array, " na"],
    wells: np.ndarray,
    *,
    x0: Float[Array, " dof"] | None = None,
    settings: SweepSettings = SweepSettings(),
    chunk: int = 512,
    devices=None,
) -> BasinMap:
    """Final configuration of the chain under the Eq. (25) tip half-sine, over an (f, A) grid.

    **Arguments:**

    - `model`: any mechanical model (reconstructed or truth).
    - `f`, `A`: actuation frequencies (Hz) and amplitudes (force units) of the grid.
    - `wells`: (dof, max_wells) stable equilibria per cell (`stable_wells`), ordered.
    - `x0`: start (default: every cell in its first well, at rest).
    - `chunk`: trajectories integrated together (lockstep batch) per `lax.map` step; bounds
      memory for grids of 1e5-1e6 points.
    - `devices`: devices to shard the grid over (default: all of `jax.devices()`); the grid is
      split with `shard_map` over a 1-D mesh, so several CPU host devices, GPUs or TPUs (and
      multi-host after `jax.distributed.initialize()`) share the work.

    Shapes depend only on the grid size and the model, not on f, A or coefficient values: a
    new grid of the same size or new coefficients do not recompile.
    """
    wells = jnp.asarray(wells, float)
    x0 = wells[:, 0] if x0 is None else jnp.asarray(x0, float)
    f = jnp.asarray(f, float)
    A = jnp.asarray(A, float)
    ff, aa = jnp.meshgrid(f, A)  # (NA, NF)
    flat_f, flat_a = ff.ravel(), aa.ravel()
    n = flat_f.shape[0]
    devices = jax.devices() if devices is None else devices
    nd = len(devices)
    per = -(-n // nd)
    per = -(-per // chunk) * chunk if per > chunk else per
    pad = per * nd - n
    flat_f = jnp.concatenate([flat_f, jnp.full(pad, flat_f[0])])
    flat_a = jnp.concatenate([flat_a, jnp.full(pad, flat_a[0])])
    if nd == 1:
        out = _sweep_points(model, settings, x0, flat_f, flat_a, wells, min(chunk, per))
    else:
        out = _sharded(tuple(devices), min(chunk, per))(model, settings, x0, wells, flat_f, flat_a)
    idx, config, code, x1, v1 = (o[:n] for o in out)
    na, nf = A.shape[0], f.shape[0]
    d = x0.shape[0]
    return BasinMap(f=f, A=A, wells=idx.reshape(na, nf, d), config=config.reshape(na, nf),
                    result=code.reshape(na, nf), x_final=x1.reshape(na, nf, d),
                    v_final=v1.reshape(na, nf, d))
