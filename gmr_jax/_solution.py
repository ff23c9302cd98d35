from typing import Any

import equinox as eqx
from jaxtyping import PyTree


class RESULTS(eqx.Enumeration):
    """Result codes of every gmr_jax entry point (read them with `throw=False` under vmap)."""

    successful = ""
    max_iterations_reached = (
        "STLS did not converge: the support was still changing at `max_iter`. "
        "Increase `max_iter` or the threshold."
    )
    nonfinite = "Non-finite (NaN or inf) values appeared in the computation."
    ill_posed_coordination = (
        "The coordination system is singular or too ill-conditioned to solve: the equilibria "
        "coincide, or the local orders do not determine a unique global polynomial."
    )
    simulation_failed = "The ODE solver failed (step size collapse or max_steps reached)."
    diverged = "The simulated state left the region where the model is valid (diverged)."
    not_settled = "The simulation had not settled into an equilibrium by the final time."


class Solution(eqx.Module):
    """The result of a gmr_jax computation.

    **Attributes:**

    - `value`: the answer (coefficients, a model, a trajectory...).
    - `result`: a `RESULTS` code; `RESULTS[sol.result]` gives the message.
    - `stats`: diagnostics (iterations, condition numbers, supports...).
    - `aux`: further outputs, e.g. a covariance.
    """

    value: PyTree
    result: RESULTS
    stats: dict[str, PyTree]
    aux: Any = None


def error_if_failed(sol: Solution, throw: bool) -> Solution:
    """Raise the result's message (inside or outside jit) when `throw` is true."""
    if throw:
        sol = eqx.tree_at(
            lambda s: s.value,
            sol,
            sol.result.error_if(sol.value, sol.result != RESULTS.successful),
        )
    return sol
