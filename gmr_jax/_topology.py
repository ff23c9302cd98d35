"""How the DOFs of a model are connected: the equations of motion of the contracts.

- `Independent()`: each DOF its own mass on the (moving) ground,
  m_i a_i + F_i(x_i, v_i) = force_i, with a_i = x_i'' + base_acc.
- `Chain()`: a serial chain of cells numbered from the base; x_i is the deformation of cell i,
  the absolute acceleration of mass i is a_i = x_0'' + ... + x_i'' + base_acc, and cell i
  carries the inertia of every mass beyond it (paper Eq. 9, written base-first):
  (H a)_i + F_i(x_i, v_i) = sum_{k>=i} force_k, (H a)_i = sum_{k>=i} m_k a_k.

Every place that needs the equations of motion (model accelerations, regression targets of the
local fits, recordings' absolute accelerations, discovery's rows, the tip response of a
frequency sweep) asks the topology. Arrays of either library work: NumPy in, NumPy out.
"""

import abc
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._errors import GMRInputError


def _xp(a):
    return np if isinstance(a, np.ndarray) else jnp


class AbstractTopology(eqx.Module):
    """The equations of motion of a lumped model (see the module docstring)."""

    name: ClassVar[str]

    @abc.abstractmethod
    def carried(self, per_mass):
        """Force carried by each DOF (..., D) from the net force on each mass (..., D),
        force_k - m_k a_k: the left side of the local regression (Eq. 8)."""

    @abc.abstractmethod
    def accelerations(self, restoring_damping, masses, base_acc, force):
        """Relative accelerations x'' (D,) from the model force F (D,), the masses, the base
        acceleration (scalar) and the external forces (D,)."""

    @abc.abstractmethod
    def displacements(self, x):
        """Displacement of each mass relative to the base (..., D) from the coordinates x."""

    @abc.abstractmethod
    def tip(self, x):
        """Displacement of the last mass relative to the base (...,) from x (..., D)."""

    def absolute(self, xdd, base_acc):
        """Absolute accelerations a (..., D) of the masses from relative ones x'' (..., D)."""
        xp = _xp(xdd)
        return self.displacements(xdd) + xp.expand_dims(base_acc, -1)

    def __str__(self):
        return self.name

    def __eq__(self, other):
        # `model.topology == "chain"` keeps working for code written against the string form
        if isinstance(other, str):
            return self.name == other
        return type(self) is type(other)

    def __hash__(self):
        return hash(self.name)


class Independent(AbstractTopology):
    """Each DOF its own mass on the ground: m_i a_i + F_i = force_i."""

    name: ClassVar[str] = "independent"

    def carried(self, per_mass):
        return per_mass

    def accelerations(self, restoring_damping, masses, base_acc, force):
        return (force - restoring_damping) / masses - base_acc

    def displacements(self, x):
        return x

    def tip(self, x):
        return x[..., -1]


class Chain(AbstractTopology):
    """A serial chain of cells from the base: (H a)_i + F_i = sum_{k>=i} force_k."""

    name: ClassVar[str] = "chain"

    def carried(self, per_mass):
        xp = _xp(per_mass)
        return xp.cumsum(per_mass[..., ::-1], axis=-1)[..., ::-1]

    def accelerations(self, restoring_damping, masses, base_acc, force):
        f = restoring_damping
        # (H a)_i = g_i = sum_{k>=i} force_k - F_i, so m_i a_i = g_i - g_{i+1}
        # = force_i - F_i + F_{i+1}: no cumulative sum needed (O(dof) per evaluation)
        f_next = jnp.concatenate([f[1:], jnp.zeros(1, f.dtype)])
        a = (force - f + f_next) / masses
        a_prev = jnp.concatenate([jnp.reshape(base_acc, (1,)), a[:-1]])
        return a - a_prev

    def displacements(self, x):
        return _xp(x).cumsum(x, axis=-1)

    def tip(self, x):
        return _xp(x).sum(x, axis=-1)


TOPOLOGIES = {"chain": Chain(), "independent": Independent()}


def as_topology(topology) -> AbstractTopology:
    """A topology object from itself or its name ("chain" | "independent")."""
    if isinstance(topology, AbstractTopology):
        return topology
    if isinstance(topology, str) and topology in TOPOLOGIES:
        return TOPOLOGIES[topology]
    raise GMRInputError(f"topology must be one of {tuple(TOPOLOGIES)}, got {topology!r}")
