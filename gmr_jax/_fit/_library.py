"""Candidate function libraries, paper Eqs. (5)-(7)."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._custom_types import Array, Float
from .._errors import GMRInputError, as_whole_number, describe
from .._topology import _xp

# `physics` names of the "gmr-model/1" format, per family.
STIFFNESS = "stiffness"
VELOCITY_DAMPING = "velocity_damping"
POSITION_DAMPING = "position_damping"


def signed_power(v, j: int, sign_eps: float = 0.0):
    """sgn(v)|v|^j (Eq. 7); with `sign_eps > 0`, sgn is smoothed to tanh(v / sign_eps). NumPy in,
    NumPy out (figures evaluate a model without JAX); JAX arrays and tracers otherwise."""
    xp = _xp(v)
    s = xp.sign(v) if sign_eps == 0.0 else xp.tanh(v / sign_eps)
    if j == 0:
        return s
    if j % 2 == 1:
        return v**j if sign_eps == 0.0 else s * xp.abs(v) ** j
    return s * xp.abs(v) ** j


def damping_columns(x, v, n_velocity: int, n_position: int, sign_eps: float = 0.0):
    """The global model's damping basis at (x, v) (Eqs. 1, 7), on a new last axis: sgn(v)|v|^j for the velocity
    damping B_j, j < `n_velocity`, then x^j v for the position damping C_j, j < `n_position` (j = 0 included, as
    `GlobalModel.position_damping` holds it). `x`, `v` broadcast together; NumPy in, NumPy out, JAX otherwise.
    The one definition of the damping force's rows: the force is `damping_columns(...) @ [B; C]`."""
    xp = _xp(v)
    x, v = xp.broadcast_arrays(xp.asarray(x), xp.asarray(v))
    cols = [signed_power(v, j, sign_eps) for j in range(n_velocity)] + [x**j * v for j in range(n_position)]
    return xp.stack(cols, axis=-1) if cols else xp.zeros(v.shape + (0,), v.dtype)


class Library(eqx.Module):
    """Polynomial library of the paper, Eqs. (5)-(7).

    Columns, in order: restoring `x^k`, k = 0..`restoring_order` (Eq. 6); position-independent
    damping `sgn(v)|v|^j`, j = 0..`damping_order`; position-dependent damping `x^j v`,
    j = 1..`damping_order` (Eq. 7 written with x^j v rather than |x|^j |v|, so that a shift
    of x keeps it a polynomial, which the coordination needs; j = 0 is the viscous term,
    already in the previous family).

    **Arguments:**

    - `restoring_order`: r, highest power of the restoring polynomial.
    - `damping_order`: d, highest power of both damping families.
    - `velocity_damping`, `position_damping`: include those families.

    Examples:
        >>> import gmr_jax as gmr
        >>> lib = gmr.Library(restoring_order=3, damping_order=2)
        >>> lib.names()
        ['1', 'x', 'x^2', 'x^3', 'sgn(v)', 'v', 'sgn(v)|v|^2', 'x*v', 'x^2*v']
        >>> lib.n_terms
        9
    """

    restoring_order: int = eqx.field(static=True, default=5)
    damping_order: int = eqx.field(static=True, default=5)
    velocity_damping: bool = eqx.field(static=True, default=True)
    position_damping: bool = eqx.field(static=True, default=True)

    def __check_init__(self):
        as_whole_number(self.restoring_order, "Library.restoring_order", lo=1,
                        fix="give the highest power of the restoring polynomial, an int >= 1 (e.g. 5)")
        as_whole_number(self.damping_order, "Library.damping_order", lo=0,
                        fix="give the highest power of the damping families, an int >= 0 (e.g. 5)")
        for name in ("velocity_damping", "position_damping"):
            val = getattr(self, name)
            if not isinstance(val, (bool, np.bool_)):
                raise GMRInputError(f"Library.{name} must be True or False, got {describe(val)}")

    def terms(self) -> list[tuple[str, int]]:
        """(physics, order) of every column, in column order."""
        out = [(STIFFNESS, k) for k in range(self.restoring_order + 1)]
        if self.velocity_damping:
            out += [(VELOCITY_DAMPING, j) for j in range(self.damping_order + 1)]
        if self.position_damping:
            out += [(POSITION_DAMPING, j) for j in range(1, self.damping_order + 1)]
        return out

    @property
    def n_terms(self) -> int:
        return len(self.terms())

    def names(self, x: str = "x", v: str = "v") -> list[str]:
        return [term_name(p, k, x, v) for p, k in self.terms()]

    def indices(self, physics: str) -> np.ndarray:
        return np.array([i for i, (p, _) in enumerate(self.terms()) if p == physics], dtype=int)

    def orders(self, physics: str) -> np.ndarray:
        return np.array([k for p, k in self.terms() if p == physics], dtype=int)

    def column(self, physics: str, order: int) -> int:
        """The column of the term (`physics`, `order`), e.g. `column(STIFFNESS, 1)`: the local stiffness."""
        return self.terms().index((physics, order))

    def __call__(
        self, x: Float[Array, " samples"], v: Float[Array, " samples"], sign_eps: float = 0.0
    ) -> Float[Array, "samples terms"]:
        cols = []
        for p, k in self.terms():
            if p == STIFFNESS:
                cols.append(x**k)
            elif p == VELOCITY_DAMPING:
                cols.append(signed_power(v, k, sign_eps))
            else:
                cols.append(x**k * v)
        return jnp.stack(cols, axis=-1)


def term_name(physics: str, order: int, x: str = "x", v: str = "v") -> str:
    """Readable name of one basis function, e.g. `x^3`, `sgn(v)|v|^2`, `x^2*v`."""

    def pw(s, k):
        return "1" if k == 0 else (s if k == 1 else f"{s}^{k}")

    if physics == STIFFNESS:
        return pw(x, order)
    if physics == VELOCITY_DAMPING:
        if order == 0:
            return f"sgn({v})"
        if order % 2 == 1:
            return pw(v, order)
        return f"sgn({v})|{v}|^{order}" if order > 1 else f"|{v}|"
    if physics == POSITION_DAMPING:
        return f"{pw(x, order)}*{v}" if order else v
    return f"{physics}[{order}]"
