"""Refinement of a global model's coefficients on measured trajectories (output-error least
squares with multiple shooting), by optimistix Levenberg-Marquardt through diffrax solves."""

import dataclasses
import warnings

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from .._config import relieve_map_pressure
from .._errors import GMRDataWarning, GMRInputError
from .._solution import RESULTS, Solution, code_name, raise_if_failed
from .._fit._library import POSITION_DAMPING, STIFFNESS, VELOCITY_DAMPING
from .._model._model import GlobalModel
from .._simulate._integrate import Integrator
from ._shooting import (FAILED_WINDOW_RESIDUAL, OutputError, Windows, check_starts, fit_starts, make_windows,
                        measured_starts, output_error, prepare, window_residuals)

PHYSICS = (STIFFNESS, VELOCITY_DAMPING, POSITION_DAMPING)


class RefineSettings(eqx.Module):
    """Settings of `refine`.

    **Attributes:**

    - `window`: shooting window length in seconds.
    - `solver`: an optimistix least-squares solver (Levenberg-Marquardt by default; e.g.
      `optx.GaussNewton(rtol, atol)` also works).
    - `max_iterations`: maximum least-squares solver iterations (optimistix's `max_steps`).
    - `stride`: residuals at every `stride`-th sample of a window (cheaper Jacobians).
    - `max_windows`: at most this many windows per recording (evenly spread), or None for all.
    - `sign_eps`: the sgn(v) in `velocity_damping` order 0 (Coulomb friction) is replaced during
      the optimisation by tanh(v / eps) with eps = `sign_eps` times the RMS measured velocity
      (the gradient of sgn is zero and its jump stalls adaptive solvers); reported errors use
      the exact model. Only applied when that term is nonzero or free.
    - `jac`: "fwd" (default): each window's Jacobian by forward-mode through the solve
      (`diffrax.ForwardMode`, cost ~ number of free coefficients); "bwd": by reverse mode with
      diffrax's default `RecursiveCheckpointAdjoint` (cost ~ residuals per window).
    - `integrator`: ODE tolerances and the per-window `max_steps`.
    - `box_ranges`: divergence box of a window: the recording's range of x widened by
      `box_ranges` times that range on each side; a window that leaves it counts as diverged.
    - `starts`: what each window starts from. "estimated" (default): the state (x0, v0) that fits
      the window's measured x best under the current coefficients (`fit_starts`; the
      coefficients' Jacobian is projected off the start states', variable projection); a noisy
      x0, or a v0 estimated from a noisy x, no longer bends the coefficients. "measured": the
      recorded (x, v) at its first sample (v estimated from x when not recorded); cheaper, and
      as good where x and v are clean.
    """

    window: float = 1.0
    solver: optx.AbstractLeastSquaresSolver = optx.LevenbergMarquardt(rtol=1e-6, atol=1e-8)
    max_iterations: int = eqx.field(static=True, default=50)
    stride: int = eqx.field(static=True, default=1)
    max_windows: int | None = eqx.field(static=True, default=None)
    sign_eps: float = eqx.field(static=True, default=1e-3)
    jac: str = eqx.field(static=True, default="fwd")
    integrator: Integrator = Integrator(rtol=1e-8, atol=1e-10, max_steps=20_000)
    box_ranges: float = 10.0
    starts: str = eqx.field(static=True, default="estimated")

    def __check_init__(self):
        check_starts(self.starts)
        if self.jac not in ("fwd", "bwd"):
            raise GMRInputError(f"jac must be 'fwd' or 'bwd', got {self.jac!r}")
        if self.window is not None and not (np.isfinite(self.window) and self.window > 0):
            raise GMRInputError(f"window must be a positive number of seconds, got {self.window}")
        if self.stride < 1 or self.max_iterations < 1:
            raise GMRInputError("stride and max_iterations must be >= 1")


def free_mask(model: GlobalModel, free=None) -> dict[str, np.ndarray]:
    """Which coefficients `refine` adjusts, as boolean arrays shaped like the model's.

    `free`: None or "all": every nonzero coefficient (the support is kept); a physics name
    ("stiffness", "velocity_damping", "position_damping"), "damping" (both damping kinds) or a
    comma-separated list of them: the nonzero coefficients of those; a list of
    (dof, physics, order) tuples (zero coefficients allowed: they start at 0); or a dict
    {physics: bool array} mask."""
    arrays = {p: np.asarray(getattr(model, p)) for p in PHYSICS}
    if free is None:
        free = "all"
    if isinstance(free, str):
        names = [s.strip() for s in free.split(",") if s.strip()]
        chosen = set()
        for s in names:
            if s == "all":
                chosen.update(PHYSICS)
            elif s == "damping":
                chosen.update((VELOCITY_DAMPING, POSITION_DAMPING))
            elif s in PHYSICS:
                chosen.add(s)
            else:
                raise GMRInputError(
                    f"free: unknown {s!r}; use 'all', 'damping', or physics names {', '.join(PHYSICS)}"
                )
        mask = {p: (arrays[p] != 0) & (p in chosen) for p in PHYSICS}
    elif isinstance(free, dict):
        mask = {}
        for p in PHYSICS:
            m = np.asarray(free.get(p, np.zeros_like(arrays[p], bool)), bool)
            if m.shape != arrays[p].shape:
                raise GMRInputError(f"free[{p!r}] has shape {m.shape}, the model's {p} has {arrays[p].shape}")
            mask[p] = m
    else:
        mask = {p: np.zeros(arrays[p].shape, bool) for p in PHYSICS}
        for item in free:
            try:
                dof, phys, order = item
                dof, order = int(dof), int(order)
            except (TypeError, ValueError):
                raise GMRInputError(f"free: expected (dof, physics, order) tuples, got {item!r}") from None
            if phys not in PHYSICS:
                raise GMRInputError(f"free: unknown physics {phys!r}; known: {', '.join(PHYSICS)}")
            if not (0 <= dof < arrays[phys].shape[0] and 0 <= order < arrays[phys].shape[1]):
                raise GMRInputError(
                    f"free: term ({dof}, {phys}, {order}) is outside the model's {phys} array "
                    f"{arrays[phys].shape} (dof, order)"
                )
            mask[phys][dof, order] = True
    if not any(m.any() for m in mask.values()):
        raise GMRInputError(f"free={free!r} selects no coefficient of the model (all zero or none named)")
    return mask


class ShootingProblem(eqx.Module):
    """The least-squares problem of `refine`: the free coefficients are `offset + transform @ p`
    (p = 0 at the start; `transform` whitens the model's covariance of the free coefficients, so
    that a unit step moves them by one posterior standard deviation along each principal
    direction, or scales each by its starting magnitude where the model has no covariance),
    residuals = (simulated - measured x) / std over all windows.

    `residuals(p, windows)` uses the default `RecursiveCheckpointAdjoint` (use it with
    `jax.grad`); `__call__(p, windows)` is the same function with a custom JVP that forms each
    window's dense Jacobian once (forward or reverse mode per `jac`), which optimistix
    linearises."""

    model: GlobalModel
    offset: Float[Array, " free"]
    transform: Float[Array, "free free"]
    index: tuple = eqx.field(static=True)  # per physics: (rows, cols) tuples
    stride: int = eqx.field(static=True)
    jac: str = eqx.field(static=True)
    integrator: Integrator
    estimated: bool = eqx.field(static=True, default=True)
    #: weight of the prior residuals p (0: none): with a whitening `transform`, ||r||^2 + prior^2 ||p||^2
    #: is the negative log posterior at residual noise variance prior^2
    prior: Float[Array, ""] | float = 0.0

    def to_model(self, p: Float[Array, " free"]) -> GlobalModel:
        coef = self.offset + self.transform @ p
        model, start = self.model, 0
        for phys, (rows, cols) in zip(PHYSICS, self.index):
            n = len(rows)
            if n:
                arr = getattr(model, phys).at[np.asarray(rows), np.asarray(cols)].set(coef[start:start + n])
                model = dataclasses.replace(model, **{phys: arr})
            start += n
        return model

    def starts(self, p, w: Windows):
        """Each window's start state (W, 2D) under the coefficients `p` (no gradient flows through it)."""
        if not self.estimated:
            return measured_starts(w)
        return fit_starts(self.to_model(jax.lax.stop_gradient(p)), w, self.stride, self.integrator,
                          FAILED_WINDOW_RESIDUAL)

    def _window_residuals(self, p, w: Windows, adjoint):
        r, ok, _ = window_residuals(self.to_model(p), w, self.starts(p, w), self.stride, self.integrator, adjoint,
                                    FAILED_WINDOW_RESIDUAL)
        return r, ok

    def residuals(self, p, windows: list[Windows], adjoint=dfx.RecursiveCheckpointAdjoint()):
        """All residuals (flat) and the per-window success flags. With estimated starts these are
        at the best start states for `p`, held fixed under differentiation: the gradient of the
        squared norm is then exact (the starts are stationary), the Jacobian is not (that is
        `residuals_and_jacobian`'s projected one)."""
        parts = [self._window_residuals(p, w, adjoint) for w in windows]
        return (jnp.concatenate([r.reshape(-1) for r, _ in parts] + [self.prior * p]),
                jnp.concatenate([ok for _, ok in parts]))

    def residuals_and_jacobian(self, p, windows: list[Windows]):
        """Residuals (R,) and their Jacobian (R, free), window by window. With estimated starts the
        Jacobian is the variable-projection one (Kaufman): each window's coefficient Jacobian with
        its start-state columns projected out, J_p - J_s J_s^+ J_p, the derivative of the
        residuals at starts re-fitted to every p (to first order in the residual)."""
        rs, js = [], []
        if self.jac == "fwd":
            adj, jfn = dfx.ForwardMode(), jax.jacfwd
        else:
            adj, jfn = dfx.RecursiveCheckpointAdjoint(), jax.jacrev
        for w in windows:
            starts = self.starts(p, w)

            def one(z, wi, adj=adj):
                q, s = z
                r, _, _ = window_residuals(self.to_model(q), jax.tree_util.tree_map(lambda a: a[None], wi), s[None],
                                        self.stride, self.integrator, adj, FAILED_WINDOW_RESIDUAL)
                return r[0], r[0]

            def window(wi, s):
                if not self.estimated:  # the recorded start: no start-state columns to project off
                    return jfn(lambda q: one((q, s), wi), has_aux=True)(p)
                (jp, jst), r = jfn(one, has_aux=True)((p, s), wi)
                return jp - jst @ jnp.linalg.lstsq(jst, jp)[0], r

            j, r = jax.vmap(window)(w, starts)
            rs.append(r.reshape(-1))
            js.append(j.reshape(-1, p.shape[0]))
        rs.append(self.prior * p)
        js.append(self.prior * jnp.eye(p.shape[0]))
        return jnp.concatenate(rs), jnp.concatenate(js)

    def __call__(self, p, windows):
        return _residual_fn(self, p, windows), None


@jax.custom_jvp
def _residual_fn(problem, p, windows):
    # not differentiated here (the JVP rule below is): a plain while loop compiles fastest
    return problem.residuals(p, windows, dfx.ForwardMode())[0]


@_residual_fn.defjvp
def _residual_fn_jvp(primals, tangents):
    problem, p, windows = primals
    _, dp, _ = tangents
    r, j = problem.residuals_and_jacobian(p, windows)
    return r, j @ dp


def shooting_problem(
    model: GlobalModel, recordings, free=None, settings: RefineSettings = RefineSettings()
) -> tuple[ShootingProblem, Float[Array, " free"], list[Windows]]:
    """Build the problem `refine` solves: (problem, p0 (zeros), windows). The model is the
    one optimised (with the sgn(v) surrogate where applicable)."""
    if not isinstance(model, GlobalModel):
        raise GMRInputError(f"refine needs a GlobalModel (polynomial coefficients), got {type(model).__name__}")
    recs = prepare(recordings, model.n_dof, model.topology)
    mask = free_mask(model, free)
    windows = make_windows(recs, settings.window, settings.box_ranges, settings.max_windows)
    index, scales = [], []
    for phys in PHYSICS:
        rows, cols = np.nonzero(mask[phys])
        index.append((tuple(rows.tolist()), tuple(cols.tolist())))
        c = np.abs(np.asarray(getattr(model, phys))[rows, cols])
        scales.append(np.where(c > 0, c, 1.0))
    scales = np.concatenate(scales)
    coef0 = np.concatenate([np.asarray(getattr(model, ph))[np.asarray(r, int), np.asarray(c, int)]
                            if len(r) else np.zeros(0) for ph, (r, c) in zip(PHYSICS, index)])
    transform = _whitening(model, index)
    prior = 0.0 if transform is None else 1.0  # its weight set by `refine` from the starting residuals
    transform = np.diag(scales) if transform is None else transform
    m = dataclasses.replace(model, stderr=None, covariance=None)
    if _uses_sign(model, mask):
        v_rms = float(np.sqrt(np.mean(np.concatenate([np.asarray(r.v).ravel() ** 2 for r in recs]))))
        m = m.with_sign_eps(settings.sign_eps * max(v_rms, 1e-300))
    problem = ShootingProblem(m, jnp.asarray(coef0, float), jnp.asarray(transform, float), tuple(index),
                              settings.stride, settings.jac, settings.integrator, check_starts(settings.starts),
                              jnp.asarray(prior))
    return problem, jnp.zeros(coef0.shape[0]), windows


#: eigenvalues of the free coefficients' covariance are floored at this share of the largest
COVARIANCE_FLOOR = 1e-12


def _whitening(model: GlobalModel, index) -> np.ndarray | None:
    """T with T T' = C, the model's covariance of the free coefficients (`index`), its
    eigenvalues floored at `COVARIANCE_FLOOR` of the largest; None without a usable covariance."""
    if model.covariance is None:
        return None
    widths = [np.shape(getattr(model, ph))[-1] for ph in PHYSICS]
    first = np.cumsum([0] + widths[:-1])
    dof = np.concatenate([np.asarray(r, int) for r, _ in index])
    flat = np.concatenate([first[j] + np.asarray(c, int) for j, (_, c) in enumerate(index)])
    cov = np.asarray(model.covariance, float)
    C = np.where(dof[:, None] == dof[None, :], cov[dof[:, None], flat[:, None], flat[None, :]], 0.0)
    if not np.all(np.isfinite(C)):
        return None
    lam, V = np.linalg.eigh(0.5 * (C + C.T))
    if not lam.max() > 0:
        return None
    return V * np.sqrt(np.maximum(lam, COVARIANCE_FLOOR * lam.max()))[None, :]


def _uses_sign(model: GlobalModel, mask) -> bool:
    col = np.asarray(model.velocity_damping)[:, 0]
    return bool(np.any(col != 0) or np.any(mask[VELOCITY_DAMPING][:, 0]))


@eqx.filter_jit
def _residuals(problem, p, windows):
    return problem.residuals(p, windows, dfx.ForwardMode())


@eqx.filter_jit
def _solve(problem, p0, windows, solver, max_iterations):
    sol = optx.least_squares(problem, solver, p0, windows, has_aux=True, max_steps=max_iterations, throw=False)
    r, ok = problem.residuals(sol.value, windows, dfx.ForwardMode())
    return sol.value, RESULTS.promote(sol.result), sol.stats["num_steps"], jnp.sum(r**2), ok


def refine(
    model: GlobalModel,
    recordings,
    *,
    free=None,
    settings: RefineSettings = RefineSettings(),
    holdout=None,
    throw: bool = True,
) -> Solution:
    """Fit the coefficients of `model` to measured trajectories (output error, multiple shooting).

    Every recording is cut into windows of `settings.window` seconds; each window is simulated
    (diffrax, Tsit5) under the measured inputs from its start state (by default the one that fits
    its samples best, `settings.starts`; or the recorded (x, v) at its first sample), and
    the residuals (simulated - measured x, per DOF over the recording's std) of all windows are
    minimised by `settings.solver` (Levenberg-Marquardt) over the free coefficients. Where the
    model has a covariance (`reconstruct` gives one), its posterior is the fit's prior: the
    objective is ||r||^2 + s^2 ||L^-1 (c - c_0)||^2 (L L' the covariance, s^2 the starting
    residuals' mean square), so a coefficient moves only as far as the trajectories support;
    otherwise each is scaled by its starting magnitude. Windows that fail or diverge get a constant penalty
    residual (no NaN gradients); sgn(v) terms are smoothed during the fit (see
    `RefineSettings.sign_eps`).

    **Arguments:**

    - `model`: the starting `GlobalModel` (e.g. from `reconstruct`); its support is kept.
    - `recordings`: training `Recording`s (same DOFs as the model; inputs base_acc or force).
    - `free`: which coefficients to fit (see `free_mask`); the others stay fixed.
    - `settings`: `RefineSettings`.
    - `holdout`: recordings not used in the fit, on which the output error is reported.
    - `throw`: raise `GMRComputationError` if the refinement failed (otherwise read `result`).

    **Returns:** a `Solution` with `value` the refined `GlobalModel` (exact sgn(v), no stderr),
    `result` (`successful`; `nonlinear_max_steps_reached` if the solver ran out of iterations;
    `diverged` if training windows of the refined model fail; `nonfinite`), and `stats`:
    `iterations`, `optimistix_result` (its message), `train` and `holdout` dicts of
    `before`/`after` `OutputError`s (exact model, windows of `settings.window` from the recorded
    state, whatever `settings.starts`), `free`
    (the terms fitted), `cost_before`/`cost_after` (the surrogate least-squares objective),
    `warnings` (also emitted as `GMRDataWarning`: a refined model worse on the holdout; a restoring
    law moved beyond the given model's band).
    """
    relieve_map_pressure()  # a long session's compiled programs (`_config.map_pressure`)
    problem, p0, windows = shooting_problem(model, recordings, free, settings)
    r0, ok0 = _residuals(problem, p0, windows)
    cost0 = float(jnp.sum(r0**2))
    # the model's posterior as the prior, at the noise variance of the starting residuals
    problem = eqx.tree_at(lambda q: q.prior, problem, problem.prior * np.sqrt(cost0 / max(r0.size - p0.size, 1)))
    p, result, steps, cost1, ok = _solve(problem, p0, windows, settings.solver, settings.max_iterations)
    refined = dataclasses.replace(problem.to_model(p), sign_eps=0.0, stderr=None, covariance=None)
    exact0 = dataclasses.replace(model, sign_eps=0.0)
    oname = code_name(result)
    if not bool(np.all(np.isfinite(np.asarray(p)))):
        result = RESULTS.nonfinite
    elif result == RESULTS.successful and not bool(np.all(np.asarray(ok))):
        result = RESULTS.diverged

    def errs(recs):
        # one yardstick whatever the settings: windows from the recorded state (a fitted-start error is
        # output_error(..., starts="estimated"); it would compile a second large program on every call)
        kw = dict(integrator=settings.integrator, box_ranges=settings.box_ranges, max_windows=settings.max_windows)
        return {"before": output_error(exact0, recs, settings.window, **kw).value,
                "after": output_error(refined, recs, settings.window, **kw).value}

    stats = {
        "iterations": int(steps),
        "optimistix_result": oname,
        "cost_before": cost0,
        "cost_after": float(cost1),
        "failed_windows_before": int(np.sum(~np.asarray(ok0))),
        "failed_windows_after": int(np.sum(~np.asarray(ok))),
        "windows": int(np.asarray(ok).size),
        "free": _free_terms(problem),
        "train": errs(recordings),
        "holdout": errs(holdout) if holdout is not None else None,
    }
    stats["warnings"] = (_unpredicted_warnings(stats["train"], settings.window) + _holdout_warnings(stats["holdout"])
                         + _moved_law_warnings(model, refined, recordings))
    for w in stats["warnings"]:
        warnings.warn(w, GMRDataWarning, stacklevel=2)
    return raise_if_failed(Solution(value=refined, result=result, stats=stats), throw, "refine")


#: `refine` warns where the training windows' output NRMSE is at least this before and after: no model predicts them
UNPREDICTED = 0.5


def _unpredicted_warnings(train, window: float) -> list[str]:
    """Neither the given nor the refined model predicts the training windows (NRMSE >= `UNPREDICTED` both): within a
    window the response leaves the recorded state (a record crossing between wells is sensitive: an exact model
    loses it too), and the fit's optimum is not the law's. Audit 8: a crossing record, 1 s windows, NRMSE 1.084 ->
    1.005, the refined law 23 % off with barriers a third of the truth's and no warning; 0.2 s windows: 0.28 %."""
    b, a = train["before"], train["after"]
    if not (b.nrmse >= UNPREDICTED and a.nrmse >= UNPREDICTED):
        return []
    return [f"neither model predicts the training windows of {window:.3g} s (output NRMSE {b.nrmse:.3g} -> "
            f"{a.nrmse:.3g}): within a window the motion leaves the recorded state (a response that crosses between "
            f"wells is sensitive; an exact model loses it too), so the fitted coefficients follow that, not the law; "
            f"keep the given model, or refine on shorter windows (gmr refine --window {window / 5:.2g}, "
            f"RefineSettings(window=...)) until the given model's windowed NRMSE is well under {UNPREDICTED:g}"]


#: `refine` warns when the refined model's holdout output error exceeds the given model's by this factor.
HOLDOUT_WORSE = 1.05


def _holdout_warnings(holdout) -> list[str]:
    """The refined model is worse than the given one on the holdout (NRMSE up by more than
    `HOLDOUT_WORSE`, or more failed windows): the refinement fitted the training windows only.
    Hand-made lab double well, trained on one record per well, cross-well holdout: 0.199 % -> 0.498 %."""
    if holdout is None:
        return []
    b, a = holdout["before"], holdout["after"]
    if not (a.nrmse > HOLDOUT_WORSE * b.nrmse or a.failed > b.failed):
        return []
    return [(f"the refined model is worse than the given one on the holdout (windowed output NRMSE {b.nrmse:.4g} -> "
             f"{a.nrmse:.4g}, failed windows {b.failed} -> {a.failed} of {a.windows}): it fitted the training "
             f"records only; keep the given model, or refine on records that cover the motion the holdout has")]


#: `refine` warns where it moved a DOF's restoring law (RMS over the recorded range) by more than this many times
#: the given model's band there, and by more than `MOVED_MIN` of the law's RMS
MOVED_FACTOR, MOVED_MIN = 2.0, 0.002


def _moved_law_warnings(model: GlobalModel, refined: GlobalModel, recordings) -> list[str]:
    """The refinement moved a restoring law further than the given model's band (its covariance, from the local
    fits) allows over the recorded range: the free stiffness terms absorbed what the model lacks elsewhere (a
    tri-stable law fitted to 0.007 %, a v^3 damping term missing: refined with every term free, 0.96 % off, while
    `free="damping"` kept it and did as well on the holdout)."""
    from .._model._metadata import ranges
    from .._reconstruct._sanity import restoring_uncertainty

    if model.covariance is None:
        return []
    recs = [recordings] if not isinstance(recordings, (list, tuple)) else list(recordings)
    out = []
    for i, (lo, hi) in enumerate(ranges(recs, "x")):
        k0, k1 = np.asarray(model.stiffness[i], float), np.asarray(refined.stiffness[i], float)
        if not hi > lo or np.array_equal(k0, k1):
            continue
        xs = np.linspace(lo, hi, 201)
        f0 = np.polynomial.polynomial.polyval(xs, k0)
        moved = float(np.linalg.norm(np.polynomial.polynomial.polyval(xs, k1) - f0) / max(np.linalg.norm(f0), 1e-300))
        band = restoring_uncertainty(k0, np.asarray(model.covariance[i]), lo, hi)
        if band <= 0:  # no band on this DOF's law (its terms not in the covariance): nothing to compare with
            continue
        if moved > max(MOVED_FACTOR * band, MOVED_MIN):
            out.append(f"DOF {i}: the refinement moved the restoring law by {100 * moved:.3g} % (RMS over the recorded "
                       f"range [{lo:.4g}, {hi:.4g}]), {moved / max(band, 1e-300):.3g} x the given model's band "
                       f"(±{100 * band:.2g} %, from the local fits): the free stiffness terms absorbed something else "
                       f"(a term the model lacks, e.g. in the damping); refine fewer terms (free='damping', gmr "
                       f"refine --free damping) or look for the missing one (gmr discover)")
    return out


def _free_terms(problem: ShootingProblem) -> list[tuple[int, str, int]]:
    return [(int(r), phys, int(c)) for phys, (rows, cols) in zip(PHYSICS, problem.index) for r, c in zip(rows, cols)]


__all__ = ["RefineSettings", "refine", "free_mask", "shooting_problem", "ShootingProblem", "OutputError",
           "output_error"]
