"""Time integration of a mechanical model (paper Eq. 1) under an input, with diffrax."""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._errors import GMRInputError, check_real, describe, is_tracer
from .._model._model import AbstractMechanicalModel
from .._solution import RESULTS, Solution, code_name, error_if_failed, raise_if_failed
from ._inputs import AbstractInput
from ._integrate import Integrator, integrate, vector_field

#: Default divergence box of `simulate`: a displacement beyond +-1e6 (model units) is divergence.
DEFAULT_BOX = 1e6


def simulate(
    model: AbstractMechanicalModel,
    inputs: AbstractInput,
    ts: Float[Array, " times"],
    x0: Float[ArrayLike, " dof"],
    v0: Float[ArrayLike, " dof"] | None = None,
    integrator: Integrator = Integrator(),
    *,
    box: float | tuple = DEFAULT_BOX,
    throw: bool = True,
) -> Solution:
    """Integrate the model's equation of motion (paper Eq. 1) from (x0, v0) at ts[0].

    **Arguments:**

    - `model`, `inputs`: any mechanical model and an input (`BaseChirp`, `HalfSineTip`,
      `Sampled`, ...); the input's jump times are declared to the step-size controller.
    - `ts`: save times (the first is the start time).
    - `x0`, `v0`: initial displacements and velocities (default at rest).
    - `integrator`: tolerances and step budget (`Integrator`).
    - `box`: divergence box on x: a number b (|x| <= b) or `(lo, hi)` arrays; leaving it stops
      the solve with `RESULTS.diverged`.
    - `throw`: raise on failure (use `False` under vmap and read `result`): called with
      concrete values, a `GMRComputationError` naming the code (and, for a model with the
      exact sgn(v) of Coulomb friction, the fix); inside jit/vmap/grad, equinox's runtime error.

    **Returns:** a `Solution` with `value = (x (times, dof), v (times, dof))`, `result` (a
    failed or diverged solve is flagged, its values NaN), `stats` with the step counts.

    A wrong argument (x0 or v0 not one finite value per DOF, ts not strictly increasing or with
    fewer than 2 times, an unknown model or input type) raises `GMRInputError` before any work;
    values are checked only when concrete, so `simulate` stays usable under jit/vmap/grad.

    Examples:
        A damped double well released near its saddle settles in the right-hand well x = 1:

        >>> import jax.numpy as jnp
        >>> import gmr_jax as gmr
        >>> model = gmr.from_terms([1.0], [
        ...     {"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -1.0},
        ...     {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1.0},
        ...     {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.5}])
        >>> sol = gmr.simulate(model, gmr.NoInput(), jnp.linspace(0.0, 40.0, 5), jnp.array([0.3]),
        ...                    throw=False)
        >>> bool(sol.result == gmr.RESULTS.successful)
        True
        >>> x, v = sol.value
        >>> x.shape, round(float(x[-1, 0]), 4)
        ((5, 1), 1.0)
    """
    _check_inputs(model, inputs, ts, x0, v0, integrator, box)
    traced = any(is_tracer(leaf) for leaf in jax.tree.leaves((model, inputs, ts, x0, v0, integrator, box)))
    if traced or not throw:  # inside jit/vmap/grad a failure can only be raised from inside
        return _simulate(model, inputs, ts, x0, v0, integrator, box=box, throw=throw)
    sol = _simulate(model, inputs, ts, x0, v0, integrator, box=box, throw=False)
    if code_name(sol.result) == "successful":
        return sol
    return raise_if_failed(sol, True, "simulate", _failure_hint(model, sol))


def _failure_hint(model, sol) -> str:
    """What to do about a failed solve that the code's message alone does not say."""
    if exact_coulomb(model):
        return ("the model has Coulomb friction sgn(v) (velocity_damping order 0) with the exact sign: an "
                "adaptive solver chatters where a mass stops (v = 0); integrate model.with_sign_eps(eps), "
                "sgn(v) -> tanh(v / eps), with eps well below the speeds that matter (e.g. 1e-3 x the RMS "
                "velocity)")
    steps = sol.stats.get("num_steps") if isinstance(sol.stats, dict) else None
    return "" if steps is None else f"{int(np.asarray(steps))} steps"


def has_coulomb(model) -> bool:
    """Whether a `GlobalModel` has Coulomb friction, a sgn(v) term (`velocity_damping` order 0)."""
    from .._model._model import GlobalModel

    return isinstance(model, GlobalModel) and bool(np.any(np.asarray(model.velocity_damping)[:, 0] != 0.0))


def exact_coulomb(model) -> bool:
    """Whether a `GlobalModel` has a sgn(v) term integrated with the exact (discontinuous) sign."""
    return has_coulomb(model) and model.sign_eps == 0.0


def _check_inputs(model, inputs, ts, x0, v0, integrator, box):
    """`GMRInputError` for a wrong argument of `simulate`. Shapes are checked always (they are
    static under jit/vmap); values only when concrete (never on a tracer)."""
    if not isinstance(model, AbstractMechanicalModel):
        raise GMRInputError(f"simulate: model must be a mechanical model (GlobalModel, a system's truth, "
                            f"...), got {type(model).__name__}; load one with gmr_jax.load_model")
    if not isinstance(inputs, AbstractInput):
        raise GMRInputError(f"simulate: inputs must be an input object (NoInput(), BaseSine, HalfSineTip, "
                            f"Sampled, ...), got {type(inputs).__name__}")
    if not isinstance(integrator, Integrator):
        raise GMRInputError(f"simulate: integrator must be a gmr_jax.Integrator, got {type(integrator).__name__}")
    d = model.n_dof
    if not is_tracer(ts):
        _check_array_type(ts, "ts")
    if jnp.ndim(ts) != 1 or jnp.shape(ts)[0] < 2:
        raise GMRInputError(f"simulate: ts must be a 1-D array of at least 2 save times (the first is the "
                            f"start), got shape {jnp.shape(ts)}; e.g. jnp.linspace(0, 1, 101)")
    if not is_tracer(ts):
        t = np.asarray(ts, float)
        if not np.all(np.isfinite(t)):
            raise GMRInputError(f"simulate: ts has NaN/inf, first at index {int(np.argmax(~np.isfinite(t)))}")
        dt = np.diff(t)
        if np.any(dt <= 0):
            i = int(np.argmax(dt <= 0)) + 1
            raise GMRInputError(f"simulate: ts must be strictly increasing; ts[{i}] = {t[i]:g} <= ts[{i - 1}] = "
                                f"{t[i - 1]:g}; sort it and drop repeated times")
    for name, val in (("x0", x0), ("v0", v0)):
        if val is None:
            continue
        if not is_tracer(val):
            _check_array_type(val, name)
        if jnp.shape(val) != (d,):
            raise GMRInputError(f"simulate: {name} must hold {d} value(s), one per DOF of this {d}-DOF model, "
                                f"got shape {jnp.shape(val)}")
        if not is_tracer(val) and not np.all(np.isfinite(np.asarray(val, float))):
            raise GMRInputError(f"simulate: {name} has NaN/inf values {np.asarray(val).tolist()}; give finite "
                                f"initial {'displacements' if name == 'x0' else 'velocities'}")
    if isinstance(box, tuple):
        if len(box) != 2:
            raise GMRInputError(f"simulate: box must be a number b or a (lo, hi) pair, got a {len(box)}-tuple")
        lo, hi = box
        if not (is_tracer(lo) or is_tracer(hi)):
            check_real(lo, "simulate: box lo")
            check_real(hi, "simulate: box hi")
            if np.any(np.asarray(lo, float) >= np.asarray(hi, float)):
                raise GMRInputError("simulate: box (lo, hi) needs lo < hi for every DOF")
    else:
        check_real(box, "simulate: box", lo=0.0, lo_open=True,
                   fix="give the largest |x| allowed before the solve counts as diverged, e.g. 1e6")


def _check_array_type(val, name):
    if isinstance(val, (bool, str, bytes)):
        raise GMRInputError(f"simulate: {name} must be an array of numbers, got {describe(val)}")
    try:
        kind = np.asarray(val).dtype.kind
    except Exception:  # noqa: BLE001 - ragged or not array-like
        kind = "O"
    if kind not in "iuf":
        raise GMRInputError(f"simulate: {name} must be an array of real numbers, got {describe(val)}")


@eqx.filter_jit
def _simulate(model, inputs, ts, x0, v0, integrator, *, box, throw):
    x0 = jnp.asarray(x0, float)
    v0 = jnp.zeros_like(x0) if v0 is None else jnp.asarray(v0, float)
    lo, hi = (-box, box) if not isinstance(box, tuple) else box
    traj = integrate(vector_field(model, inputs), ts[0], ts[-1], (x0, v0), integrator,
                     saveat=dfx.SaveAt(ts=ts), box=(lo, hi), jump_ts=inputs.jump_times(),
                     step_ts=inputs.step_times())
    # checked here as well as in `_check_inputs`: under jit the times are traced and only a code can say it
    ordered = jnp.all(jnp.diff(ts) > 0) & jnp.all(jnp.isfinite(ts))
    result = RESULTS.where(ordered, traj.result, RESULTS.unordered_times)
    good = result == RESULTS.successful
    xs, vs = (jnp.where(good, y, jnp.nan) for y in traj.ys)
    return error_if_failed(Solution(value=(xs, vs), result=result, stats=traj.stats), throw)

