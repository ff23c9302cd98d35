"""The global mechanical model (paper Eq. 1), in the "gmr-model/1" term vocabulary."""

import abc
import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._fit._library import POSITION_DAMPING, STIFFNESS, VELOCITY_DAMPING, signed_power, term_name
from .._topology import AbstractTopology, Independent, as_topology


def polyval(coef: Float[Array, " orders"], x):
    """sum_k coef[k] x^k by Horner's rule."""
    out = jnp.zeros_like(x)
    for c in coef[::-1]:
        out = out * x + c
    return out


class AbstractMechanicalModel(eqx.Module):
    """A lumped model: masses plus a restoring-and-damping force per DOF (cell).

    Equation of motion (contracts): independent, m_i a_i + F_i(x_i, v_i) = force_i;
    chain (cells numbered from the base), (H a)_i + F_i(x_i, v_i) = sum_{k>=i} force_k with
    (H a)_i = sum_{k>=i} m_k a_k (paper Eq. 9 for base-first numbering). a is the absolute
    acceleration: a_i = x_0'' + ... + x_i'' + base_acc for a chain, x_i'' + base_acc otherwise.
    """

    masses: eqx.AbstractVar[Float[Array, " dof"]]
    topology: eqx.AbstractVar[AbstractTopology]

    def force(self, x: Float[Array, " dof"], v: Float[Array, " dof"]) -> Float[Array, " dof"]:
        return self.restoring(x) + self.damping(x, v)

    @abc.abstractmethod
    def restoring(self, x: Float[Array, " dof"]) -> Float[Array, " dof"]:
        """Restoring force F_r of each DOF at deformations x."""

    @abc.abstractmethod
    def damping(self, x: Float[Array, " dof"], v: Float[Array, " dof"]) -> Float[Array, " dof"]:
        """Damping force F_d of each DOF."""

    @property
    def n_dof(self) -> int:
        return int(np.shape(self.masses)[0])

    def accelerations(self, x, v, base_acc, force) -> Float[Array, " dof"]:
        """Relative accelerations x'' of every DOF, given base acceleration and forces."""
        return self.topology.accelerations(self.force(x, v), self.masses, base_acc, force)

    def absolute_accelerations(self, xdd, base_acc):
        """Absolute accelerations a of the masses from relative ones x'' (..., dof)."""
        return self.topology.absolute(xdd, base_acc)


class GlobalModel(AbstractMechanicalModel):
    """Polynomial global model: per DOF i,
    F_i(x, v) = sum_k K_ik x^k + sum_j B_ij sgn(v)|v|^j + (sum_j C_ij x^j) v.

    **Attributes:**

    - `masses` (dof,); `topology`: `Chain()` or `Independent()` (or their names).
    - `stiffness` (dof, orders): K_ik, coefficient of x^k (`stiffness` order k).
    - `velocity_damping` (dof, orders): B_ij of sgn(v)|v|^j.
    - `position_damping` (dof, orders): C_ij of x^j v.
    - `stderr`: optional standard errors, same structure (from the coordination's covariance).
    - `sign_eps`: 0 for the exact sgn(v); > 0 replaces it by tanh(v/eps) (for gradients).
    """

    masses: Float[Array, " dof"]
    stiffness: Float[Array, "dof orders"]
    velocity_damping: Float[Array, "dof orders"]
    position_damping: Float[Array, "dof orders"]
    topology: AbstractTopology = eqx.field(static=True, default=Independent(), converter=as_topology)
    sign_eps: float = eqx.field(static=True, default=0.0)
    stderr: dict | None = None

    def restoring(self, x):
        return jax.vmap(polyval)(self.stiffness, x)

    def damping(self, x, v):
        out = jax.vmap(polyval)(self.position_damping, x) * v
        for j in range(self.velocity_damping.shape[1]):
            out = out + self.velocity_damping[:, j] * signed_power(v, j, self.sign_eps)
        return out

    def with_sign_eps(self, eps: float) -> "GlobalModel":
        """A copy whose sgn(v) terms are smoothed to tanh(v/eps) (for differentiation)."""
        return dataclasses.replace(self, sign_eps=float(eps))

    # -- readable form ---------------------------------------------------------------
    def terms(self, tol: float = 0.0) -> list[dict]:
        """Nonzero terms as "gmr-model/1" term dicts (with `stderr` where known)."""
        out = []
        for name, arr in (
            (STIFFNESS, self.stiffness),
            (VELOCITY_DAMPING, self.velocity_damping),
            (POSITION_DAMPING, self.position_damping),
        ):
            a = np.asarray(arr)
            se = None if self.stderr is None else self.stderr.get(name)
            for i in range(a.shape[0]):
                for k in range(a.shape[1]):
                    if a[i, k] != 0.0 and abs(a[i, k]) > tol:
                        t = {"dof": i, "physics": name, "order": k, "coefficient": float(a[i, k])}
                        if se is not None and np.isfinite(se[i, k]):
                            t["stderr"] = float(np.asarray(se)[i, k])
                        out.append(t)
        return out

    def equations(self, precision: int = 4, x: str = "x", v: str = "v") -> list[str]:
        """One readable line per DOF: `F_0(x, v) = -2244 x + 1755 x^3 + 10 v^3`."""
        lines = []
        for i in range(self.n_dof):
            parts = []
            for t in self.terms():
                if t["dof"] != i:
                    continue
                name = term_name(t["physics"], t["order"], x, v)
                c = t["coefficient"]
                cs = f"{c:.{precision}g}"
                parts.append(cs if name == "1" else f"{cs} {name}")
            body = " + ".join(parts).replace("+ -", "- ") or "0"
            lines.append(f"F_{i}({x}, {v}) = {body}")
        return lines

    def __str__(self):
        return "\n".join(self.equations())


def from_terms(
    masses, terms: list[dict], topology: str = "independent", *, min_orders: dict | None = None
) -> GlobalModel:
    """Build a `GlobalModel` from "gmr-model/1" term dicts (coefficients of repeated terms add)."""
    masses = np.asarray(masses, dtype=np.float64).reshape(-1)
    d = masses.shape[0]
    min_orders = min_orders or {}
    arrays, errs = {}, {}
    for name in (STIFFNESS, VELOCITY_DAMPING, POSITION_DAMPING):
        orders = [int(t["order"]) for t in terms if t["physics"] == name]
        size = max([o + 1 for o in orders] + [min_orders.get(name, 1)])
        arrays[name] = np.zeros((d, size))
        errs[name] = np.full((d, size), np.nan)
    for t in terms:
        arrays[t["physics"]][int(t["dof"]), int(t["order"])] += float(t["coefficient"])
        if "stderr" in t:
            errs[t["physics"]][int(t["dof"]), int(t["order"])] = float(t["stderr"])
    has_err = any("stderr" in t for t in terms)
    return GlobalModel(
        masses=jnp.asarray(masses),
        stiffness=jnp.asarray(arrays[STIFFNESS]),
        velocity_damping=jnp.asarray(arrays[VELOCITY_DAMPING]),
        position_damping=jnp.asarray(arrays[POSITION_DAMPING]),
        topology=topology,
        stderr={k: jnp.asarray(v) for k, v in errs.items()} if has_err else None,
    )
