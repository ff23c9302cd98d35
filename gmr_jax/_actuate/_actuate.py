"""Actuation design: the smallest tip load that deploys a chain into a requested configuration.

Two load families (the `gmr actuate` contract):

- `kind="half_sine"`: the paper's Eq. (25) tip force A sin(2 pi f t), t <= 1/(2f); peak = A.
- `kind="samples"`: a tip force history on `n_knots` equally spaced samples over a duration,
  linearly interpolated, zero after the last sample; peak = max |u_k|.

Method (half_sine). The target's region in the (f, A) plane is bounded below by a basin
boundary A*(f); the cheapest actuation sits on it. (1) A coarse `basin_map` (n_f log-spaced frequencies x n_A
amplitudes) seeds: in every f column the lowest amplitude that reaches the target, with the grid point
below it as a bracket. (2) The `n_seeds` best columns are bisected in A (all at once, vmapped)
down to `A_rtol`. (3) Each seed walks along its boundary: the gradient of the smooth terminal
margin (`_surrogate.py`; reverse mode through diffrax, `RecursiveCheckpointAdjoint`, the
switch-off time 1/(2f) declared to the step-size controller) gives the boundary's normal, hence
its slope dA*/df = -(dm/df)/(dm/dA) and the objective's derivative along it; a step in f is
predicted with that slope, re-bracketed and bisected, accepted when the objective drops (trust
step grown x1.5) and otherwise halved. (4) The best candidates are verified by plain simulation
with the exact model (`simulate`, tighter tolerances) and the basin map's own classifier; the
first that reaches the target is returned.

Method (samples). Starts from the half_sine optimum sampled on the knots; keeps the history on
the boundary by bisecting a scale factor s (s u reaches the target, a slightly smaller s does
not) and moves it along the boundary: the step is minus the gradient of a smooth peak
(L_p norm of the knots, p = `p_norm`, or the effort integral) projected onto the boundary's
tangent plane (normal = gradient of the terminal margin wrt the knots). Verified as above.

Objectives: `"peak"` (max |F|, N) or `"effort"` (the integral of F(t)^2 dt, N^2 s).
"""

import dataclasses
import math

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._config import relieve_map_pressure
from .._errors import GMRInputError
from .._solution import RESULTS, Solution, code_name, raise_if_failed
from .._basins._sweep import SweepSettings, _final_state, basin_map, classify
from .._basins._wells import stable_wells
from .._model._model import AbstractMechanicalModel
from .._simulate._inputs import HalfSineTip, Sampled
from .._simulate._integrate import Integrator, integrate, vector_field
from .._simulate._simulate import simulate
from ._surrogate import bits_to_config, parse_target, saddles, smooth_model, terminal_margin

KINDS = ("half_sine", "samples")
OBJECTIVES = ("peak", "effort")


class ActuateSettings(eqx.Module):
    """Search settings of `actuate`.

    - `f_range`, `A_range`: the half-sine search box (Hz, force units).
    - `n_f`, `n_A`: the coarse seeding grid (n_f x n_A solves).
    - `n_seeds`: grid columns refined (bisection + walk along the boundary).
    - `A_rtol`: relative bracket width at which a bisection stops.
    - `max_walk`: gradient steps along the boundary per seed.
    - `objective`: `"peak"` (max |F|) or `"effort"` (integral of F^2 dt).
    - `sweep`: how each outcome is simulated and classified (settle time, tolerances, x_tol, v_tol):
      the same `SweepSettings` as `basin_map`.
    - `sign_eps`: sgn(v) -> tanh(v / sign_eps) inside differentiated solves (only for models with
      sgn(v) terms; velocity units). Outcomes always use the exact model.
    - `tau`: soft-minimum temperature of the terminal margin (in half interwell distances).
    - `grad_max_steps`: step budget of a differentiated solve.
    - `n_knots`, `duration`, `p_norm`, `max_iter_samples`: the `"samples"` history (duration
      None: twice the half-sine optimum's load time 1/(2f)), the smooth peak's L_p order, and its
      iterations.
    - `verify`: integrator of the verifying simulation (exact model).
    """

    f_range: tuple[float, float] = (0.1, 5.0)
    A_range: tuple[float, float] = (0.02, 1.0)
    n_f: int = 24
    n_A: int = 24
    n_seeds: int = 6
    A_rtol: float = 2e-3
    max_walk: int = 20
    objective: str = "peak"
    sweep: SweepSettings = SweepSettings()
    sign_eps: float = 1e-3
    tau: float = 0.05
    grad_max_steps: int = 20_000
    n_knots: int = 24
    duration: float | None = None
    p_norm: float = 16.0
    max_iter_samples: int = 10
    verify: Integrator = Integrator(rtol=1e-8, atol=1e-10, max_steps=200_000)


class Actuation(eqx.Module):
    """A designed tip load. `kind` "half_sine": `f`, `A` (Eq. 25); "samples": `t`, `force`
    (linearly interpolated, zero after the last sample). `peak` = max |F| and `effort` = the
    integral of F(t)^2 dt of the load."""

    kind: str
    f: float | None = None
    A: float | None = None
    t: np.ndarray | None = None
    force: np.ndarray | None = None
    peak: float = math.nan
    effort: float = math.nan

    def to_json(self) -> dict:
        if self.kind == "half_sine":
            out = {"kind": "half_sine", "f": float(self.f), "A": float(self.A)}
        else:
            out = {"kind": "samples", "t": np.asarray(self.t).tolist(), "force": np.asarray(self.force).tolist()}
        out.update(peak=float(self.peak), effort=float(self.effort))
        return out

    def inputs(self, n_dof: int):
        """The load as a `gmr_jax` input (tip force on the last mass)."""
        if self.kind == "half_sine":
            return HalfSineTip(jnp.asarray(self.f), jnp.asarray(self.A), n_dof=n_dof)
        return _tip_samples(jnp.asarray(self.t), jnp.asarray(self.force), n_dof)

    @property
    def load_time(self) -> float:
        return 0.5 / float(self.f) if self.kind == "half_sine" else float(np.asarray(self.t)[-1])


def _traced(sweep: SweepSettings) -> SweepSettings:
    """The sweep settings with every float as an array: new settle times or tolerances reuse the
    compiled solves (`max_steps` stays static)."""
    return jax.tree.map(lambda v: jnp.asarray(v, float), sweep)


def _tip_samples(t, u, n_dof):
    force = jnp.zeros((t.shape[0], n_dof)).at[:, -1].set(u)
    return Sampled(t=t, base_acc=jnp.zeros_like(t), force=force, n_dof=n_dof)


def _half_sine_effort(f, A):
    return A**2 / (4.0 * f)


def _samples_effort(t, u):
    """Exact integral of the squared piecewise-linear history."""
    dt = jnp.diff(t)
    return jnp.sum(dt / 3.0 * (u[:-1] ** 2 + u[:-1] * u[1:] + u[1:] ** 2))


# -- jitted solves ------------------------------------------------------------------------------


def _geometry(wells):
    span = jnp.nanmax(wells, axis=1) - jnp.nanmin(wells, axis=1)
    span = jnp.where(span > 0, span, 1.0)
    centre = 0.5 * (jnp.nanmax(wells, axis=1) + jnp.nanmin(wells, axis=1))
    return span, centre


@eqx.filter_jit
def _hs_outcomes(model, sweep, x0, wells, f, A):
    """Configuration (and code) reached under half-sines (f[k], A[k]) with the exact model."""
    span, centre = _geometry(wells)

    def one(fa):
        x1, v1, code = _final_state(model, sweep, x0, fa[0], fa[1], centre, span)
        _, config, code = classify(x1, v1, code, wells, span, sweep)
        return config, code

    return jax.vmap(one)(jnp.stack([f, A], axis=1))


def _final_generic(model, sweep, x0, inp, jumps, t1, centre, span, max_steps, event=True):
    integrator = dataclasses.replace(sweep.integrator, max_steps=max_steps)
    box = (centre - sweep.box_spans * span, centre + sweep.box_spans * span) if event else None
    traj = integrate(vector_field(model, inp), 0.0, t1, (x0, jnp.zeros_like(x0)), integrator,
                     saveat=dfx.SaveAt(t1=True), box=box, jump_ts=jumps)
    return traj.ys[0][-1], traj.ys[1][-1], traj.result._value


@eqx.filter_jit
def _samples_outcomes(model, sweep, x0, wells, t, U):
    """Configuration reached under tip histories U[k] on knots t (exact model)."""
    span, centre = _geometry(wells)
    d = x0.shape[0]

    def one(u):
        x1, v1, code = _final_generic(model, sweep, x0, _tip_samples(t, u, d), t, t[-1] + sweep.settle_time,
                                      centre, span, sweep.integrator.max_steps)
        _, config, code = classify(x1, v1, code, wells, span, sweep)
        return config, code

    return jax.vmap(one)(U)


@eqx.filter_jit
def _hs_margin_grad(model_s, sweep, x0, wells, sigma, saddle, tau, max_steps, p):
    """Terminal margin and its gradient wrt p = (f, A) (smoothed model, reverse mode)."""
    span, centre = _geometry(wells)
    d = x0.shape[0]

    def m(p):
        f, a = p[0], p[1]
        t_off = 0.5 / f
        x1, _, _ = _final_generic(model_s, sweep, x0, HalfSineTip(f, a, n_dof=d), jnp.reshape(t_off, (1,)),
                                  t_off + sweep.settle_time, centre, span, max_steps, event=False)
        return terminal_margin(x1, sigma, saddle, 0.5 * span, tau)

    return jax.value_and_grad(m)(p)


@eqx.filter_jit
def _samples_margin_grad(model_s, sweep, x0, wells, sigma, saddle, tau, max_steps, t, u):
    span, centre = _geometry(wells)
    d = x0.shape[0]

    def m(u):
        x1, _, _ = _final_generic(model_s, sweep, x0, _tip_samples(t, u, d), t, t[-1] + sweep.settle_time,
                                  centre, span, max_steps, event=False)
        return terminal_margin(x1, sigma, saddle, 0.5 * span, tau)

    return jax.value_and_grad(m)(u)


def terminal_margin_half_sine(model, wells, target, f, A, *, settings: ActuateSettings = ActuateSettings(),
                              x0=None):
    """The smooth terminal surrogate m(f, A) and its gradient (for inspection and tests).

    **Returns:** `(m, (dm/df, dm/dA))`, computed on the smoothed model (see `_surrogate.py`)."""
    wells = jnp.asarray(wells, float)
    bits = parse_target(target, model.n_dof)
    x0 = wells[:, 0] if x0 is None else jnp.asarray(x0, float)
    sigma = jnp.asarray(2.0 * bits - 1.0)
    sad = jnp.asarray(saddles(model, np.asarray(wells)))
    m, g = _hs_margin_grad(smooth_model(model, settings.sign_eps), _traced(settings.sweep), x0, wells, sigma, sad,
                           jnp.asarray(settings.tau, float), settings.grad_max_steps, jnp.asarray([f, A], float))
    return float(m), (float(g[0]), float(g[1]))


# -- the driver ---------------------------------------------------------------------------------


@dataclasses.dataclass
class _Problem:
    model: AbstractMechanicalModel
    model_s: AbstractMechanicalModel
    settings: ActuateSettings
    wells: jnp.ndarray
    x0: jnp.ndarray
    sigma: jnp.ndarray
    saddle: jnp.ndarray
    config: int
    counts: dict
    batch: int = 2

    @property
    def sweep(self):
        return _traced(self.settings.sweep)

    @property
    def tau(self):
        return jnp.asarray(self.settings.tau, float)

    def hs_reach(self, f, A):
        """Whether each (f[k], A[k]) reaches the target (exact model). Evaluated in padded batches
        of one fixed size, so that one compilation serves every call."""
        f = np.atleast_1d(np.asarray(f, float))
        A = np.atleast_1d(np.asarray(A, float))
        n, b = f.shape[0], self.batch
        out = []
        for k in range(0, n, b):
            fk, ak = f[k:k + b], A[k:k + b]
            pad = b - fk.shape[0]
            fk = np.concatenate([fk, np.full(pad, fk[0])])
            ak = np.concatenate([ak, np.full(pad, ak[0])])
            conf, _ = _hs_outcomes(self.model, self.sweep, self.x0, self.wells, jnp.asarray(fk),
                                   jnp.asarray(ak))
            out.append(np.asarray(conf)[: b - pad])
        self.counts["forward"] += n
        return np.concatenate(out) == self.config

    def hs_grad(self, f, A):
        s = self.settings
        m, g = _hs_margin_grad(self.model_s, self.sweep, self.x0, self.wells, self.sigma, self.saddle, self.tau,
                               s.grad_max_steps, jnp.asarray([f, A], float))
        self.counts["gradient"] += 1
        return float(m), np.asarray(g)

    def s_reach(self, t, U):
        U = jnp.atleast_2d(jnp.asarray(U, float))
        conf, _ = _samples_outcomes(self.model, self.sweep, self.x0, self.wells, jnp.asarray(t), U)
        self.counts["forward"] += int(U.shape[0])
        return np.asarray(conf) == self.config

    def s_grad(self, t, u):
        s = self.settings
        m, g = _samples_margin_grad(self.model_s, self.sweep, self.x0, self.wells, self.sigma, self.saddle, self.tau,
                                    s.grad_max_steps, jnp.asarray(t), jnp.asarray(u, float))
        self.counts["gradient"] += 1
        return float(m), np.asarray(g)

    def hs_cost(self, f, A):
        return A if self.settings.objective == "peak" else float(_half_sine_effort(f, A))


def _bisect_A(prob: _Problem, f, lo, hi):
    """Bisect each bracket [lo, hi] (lo misses, hi reaches the target) in A, all at once."""
    f, lo, hi = (np.asarray(z, float).copy() for z in (f, lo, hi))
    while np.any((hi - lo) > prob.settings.A_rtol * hi):
        mid = 0.5 * (lo + hi)
        active = (hi - lo) > prob.settings.A_rtol * hi
        ok = prob.hs_reach(f[active], mid[active])
        idx = np.nonzero(active)[0]
        hi[idx[ok]] = mid[idx[ok]]
        lo[idx[~ok]] = mid[idx[~ok]]
    return lo, hi


def _bracket_near(prob: _Problem, f, a_pred, w):
    """Lower edge of the target region near amplitude a_pred at frequency f: a ladder of four
    amplitudes over a_pred -/+ w (one padded batch; thin target bands are not stepped over),
    extended downwards while its lowest rung still reaches the target, then bisected."""
    a_min, a_max = prob.settings.A_range
    ladder = np.clip(a_pred + w * np.array([-1.0, -1.0 / 3.0, 1.0 / 3.0, 1.0]), a_min, a_max)
    r = prob.hs_reach(np.full(4, f), ladder)
    if not r.any():
        return None
    k = int(np.argmax(r))
    if k > 0:
        lo, hi = _bisect_A(prob, [f], [ladder[k - 1]], [ladder[k]])
        return lo[0], hi[0]
    hi = ladder[0]
    for _ in range(3):
        if hi <= a_min:
            return a_min, a_min
        lo = max(a_min, hi - 2 * w)
        if not prob.hs_reach([f], [lo])[0]:
            lo, hi = _bisect_A(prob, [f], [lo], [hi])
            return lo[0], hi[0]
        hi = lo
    return None


def _walk(prob: _Problem, f, lo, hi, h):
    """Move a bisected boundary point along its boundary to lower cost (see module docstring)."""
    s = prob.settings
    f_lo, f_hi = s.f_range
    a_min = s.A_range[0]
    h_min = 1e-3 * (f_hi - f_lo)
    cost = prob.hs_cost(f, hi)
    for _ in range(s.max_walk):
        if h < h_min or lo <= a_min:
            break
        _, g = prob.hs_grad(f, hi)
        if not np.all(np.isfinite(g)) or g[1] == 0.0:
            break
        slope = -g[0] / g[1]  # dA*/df along the boundary
        if s.objective == "peak":
            dcost = slope
        else:
            dcost = (2 * hi * slope) / (4 * f) - hi**2 / (4 * f**2)
        if not np.isfinite(dcost) or dcost == 0.0:
            break
        moved = False
        while h >= h_min and not moved:
            f_new = float(np.clip(f - np.sign(dcost) * h, f_lo, f_hi))
            if f_new == f:
                h = 0.0
                break
            a_pred = hi + slope * (f_new - f)
            w = max(0.75 * abs(slope * (f_new - f)), 4 * s.A_rtol * abs(a_pred))
            br = _bracket_near(prob, f_new, a_pred, w)
            if br is None:
                h *= 0.5
                continue
            n_lo, n_hi = br
            new_cost = prob.hs_cost(f_new, n_hi)
            if new_cost < cost:
                f, lo, hi, cost = f_new, n_lo, n_hi, new_cost
                h *= 1.5
                moved = True
            else:
                h *= 0.5
        if not moved:
            break
    return f, lo, hi


def _verify(prob: _Problem, act: Actuation):
    """Plain simulation with the exact model, classified as `basin_map` does."""
    s = prob.settings
    d = prob.x0.shape[0]
    t1 = act.load_time + s.sweep.settle_time
    sol = simulate(prob.model, act.inputs(d), jnp.asarray([0.0, t1]), prob.x0, integrator=s.verify, throw=False)
    prob.counts["verify"] += 1
    span, _ = _geometry(prob.wells)
    x1, v1 = sol.value[0][-1], sol.value[1][-1]
    idx, config, code = classify(x1, v1, sol.result._value, prob.wells, span, s.sweep)
    return np.asarray(idx), int(config), np.asarray(x1), code_name(int(code))


def _half_sine(prob: _Problem):
    s = prob.settings
    fs = np.geomspace(*s.f_range, s.n_f)  # log-spaced: the cheap loads sit at the low, resonant end
    As = np.linspace(*s.A_range, s.n_A)
    bm = basin_map(prob.model, fs, As, np.asarray(prob.wells), x0=prob.x0, settings=prob.sweep, throw=False).value
    prob.counts["forward"] += s.n_f * s.n_A
    prob.counts["seed_grid"] = s.n_f * s.n_A
    hit = np.asarray(bm.config) == prob.config  # (n_A, n_f)
    seeds = []
    for j in range(s.n_f):
        rows = np.nonzero(hit[:, j])[0]
        if rows.size:
            i = rows[0]
            seeds.append((prob.hs_cost(fs[j], As[i]), fs[j], As[i - 1] if i > 0 else None, As[i]))
    if not seeds:
        return [], bm
    seeds.sort(key=lambda z: z[0])
    seeds = seeds[: s.n_seeds]
    floor = [z for z in seeds if z[2] is None]
    brk = [z for z in seeds if z[2] is not None]
    cands = [(z[1], z[3], z[3]) for z in floor]
    if brk:
        lo, hi = _bisect_A(prob, [z[1] for z in brk], [z[2] for z in brk], [z[3] for z in brk])
        ratio = (fs[1] / fs[0]) if s.n_f > 1 else 1.1
        for z, a_lo, a_hi in zip(brk, lo, hi):
            cands.append(_walk(prob, z[1], a_lo, a_hi, 0.5 * (ratio - 1.0) * z[1]))
    return [(prob.hs_cost(f, hi), f, hi) for f, _, hi in cands], bm


def _finish(prob: _Problem, act: Actuation, verified, extra: dict, code):
    idx, config, x1, how = verified if verified is not None else (None, -1, None, None)
    c = prob.counts
    stats = {
        "forward_solves": c["forward"], "gradient_evaluations": c["gradient"], "verify_solves": c["verify"],
        "seed_grid_solves": c.get("seed_grid", 0),
        "solves": c["forward"] + 2 * c["gradient"] + c["verify"],
        "verified_wells": None if idx is None else idx.tolist(),
        "verified_config": config, "target_config": prob.config,
        # "not_settled": the verifying simulation was still moving at t1 (a longer settle time decides it)
        "verified_result": how,
        "x_final": None if x1 is None else x1.tolist(),
        **extra,
    }
    return Solution(value=act, result=code, stats=stats)


def _verified_candidates(prob, cands, make):
    """Verify candidates cheapest first (bumping each by A_rtol up to twice); first success wins."""
    tried = None
    for _, *p in sorted(cands, key=lambda z: z[0]):
        for bump in range(3):
            act = make(*p, 1.0 + bump * prob.settings.A_rtol)
            ver = _verify(prob, act)
            tried = (act, ver) if tried is None else tried
            if ver[1] == prob.config:
                return act, ver, True
    return tried[0], tried[1], False


def actuate(
    model: AbstractMechanicalModel,
    target,
    *,
    kind: str = "half_sine",
    settings: ActuateSettings = ActuateSettings(),
    wells=None,
    x_range=None,
    x0=None,
    throw: bool = True,
) -> Solution:
    """Design the cheapest tip load that deploys the chain from `x0` into `target`.

    **Arguments:**

    - `model`: any mechanical model (reconstructed `GlobalModel` or a truth model).
    - `target`: `"0-1-1-0-0"` (cell 0 at the base first), `"01100"`, a 0/1 sequence or a bit field.
    - `kind`: `"half_sine"` (Eq. 25, optimise f and A) or `"samples"` (a tip force history).
    - `settings`: `ActuateSettings` (search box, objective, settle time, smoothing...).
    - `wells`: (dof, 2) stable equilibria per cell (default `stable_wells(model, x_range)`).
    - `x0`: start at rest (default: every cell in its first well).

    **Returns:** a `Solution` whose `value` is an `Actuation` (kind, parameters, peak, effort),
    `result` an `RESULTS` code (`target_not_found`: no seed reached it; `not_verified`:
    the exact-model simulation ended elsewhere), and `stats`: solve counts (`solves` counts an
    adjoint solve as one), the verifying simulation's wells and configuration and its code
    (`verified_result`: "not_settled" when it was still moving `settings.sweep.settle_time`
    after the load, apart from ending in another configuration), the candidates. The settle
    time is `settings.sweep`'s; `gmr actuate` takes the model's own (7 / its slowest decay rate).

    Raises `GMRInputError` for a malformed target, a cell that is not bistable, or a target equal
    to the start.
    """
    relieve_map_pressure()  # a long session's compiled programs (`_config.map_pressure`)
    if kind not in KINDS:
        raise GMRInputError(f"kind must be one of {KINDS}, got {kind!r}")
    if settings.objective not in OBJECTIVES:
        raise GMRInputError(f"objective must be one of {OBJECTIVES}, got {settings.objective!r}")
    (f0, f1), (a0, a1) = settings.f_range, settings.A_range
    if not (0 < f0 < f1 and 0 <= a0 < a1):
        raise GMRInputError(f"need 0 < f_range[0] < f_range[1] and 0 <= A_range[0] < A_range[1], got "
                            f"{settings.f_range}, {settings.A_range}")
    d = model.n_dof
    bits = parse_target(target, d)
    if wells is None:
        if x_range is None:
            raise GMRInputError("give the wells (dof, 2) or an x_range to search them in")
        wells = stable_wells(model, np.broadcast_to(np.asarray(x_range, float).reshape(-1, 2), (d, 2)))
    wells = np.asarray(wells, float)
    if wells.ndim != 2 or wells.shape[0] != d or wells.shape[1] < 2 or np.any(np.isnan(wells[:, :2])):
        raise GMRInputError("every cell needs two stable wells to be actuated between (check x_range)")
    more = [i for i in range(d) if np.sum(np.isfinite(wells[i])) > 2]
    if more:  # the target is one bit per cell: a third well would be read as one of the first two
        raise GMRInputError(f"cell(s) {more} have more than two stable wells ({np.round(wells[more[0]], 6).tolist()}): "
                            f"actuation designs between two wells per cell; give the two (wells=, or an x_range / "
                            f"--x-range that holds only them)")
    wells = wells[:, :2]
    wj = jnp.asarray(wells)
    x0 = wj[:, 0] if x0 is None else jnp.asarray(x0, float)
    span, _ = _geometry(wj)
    _, start_config, _ = classify(x0, jnp.zeros(d), RESULTS.successful._value, wj, span, settings.sweep)
    config = bits_to_config(bits)
    if int(start_config) == config:
        raise GMRInputError(f"target {'-'.join(map(str, bits))} is the start configuration: nothing to do")
    prob = _Problem(model=model, model_s=smooth_model(model, settings.sign_eps), settings=settings, wells=wj,
                    x0=x0, sigma=jnp.asarray(2.0 * bits - 1.0), saddle=jnp.asarray(saddles(model, wells)),
                    config=config, counts={"forward": 0, "gradient": 0, "verify": 0},
                    batch=max(4, settings.n_seeds))

    cands, bm = _half_sine(prob)
    if not cands:
        act = Actuation(kind=kind)
        sol = _finish(prob, act, None, {"candidates": []}, RESULTS.target_not_found)
        return _raise(sol, throw)

    def make_hs(f, A, scale):
        A = A * scale
        return Actuation(kind="half_sine", f=float(f), A=float(A), peak=float(A),
                         effort=float(_half_sine_effort(f, A)))

    act, ver, ok = _verified_candidates(prob, cands, make_hs)
    extra = {"candidates": [{"f": float(f), "A": float(a)} for _, f, a in sorted(cands)]}
    if kind == "samples" and ok:
        act, ver, ok, more = _samples(prob, act)
        extra.update(more)
    if ok:
        if act.kind == "half_sine":  # the basin map's own solve and classifier at the optimum
            conf, _ = _hs_outcomes(model, prob.sweep, x0, wj, jnp.full(prob.batch, act.f),
                                   jnp.full(prob.batch, act.A))
            extra["basin_map_config"] = int(conf[0])
            prob.counts["forward"] += 1
    code = RESULTS.successful if ok else RESULTS.not_verified
    return _raise(_finish(prob, act, ver, extra, code), throw)


def _raise(sol: Solution, throw: bool) -> Solution:
    return raise_if_failed(sol, throw, "actuate", f"stats: {_short(sol.stats)}")


def _short(stats):
    return {k: stats[k] for k in ("solves", "target_config", "verified_config") if k in stats}


# -- samples ------------------------------------------------------------------------------------


def _samples(prob: _Problem, hs: Actuation):
    s = prob.settings
    T = s.duration if s.duration is not None else 2.0 * hs.load_time
    t = np.linspace(0.0, T, s.n_knots)
    u0 = np.where(t <= hs.load_time, hs.A * np.sin(2 * np.pi * hs.f * t), 0.0)
    u0 = np.where(np.abs(u0) < 1e-14, 0.0, u0)

    def peak(u):
        return float(np.max(np.abs(u)))

    def cost(u):
        return peak(u) if s.objective == "peak" else float(_samples_effort(jnp.asarray(t), jnp.asarray(u)))

    def to_boundary(u):
        """Scale u onto the boundary: (s_lo, s_hi) with s_hi u reaching the target, or None."""
        hi = 1.0
        for _ in range(4):
            if prob.s_reach(t, [hi * u])[0]:
                break
            hi *= 1.05
        else:
            return None
        lo = 0.9 * hi
        for _ in range(6):
            if not prob.s_reach(t, [lo * u])[0]:
                break
            hi, lo = lo, 0.8 * lo
        else:
            return lo, lo
        while hi - lo > s.A_rtol * hi:
            mid = 0.5 * (lo + hi)
            if prob.s_reach(t, [mid * u])[0]:
                hi = mid
            else:
                lo = mid
        return lo, hi

    b = to_boundary(u0)
    if b is None:
        act = Actuation(kind="samples", t=t, force=u0, peak=peak(u0), effort=cost(u0))
        return act, _verify(prob, act), False, {"samples_iterations": 0}
    u = b[1] * u0
    best = cost(u)
    alpha = 0.1
    iters = 0
    tj = jnp.asarray(t)
    for _ in range(s.max_iter_samples):
        iters += 1
        _, n = prob.s_grad(t, u)
        if s.objective == "peak":
            gp = np.asarray(jax.grad(lambda v: jnp.sum(jnp.abs(v) ** s.p_norm) ** (1 / s.p_norm))(jnp.asarray(u)))
        else:
            gp = np.asarray(jax.grad(lambda v: _samples_effort(tj, v))(jnp.asarray(u)))
        if not (np.all(np.isfinite(n)) and np.all(np.isfinite(gp))) or np.dot(n, n) == 0:
            break
        g = gp - np.dot(gp, n) / np.dot(n, n) * n
        if np.max(np.abs(g)) == 0:
            break
        moved = False
        while alpha > 1e-3 and not moved:
            trial = u - alpha * peak(u) * g / np.max(np.abs(g))
            b = to_boundary(trial)
            if b is not None and cost(b[1] * trial) < best:
                u, best = b[1] * trial, cost(b[1] * trial)
                alpha *= 1.5
                moved = True
            else:
                alpha *= 0.5
        if not moved:
            break

    def make_s(uu, _, scale):
        uu = uu * scale
        return Actuation(kind="samples", t=t, force=uu, peak=peak(uu),
                         effort=float(_samples_effort(tj, jnp.asarray(uu))))

    act, ver, ok = _verified_candidates(prob, [(best, u, None)], make_s)
    return act, ver, ok, {"samples_iterations": iters, "half_sine": hs.to_json()}
