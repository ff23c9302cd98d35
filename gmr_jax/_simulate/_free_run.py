"""Free run of a model under a recording's measured input, against the measured displacement
(the output error of `gmr discover`, per DOF, as one public call).

The run starts from the recorded state at `sim_start` (half a Savitzky-Golay window in when v
was estimated from x), the input is low-passed at 3x its band edge where it carries white noise
and interpolated by a cubic spline (`_inputs.smooth_input`, `sampled_spline`), sgn(v) terms are smoothed to
tanh(v / eps) with eps = 1e-3 rms(v), and the step budget grows with the record: the same
simulation `discover` reports as output error. An x integrated from v or a is compared after the
same drift removal (`_offset.comparable`), its unobservable equilibrium placed by the model.
"""

import warnings
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
from jaxtyping import Float, Int

from .._errors import GMRDataWarning, GMRInputError
from .._model._model import AbstractMechanicalModel
from .._recordings._recording import Recording, load_recording, validate
from .._solution import RESULTS, Solution, as_result, code_name, message, raise_if_failed
from ._inputs import sampled_spline, smooth_input
from ._integrate import Integrator
from ._offset import comparable, place
from ._simulate import simulate

#: a displacement farther than this many recorded spans from the recorded mean is divergence
BOX_SPANS = 100.0


@dataclass(frozen=True)
class FreeRun:
    """What `free_run` returns as `value`.

    - `t` (n,): the times of the run (from the start sample on), s.
    - `x` (n, dof): simulated displacement (NaN when the run failed).
    - `x_measured` (n, dof): the recording's displacement over the same times.
    - `nrmse` (dof,): ||x - x_measured|| / ||x_measured - mean|| per DOF (NaN when failed).
    - `start`: index of the first sample in the recording; `name`: the recording's name.
    - `notes`: how the input and x were treated (for reports).
    - `horizon`, `horizon_nrmse` (dof,): the model restarted from the recorded state every
      `horizon` seconds (one period of the input, or of x for a free decay) and run for that long,
      its error pooled over the restarts, as `nrmse` (`horizon_runs`). A record that crosses
      between wells can be chaotic: a free run leaves it even with an exact model, a run of one
      period does not. None where x was integrated from v or a.
    - `crossings` (2, dof): well-to-well crossings of the measured x and of the free run (`crossings`;
      -1 for a DOF with fewer than two of the model's wells in the recorded range).
    """

    t: Float[np.ndarray, " n"]
    x: Float[np.ndarray, "n dof"]
    x_measured: Float[np.ndarray, "n dof"]
    nrmse: Float[np.ndarray, " dof"]
    start: int
    name: str
    notes: tuple[str, ...] = ()
    horizon: float | None = None
    horizon_nrmse: Float[np.ndarray, " dof"] | None = None
    crossings: Int[np.ndarray, "2 dof"] | None = None

    @property
    def residual(self) -> Float[np.ndarray, "n dof"]:
        """Model minus measurement."""
        return self.x - self.x_measured


#: the free run's integrator: tolerances and the step budget of a record up to 20 000 samples
SIM = Integrator(rtol=1e-7, atol=1e-10, max_steps=400_000)


def sim_start(rec: Recording) -> int:
    """First sample of the output-error simulation: half a Savitzky-Golay window in, where an
    estimated v is an interior (not extrapolated) estimate; 0 when v was recorded."""
    if "v" not in rec.derived:
        return 0
    from .._recordings._derivatives import auto_window

    w = max(auto_window(rec.x[:, i], rec.dt) for i in range(rec.n_dof))
    return int(min(w // 2 + 1, rec.n_samples // 10))


def free_run(model: AbstractMechanicalModel, recording, *, columns: dict | None = None,
             integrator: Integrator | None = None, throw: bool = True) -> Solution:
    """Simulate `model` under `recording`'s measured input and compare with its displacement.

    **Arguments:**

    - `model`: a mechanical model (`load_model`, `reconstruct(...).value`, a system's truth).
    - `recording`: a `Recording` or the path of a recording file (`columns` maps a lab file).
    - `integrator`: tolerances and step budget (default: rtol 1e-7, atol 1e-10, at least 20
      steps per sample).
    - `throw`: raise `GMRComputationError` when the run fails (diverged, step budget).

    **Returns:** a `Solution` whose value is a `FreeRun` and whose `result` is `successful`,
    `diverged` (x left the box of 100 recorded spans around the recorded mean, or turned
    non-finite) or the solver's failure code; `stats["message"]` says it in words.
    """
    if not isinstance(model, AbstractMechanicalModel):
        raise GMRInputError(f"free_run: model must be a mechanical model, got {type(model).__name__}")
    rec = recording if isinstance(recording, Recording) else load_recording(recording, columns)
    rec = validate(rec, rec.name)
    if rec.n_dof != model.n_dof:
        raise GMRInputError(f"free_run: {rec.name} has {rec.n_dof} DOF(s), the model {model.n_dof}")
    rec = rec.complete(model.topology.name)
    b, f = rec.inputs()
    smooth_b, smooth_f = smooth_input(b, rec.dt), smooth_input(f, rec.dt)
    if not rec.driven:  # the contract's free decay, or an input column left out
        notes = ["no input column (base_acc or force): simulated as a free decay from the first state"]
        warnings.warn(rec.free_decay_sentence("the model is run"), GMRDataWarning, stacklevel=2)
    else:
        filtered = not (np.array_equal(smooth_b, b) and np.array_equal(smooth_f, f))
        notes = ["input low-passed at 3x its band edge (it carries white noise), cubic-spline interpolated"
                 if filtered else "input cubic-spline interpolated (no measurable noise on it: not filtered)"]
    if not rec.equilibrium_observed:
        rec = place(model, [rec])[0][0]
        notes.append("x integrated from the recording's " + rec.integration["from"] +
                     "; its equilibrium placed by the model, compared after the same drift removal")
    k = sim_start(rec)
    if k:
        notes.append(f"started at sample {k} (v estimated from x: an interior estimate)")
    _check_scale(model, rec, smooth_b, smooth_f)
    inp = sampled_spline(rec.t, smooth_b, smooth_f, model.n_dof)  # `place` moves x only: the inputs stand
    if integrator is None:
        integrator = SIM if 20 * rec.n_samples <= SIM.max_steps else Integrator(
            rtol=SIM.rtol, atol=SIM.atol, max_steps=int(20 * rec.n_samples))
    xm = rec.x[k:]
    mid, span = xm.mean(0), np.maximum(np.ptp(xm, 0), 1e-12)
    box = (jnp.asarray(mid - BOX_SPANS * span), jnp.asarray(mid + BOX_SPANS * span))
    eps = 1e-3 * float(np.sqrt(np.mean(rec.v**2)))
    m = model.with_sign_eps(eps) if hasattr(model, "with_sign_eps") else model
    sol = simulate(m, inp, jnp.asarray(rec.t[k:]), jnp.asarray(rec.x[k]), jnp.asarray(rec.v[k]),
                   integrator=integrator, box=box, throw=False)
    x = np.asarray(sol.value[0])
    result = sol.result
    if code_name(result) == "successful" and not np.all(np.isfinite(x)):
        result = as_result(RESULTS.diverged._value)
    ok = code_name(result) == "successful"
    if ok and "x" in rec.derived:
        x, xm = comparable(rec, x), comparable(rec, xm)
    nrmse = (np.sqrt(np.sum((x - xm) ** 2, 0) / np.sum((xm - xm.mean(0)) ** 2, 0)) if ok
             else np.full(model.n_dof, np.nan))
    horizon, h_nrmse, crossed = None, None, None
    if "x" not in rec.derived:
        horizon, h_nrmse, failed = horizon_runs(m, inp, rec, k, integrator, box)
        if failed:
            notes.append(f"{failed} of the runs over {horizon:.3g} s failed or diverged (left out of the horizon NRMSE)")
        crossed = np.array([crossings(model, xm, None), crossings(model, xm, x if ok else None)])
    run = FreeRun(t=np.asarray(rec.t[k:]), x=x if ok else np.full_like(xm, np.nan), x_measured=xm,
                  nrmse=nrmse, start=k, name=rec.name, notes=tuple(notes), horizon=horizon, horizon_nrmse=h_nrmse,
                  crossings=crossed)
    what = f"free run of the model on {rec.name}"
    stats = {"result": code_name(result), "message": "" if ok else f"{what}: {message(result)} [{code_name(result)}]",
             "steps": sol.stats.get("num_steps") if isinstance(sol.stats, dict) else None}
    return raise_if_failed(Solution(value=run, result=result, stats=stats), throw, what)


#: `free_run` refuses a recording where the model's accelerations at its states are this many times its own (x''
#: from x), RMS per DOF: the record is in other units than the model (audit: a chain model in m on a record in mm,
#: a degree-11 law read 1000 x out, ran for over 10 minutes without an answer), or far from where the model holds.
#: A model linear in x and v is unit-free (no guard needed there); clean built-in fits on their own records: <= 1.1.
SCALE_LIMIT = 1e3


def _check_scale(model, rec: Recording, b, f) -> None:
    """`SCALE_LIMIT`'s refusal (GMRInputError naming the DOF, the factor and the fix), on up to 2000 recorded
    states; records whose x'' is 0 (a constant DOF) are left to the run."""
    import jax

    from .._recordings._derivatives import differentiate

    idx = np.unique(np.linspace(0, rec.n_samples - 1, min(rec.n_samples, 2000)).round().astype(int))
    acc = np.asarray(jax.vmap(model.accelerations)(jnp.asarray(rec.x[idx]), jnp.asarray(rec.v[idx]),
                                                   jnp.asarray(b[idx]), jnp.asarray(f[idx])))
    own = differentiate(rec.x, rec.dt, 2)[idx]
    for i in range(rec.n_dof):
        m, r = float(np.sqrt(np.mean(acc[:, i] ** 2))), float(np.sqrt(np.mean(own[:, i] ** 2)))
        if r > 0 and not m <= SCALE_LIMIT * r:  # NaN or inf included
            lo, hi = float(rec.x[:, i].min()), float(rec.x[:, i].max())
            raise GMRInputError(
                f"free_run: the model's accelerations at {rec.name}'s recorded states are {m / r:.3g} times the "
                f"record's own (x'' from x, RMS, DOF {i}; x from {lo:.4g} to {hi:.4g}): the recording is not in the "
                f"units the model was fitted in (a record in mm for a model in m reads its law 1000 x out), or lies far "
                f"from where the model holds; give the recording in the model's units (--columns 'x0=COLUMN*1e-3', "
                f"or the unit in the CSV header, 'x0 [mm]')")


def horizon_runs(model, inp, rec: Recording, start: int, integrator: Integrator, box):
    """The model restarted from the recorded state (x, v) every `horizon` seconds from sample
    `start` on and run for `horizon` under the same input (vmapped): `(horizon, nrmse (dof,),
    failed)`, the NRMSE pooled over the runs that succeeded, normalised as `free_run`'s. The
    horizon is the dominant period of the input (of x for a free decay), at least 20 samples and
    at most a quarter of the record."""
    import jax

    from .._recordings._derivatives import dominant_period

    b, f = rec.inputs()
    drive = np.column_stack([b, f])
    sig = drive[:, np.argmax(np.ptp(drive, 0))] if np.ptp(drive) > 0 else rec.x[start:, 0]
    n_total = rec.n_samples - start
    steps = int(round(dominant_period(sig, rec.dt) / rec.dt))
    steps = int(np.clip(steps, 20, max(n_total // 4, 2)))
    firsts = np.arange(start, rec.n_samples - steps, steps)
    local = jnp.arange(steps + 1) * rec.dt

    def one(t0, x0, v0):
        sol = simulate(model, inp, t0 + local, x0, v0, integrator=integrator, box=box, throw=False)
        return sol.value[0], sol.result._value

    xs, codes = jax.vmap(one)(jnp.asarray(rec.t[firsts]), jnp.asarray(rec.x[firsts]), jnp.asarray(rec.v[firsts]))
    xs, codes = np.asarray(xs), np.asarray(codes)
    good = (codes == RESULTS.successful._value) & np.all(np.isfinite(xs), axis=(1, 2))
    measured = np.stack([rec.x[i:i + steps + 1] for i in firsts])
    xm = rec.x[start:]
    denom = np.sum((xm - xm.mean(0)) ** 2, 0) / xm.shape[0]
    if not np.any(good):
        return steps * rec.dt, np.full(rec.n_dof, np.nan), int(firsts.size)
    err = np.mean((xs[good] - measured[good]) ** 2, axis=(0, 1))
    return steps * rec.dt, np.sqrt(err / denom), int(np.sum(~good))


def crossings(model, x_measured, x) -> np.ndarray:
    """Per DOF, the well-to-well crossings of `x` (n, dof) (of `x_measured` where `x` is None; -1
    where `x` is NaN or the model has fewer than two stable wells within the recorded range widened
    by a quarter of it): a crossing is counted when x passes halfway from the saddle to the
    neighbouring well (hysteresis: noise about a saddle is not a crossing)."""
    from ..metrics._metrics import equilibria

    xm = np.asarray(x_measured, float)
    sig = xm if x is None else np.asarray(x, float)
    out = np.full(xm.shape[1], -1)
    if not np.all(np.isfinite(sig)):
        return out
    for i in range(xm.shape[1]):
        lo, hi = float(xm[:, i].min()), float(xm[:, i].max())
        pad = 0.25 * (hi - lo)
        roots = equilibria(model, i, (lo - pad, hi + pad))
        wells = [r for r, stable in roots if stable]
        if len(wells) < 2:
            continue
        saddles = [next((r for r, st in roots if not st and a < r < b), 0.5 * (a + b)) for a, b in zip(wells, wells[1:])]
        up = [0.5 * (sd + w) for sd, w in zip(saddles, wells[1:])]  # from well j to j + 1
        down = [0.5 * (sd + w) for sd, w in zip(saddles, wells[:-1])]  # from well j + 1 to j
        state, n = int(np.argmin(np.abs(np.asarray(wells) - sig[0, i]))), 0
        for v in sig[:, i]:
            while state < len(up) and v > up[state]:
                state, n = state + 1, n + 1
            while state > 0 and v < down[state - 1]:
                state, n = state - 1, n + 1
        out[i] = n
    return out
