"""One result convention for every numeric entry point: a `Solution` with a `RESULTS` code.

`RESULTS` extends diffrax's enumeration (which extends optimistix's and lineax's), so a code
returned by `diffeqsolve`, `optx.least_squares` or `lx.linear_solve` is promoted with
`RESULTS.promote(code)`, keeping its own message; gmr_jax adds the codes of its own stages.
User mistakes (bad shapes, NaN inputs, an ill-posed request) are raised as `GMRInputError`
at call time, before any computation; numerical failures are codes, raised only when
`throw=True` (the default outside vmap).
"""

from typing import Any

import diffrax as dfx
import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import PyTree


class RESULTS(dfx.RESULTS):
    """Result codes of every gmr_jax entry point (read them with `throw=False` under vmap).

    Inherits diffrax's, optimistix's and lineax's codes (`max_steps_reached`, `event_occurred`,
    `nonlinear_max_steps_reached`, `nonfinite`, ...) with their messages, and adds:
    """

    stls_max_iterations = (
        "STLS did not converge: the support was still changing at `max_iter`. "
        "Increase `STLS.max_iter` or the threshold."
    )
    ill_posed_coordination = (
        "The coordination system is singular or too ill-conditioned to solve: the equilibria "
        "coincide, or the local orders do not determine a unique global polynomial. Use lower "
        "library orders or a larger threshold."
    )
    simulation_failed = (
        "The ODE solver failed (step-size collapse or its step budget reached); raise "
        "`Integrator.max_steps` or loosen the tolerances."
    )
    diverged = (
        "The simulated state left its divergence box (the model escaped the region where it is "
        "valid); the model is likely unbounded there."
    )
    not_settled = "The simulation had not settled into an equilibrium by the final time; lengthen the settle time."
    target_not_found = (
        "No actuation in the search range reached the target configuration: widen f_range / "
        "A_range (or the duration), or the target is not reachable from the start with this load."
    )
    not_verified = (
        "The optimized actuation did not reach the target in the verifying simulation with the "
        "exact model (it lies on a basin boundary that the verification resolves differently)."
    )
    unordered_times = (
        "The save times are not strictly increasing and finite (a reversed or repeated time, or "
        "NaN, passed under jit where it cannot be refused): give ts in increasing order."
    )


def _value(code) -> int:
    return int(np.asarray(getattr(code, "_value", code)))


_NAMES = {int(item._value): name for name, item in RESULTS._name_to_item.items()}


def code_name(code) -> str:
    """The member name of a RESULTS code (an item or its integer value), e.g. "diverged"."""
    value = _value(code)
    if value not in _NAMES:
        raise ValueError(f"{value} is not a RESULTS value")
    return _NAMES[value]


def message(code) -> str:
    """The message of a RESULTS code (an item or its integer value)."""
    return RESULTS._index_to_message[_value(code)]


def value_of(name: str) -> int:
    """Integer value of the RESULTS member `name` (for codes stored in arrays and files)."""
    return int(RESULTS._name_to_item[name]._value)


class Solution(eqx.Module):
    """The result of a gmr_jax computation.

    **Attributes:**

    - `value`: the answer (coefficients, a model, a trajectory, a map...).
    - `result`: a `RESULTS` code; `RESULTS[sol.result]` gives the message.
    - `stats`: diagnostics (iterations, condition numbers, supports, warnings...).
    - `aux`: further outputs, e.g. a covariance.

    Outside jit, `sol.status` names the result ("successful", "diverged", ...; an array of
    names for a batch of results) and `sol.ok` says whether every one succeeded.
    """

    value: PyTree
    result: RESULTS
    stats: dict[str, PyTree]
    aux: Any = None

    @property
    def status(self):
        """The result's name, e.g. "successful" or "diverged" (a str; a NumPy array of names
        for a batch of results, e.g. from `vmap` with `throw=False`). Outside jit only."""
        values = _concrete(self.result, "status")
        if values.ndim == 0:
            return code_name(int(values))
        return np.vectorize(code_name, otypes=[str])(values)

    @property
    def ok(self) -> bool:
        """True when the result (every one, for a batch) is `RESULTS.successful`. Outside jit only."""
        return bool(np.all(_concrete(self.result, "ok") == int(RESULTS.successful._value)))


def _concrete(code, what: str) -> np.ndarray:
    from ._errors import GMRInputError, is_tracer

    value = getattr(code, "_value", code)
    if is_tracer(value):
        raise GMRInputError(f"Solution.{what} is known only outside jit/vmap: inside, compare "
                            f"`sol.result == gmr.RESULTS.successful` (a traced boolean) instead")
    return np.asarray(value)


def error_if_failed(sol: Solution, throw: bool) -> Solution:
    """Raise the result's message (inside or outside jit) when `throw` is true."""
    if throw:
        sol = eqx.tree_at(
            lambda s: s.value,
            sol,
            sol.result.error_if(sol.value, sol.result != RESULTS.successful),
            is_leaf=lambda x: x is None,
        )
    return sol


class GMRComputationError(RuntimeError):
    """A numerical failure outside jit with `throw=True`: the message of its `RESULTS` code.

    The command line prints it as one line and exits with status 1."""

    def __init__(self, what: str, code, detail: str = ""):
        self.code = code
        self.name = code_name(code)
        super().__init__(f"{what}: {message(code)}" + (f" ({detail})" if detail else "") + f" [{self.name}]")


def raise_if_failed(sol: Solution, throw: bool, what: str, detail: str = "") -> Solution:
    """Host-side counterpart of `error_if_failed` for entry points that are not jitted (they
    hold Python objects in `value`): raise `GMRComputationError` with the code's message."""
    if throw and code_name(sol.result) != "successful":
        raise GMRComputationError(what, sol.result, detail)
    return sol


def codes_where(ok, good, bad):
    """Elementwise choice between two RESULTS members (arrays of values allowed)."""
    return jnp.where(ok, good._value, bad._value)


def as_result(value) -> RESULTS:
    """A RESULTS item holding `value` (an integer array of codes, e.g. from a vmapped solve)."""
    return eqx.tree_at(lambda r: r._value, RESULTS.successful, jnp.asarray(value, RESULTS.successful._value.dtype))


def first_failure(codes: RESULTS) -> RESULTS:
    """The first non-successful code of a batch of codes (successful if none)."""
    values = jnp.ravel(codes._value)
    bad = values != RESULTS.successful._value
    return as_result(jnp.where(jnp.any(bad), values[jnp.argmax(bad)], RESULTS.successful._value))
