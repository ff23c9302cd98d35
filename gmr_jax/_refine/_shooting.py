"""Multiple shooting: recordings cut into fixed-length windows, each simulated from its measured
start state, so that a poor model cannot drift (or diverge) over a whole long record."""

from dataclasses import dataclass

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._errors import GMRInputError
from .._model._model import AbstractMechanicalModel
from .._recordings._recording import Recording, validate
from .._simulate._inputs import Sampled
from .._simulate._integrate import Integrator, integrate, vector_field
from .._solution import RESULTS, Solution, as_result, code_name, raise_if_failed


class Windows(eqx.Module):
    """Windows of one length (one shape), stacked for vmap.

    **Attributes:** `t` (W, L) sample times; `x` (W, L, D) measured displacements; `v0` (W, D)
    measured velocity at each window's first sample; `base_acc` (W, L); `force` (W, L, D);
    `scale` (W, D) per-DOF standard deviation of x over the window's recording (residual
    scale); `vscale` (W, D) that of v (bounds `fit_starts`' step); `lo`, `hi` (W, D) the
    divergence box (data range widened by `box_ranges` ranges);
    `record` (W,) index of the recording each window comes from.
    """

    t: Float[Array, "win samples"]
    x: Float[Array, "win samples dof"]
    v0: Float[Array, "win dof"]
    base_acc: Float[Array, "win samples"]
    force: Float[Array, "win samples dof"]
    scale: Float[Array, "win dof"]
    vscale: Float[Array, "win dof"]
    lo: Float[Array, "win dof"]
    hi: Float[Array, "win dof"]
    record: np.ndarray = eqx.field(static=True, converter=lambda a: tuple(np.asarray(a).tolist()))

    @property
    def n_windows(self) -> int:
        return int(self.t.shape[0])


def prepare(recordings, n_dof: int, topology: str, src: str = "recording") -> list[Recording]:
    """Validate recordings against a model of `n_dof` DOFs and fill a missing `v` from `x`."""
    if isinstance(recordings, Recording):
        recordings = [recordings]
    recordings = list(recordings)
    if not recordings:
        raise GMRInputError(f"no {src}s given: refinement needs at least one recording")
    out = []
    for k, rec in enumerate(recordings):
        name = f"{src} {k} ({rec.name})"
        rec = validate(rec, name)
        if not rec.equilibrium_observed:
            raise GMRInputError(
                f"{name}: x was integrated from {rec.integration['from']}, so the equilibrium it vibrated about "
                f"is unobservable, and simulated trajectories cannot be compared with it; give the recording's "
                f"'equilibrium' (the static displacement), or record x")
        if rec.n_dof != n_dof:
            raise GMRInputError(
                f"{name}: 'x' has {rec.n_dof} DOF column(s) but the model has {n_dof} DOFs; "
                f"give recordings of the same structure as the model"
            )
        std = np.std(rec.x, axis=0)
        if np.any(std <= 0):
            raise GMRInputError(f"{name}: DOF {int(np.argmin(std))} is constant; nothing to fit to")
        if rec.v is None:
            rec = rec.complete(topology)
        out.append(rec)
    return out


def make_windows(
    recordings: list[Recording], window: float | None, box_ranges: float, max_windows: int | None = None
) -> list[Windows]:
    """Cut validated recordings into non-overlapping windows of `window` seconds (None: the
    whole record, one window each); windows of equal sample count are stacked together.
    `max_windows` keeps at most that many per recording, evenly spread."""
    groups: dict[int, list] = {}
    for k, rec in enumerate(recordings):
        n = rec.n_samples
        if window is None:
            length = n
        else:
            length = int(round(window / rec.dt)) + 1
            if length < 3:
                raise GMRInputError(f"window {window} s is shorter than 2 samples of {rec.name} (dt {rec.dt} s)")
            if length > n:
                raise GMRInputError(
                    f"window {window} s is longer than recording {rec.name} ({(n - 1) * rec.dt:.3g} s); "
                    f"use a shorter window"
                )
        starts = np.arange(0, n - length + 1, length - 1)
        if max_windows is not None and starts.size > max_windows:
            starts = starts[np.unique(np.round(np.linspace(0, starts.size - 1, max_windows)).astype(int))]
        b, f = rec.inputs()
        std = np.std(rec.x, axis=0)
        lo_d, hi_d = rec.x.min(axis=0), rec.x.max(axis=0)
        span = np.maximum(hi_d - lo_d, 1e-12)
        idx = starts[:, None] + np.arange(length)[None, :]
        g = groups.setdefault(length, [])
        for i, s in enumerate(starts):
            g.append(dict(t=rec.t[idx[i]], x=rec.x[idx[i]], v0=rec.v[s], base_acc=b[idx[i]], force=f[idx[i]],
                          scale=std, vscale=np.maximum(np.std(rec.v, axis=0), 1e-300), lo=lo_d - box_ranges * span,
                          hi=hi_d + box_ranges * span, record=k))
    out = []
    for length in sorted(groups):
        g = groups[length]
        out.append(Windows(**{key: jnp.asarray(np.stack([w[key] for w in g])) for key in
                              ("t", "x", "v0", "base_acc", "force", "scale", "vscale", "lo",
                                                                    "hi")},
                           record=np.array([w["record"] for w in g])))
    return out


def solve_window(
    model: AbstractMechanicalModel,
    t: Float[Array, " samples"],
    x0: Float[Array, " dof"],
    v0: Float[Array, " dof"],
    base_acc: Float[Array, " samples"],
    force: Float[Array, "samples dof"],
    lo: Float[Array, " dof"],
    hi: Float[Array, " dof"],
    stride: int,
    integrator: Integrator,
    adjoint: dfx.AbstractAdjoint,
) -> tuple[Float[Array, "saved dof"], Int[Array, ""]]:
    """Simulate one window from its measured start state (x0, v0) under the sampled inputs.

    Saves x at `t[stride::stride]`. Returns (x, ok): `ok` is false if the solver failed, hit
    `max_steps`, or the state left the box [lo, hi] (then the solve stops there; x is not
    meaningful and the caller must not use it)."""
    d = x0.shape[0]
    inputs = Sampled(t=t, base_acc=base_acc, force=force, n_dof=d)
    ts = t[stride::stride]
    # the sampled input is piecewise linear: land a step on every sample (its kinks)
    traj = integrate(vector_field(model, inputs), t[0], ts[-1], (x0, v0), integrator, saveat=dfx.SaveAt(ts=ts),
                     box=(lo, hi), step_ts=t, adjoint=adjoint)
    return traj.ys[0], traj.result._value


def simulate_windows(model, w: Windows, stride: int, integrator: Integrator, adjoint,
                     starts: Float[Array, "win state"] | None = None) -> tuple[Array, Array]:
    """vmap of `solve_window` over a `Windows` group: x (W, saved, D), RESULTS values (W,).
    `starts` (W, 2D): each window's (x0, v0); None: the measured ones (`measured_starts`)."""
    s = measured_starts(w) if starts is None else starts
    d = w.x.shape[-1]

    def one(t, s_, b, f, lo, hi):
        return solve_window(model, t, s_[:d], s_[d:], b, f, lo, hi, stride, integrator, adjoint)

    return jax.vmap(one)(w.t, s, w.base_acc, w.force, w.lo, w.hi)


def measured_starts(w: Windows) -> Float[Array, "win state"]:
    """Each window's measured start state (x at its first sample, v0), stacked as (W, 2D)."""
    return jnp.concatenate([w.x[:, 0], w.v0], axis=-1)


#: Residual (in units of the DOF's standard deviation) given to every sample of a window whose
#: simulation failed or left the divergence box: large, constant, with zero derivative, so that
#: a step into divergence is rejected by the trust region instead of producing NaN gradients.
FAILED_WINDOW_RESIDUAL = 10.0

#: Gauss-Newton iterations of `fit_starts` from the measured start state (the window's x is
#: nearly linear in its start state over a window of a period or less: two suffice on the tests'
#: cases, the third is a margin).
START_ITERATIONS = 3
#: `fit_starts` keeps each start within this many standard deviations of x (and of v) of the
#: measured one: noise moves a start by a few percent of them; a model far from the data would
#: otherwise buy a lower misfit with a start far off (the joint 15 % too stiff: v0 moved by 9
#: standard deviations, then the window diverged).
START_BOX = 0.5


def window_residuals(model, w: Windows, starts, stride: int, integrator: Integrator, adjoint,
                     failed: float) -> tuple[Float[Array, "win res"], Array, Array]:
    """Residuals of every window from `starts` (W, 2D): (x0 - measured x at the first sample,
    simulated - measured x at `t[stride::stride]`) over the recording's std, flattened per
    window (the first D entries are the start's misfit); a failed window's simulated part is the
    constant `failed`. Returns (W, R), ok (W,) and the RESULTS values (W,)."""
    d = w.x.shape[-1]
    xs, codes = simulate_windows(model, w, stride, integrator, adjoint, starts)
    ok = codes == RESULTS.successful._value
    e = (xs - w.x[:, stride::stride]) / w.scale[:, None, :]
    e = jnp.where(ok[:, None, None], e, failed)
    e0 = (starts[:, :d] - w.x[:, 0]) / w.scale
    return jnp.concatenate([e0[:, None, :], e], axis=1).reshape(e.shape[0], -1), ok, codes


def fit_starts(model, w: Windows, stride: int, integrator: Integrator, failed: float,
               iterations: int = START_ITERATIONS) -> Float[Array, "win state"]:
    """Each window's start state (x0, v0) that fits its measured x best under `model`: Gauss-Newton
    from the measured start (`iterations` steps; the best state seen is kept, so a step into a
    failed solve is undone). Not differentiated (used under `stop_gradient`).

    Why: a measured x0 carries the sensor's noise, and a v0 estimated from x the derivative's
    error; a window that must start there bends the coefficients to absorb it (an exact linear
    oscillator refined on x-only 30 dB data: damping +7 %). Fitting the start with the window's
    samples removes that errors-in-variables bias (output-error identification with estimated
    initial states). Each start stays within `START_BOX` standard deviations of the measured one."""
    model = jax.lax.stop_gradient(model)
    adj = dfx.ForwardMode()

    def one_window(wi, s0):
        w1 = jax.tree_util.tree_map(lambda a: a[None], wi)
        half = START_BOX * jnp.concatenate([wi.scale, wi.vscale])

        def res(s):
            r, ok, _ = window_residuals(model, w1, s[None], stride, integrator, adj, failed)
            return r[0], (r[0], ok[0])

        def step(carry, _):
            s, best, best_c = carry
            jac, (r, ok) = jax.jacfwd(res, has_aux=True)(s)
            c = jnp.where(ok, r @ r, jnp.inf)
            better = c < best_c
            best, best_c = jnp.where(better, s, best), jnp.where(better, c, best_c)
            ds = jnp.linalg.lstsq(jac, -r)[0]
            nxt = jnp.where(ok & jnp.all(jnp.isfinite(ds)), jnp.clip(s + ds, s0 - half, s0 + half), best)
            return (nxt, best, best_c), None

        (s, best, best_c), _ = jax.lax.scan(step, (s0, s0, jnp.inf), None, length=iterations)
        r, ok, _ = window_residuals(model, w1, s[None], stride, integrator, adj, failed)
        c = jnp.where(ok[0], r[0] @ r[0], jnp.inf)
        return jnp.where(c < best_c, s, best)

    return jax.vmap(one_window)(w, measured_starts(w))


@dataclass(frozen=True)
class OutputError:
    """Output error of a model on recordings: `nrmse` is the RMS over all windows, samples and
    DOFs of (simulated x - measured x) / std of the recording's x for that DOF (inf if any
    window failed); `failed` windows out of `windows`."""

    nrmse: float
    failed: int
    windows: int

    def as_dict(self) -> dict:
        return {"nrmse": self.nrmse, "failed": self.failed, "windows": self.windows}


@eqx.filter_jit
def _window_errors(model, groups, stride, integrator, estimated):
    out = []
    for w in groups:
        s = fit_starts(model, w, stride, integrator, FAILED_WINDOW_RESIDUAL) if estimated else measured_starts(w)
        r, ok, codes = window_residuals(model, w, s, stride, integrator, dfx.ForwardMode(), 0.0)  # no AD here
        if not estimated:  # the recorded start's misfit is 0 by construction: not a sample of the error
            r = r[:, w.x.shape[-1]:]
        out.append((jnp.sum(jnp.where(ok[:, None], r, 0.0) ** 2, axis=1), r.shape[1], codes))
    return out


#: What `output_error` and `refine` start each window from: "measured" (x and v at its first
#: sample, v estimated from x when not recorded) or "estimated" (`fit_starts`).
STARTS = ("measured", "estimated")


def check_starts(starts: str) -> bool:
    """True for "estimated"; a clear error for anything but `STARTS`."""
    if starts not in STARTS:
        raise GMRInputError(f"starts must be one of {', '.join(map(repr, STARTS))}, got {starts!r}")
    return starts == "estimated"


def output_error(
    model: AbstractMechanicalModel,
    recordings,
    window: float | None = None,
    *,
    integrator: Integrator = Integrator(rtol=1e-8, atol=1e-10, max_steps=100_000),
    box_ranges: float = 10.0,
    max_windows: int | None = None,
    starts: str = "measured",
    throw: bool = False,
) -> Solution:
    """Output NRMSE of `model` on `recordings`: simulated in windows of `window` seconds (None:
    each whole record from its first sample), compared with the measured x (see
    `OutputError`). The model is used as given (exact sgn(v) if `sign_eps=0`).

    `starts`: "measured" (default) starts each window from the recorded state (x and v at its
    first sample); "estimated" from the state that fits the window's x best under the model
    (`fit_starts`; its misfit at the first sample counts): the error then measures the model,
    not the noise of one recorded sample, which matters on noisy x with v estimated from it.

    **Returns:** a `Solution` whose `value` is an `OutputError` (nrmse inf when a window
    failed), `result` the first failed window's code (`diverged`: it left the data range
    widened by `box_ranges` ranges; `max_steps_reached`, ...), `stats["codes"]` every window's
    code name. `throw` (default False: a model that cannot follow the data is an answer here)
    raises `GMRComputationError` instead."""
    estimated = check_starts(starts)
    recs = prepare(recordings, model.n_dof, model.topology)
    groups = make_windows(recs, window, box_ranges, max_windows)
    res = _window_errors(model, groups, 1, integrator, estimated)
    codes = np.concatenate([np.asarray(c).reshape(-1) for *_, c in res])
    ok_all = codes == RESULTS.successful._value
    sq = sum(float(np.sum(np.asarray(s)[np.asarray(c) == RESULTS.successful._value])) for s, _, c in res)
    cnt = sum(int(np.sum(np.asarray(c) == RESULTS.successful._value)) * n for _, n, c in res)
    failed = int(np.sum(~ok_all))
    nrmse = float(np.sqrt(sq / cnt)) if failed == 0 and cnt else float("inf")
    err = OutputError(nrmse=nrmse, failed=failed, windows=int(codes.size))
    result = as_result(int(codes[~ok_all][0])) if failed else RESULTS.successful
    sol = Solution(value=err, result=result, stats={"codes": [code_name(c) for c in codes]})
    return raise_if_failed(sol, throw, "output_error", f"{failed} of {codes.size} windows")
