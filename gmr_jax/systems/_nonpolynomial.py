"""Non-polynomial single-DOF bistable truths (issue 15): a reconstruction can only approximate
them, as it would a real structure."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float
from scipy.optimize import brentq

from .._model._model import AbstractMechanicalModel
from .._topology import AbstractTopology, Independent, as_topology
from ._system import System


class _Oscillator(AbstractMechanicalModel):
    masses: eqx.AbstractVar[Float[Array, " dof"]]
    c: eqx.AbstractVar[float]
    c2: eqx.AbstractVar[float]

    def damping(self, x, v):
        return self.c * v + self.c2 * v * jnp.abs(v)


class ShallowArch(_Oscillator):
    """A von Mises truss (two bars of stiffness `k`, half-span `w`, rise `rise`) loaded by a
    preload `p`: F_r(x) = k x (1 - L0 / sqrt(w^2 + x^2)) + p, L0 = sqrt(w^2 + rise^2);
    damping c v + c2 v|v| (viscous plus air drag)."""

    masses: Float[Array, " dof"]
    k: float = 100.0
    w: float = 2.0
    rise: float = 1.0
    p: float = 2.0
    c: float = 0.18
    c2: float = 0.05
    topology: AbstractTopology = eqx.field(static=True, default=Independent(), converter=as_topology)

    def restoring(self, x):
        l0 = (self.w**2 + self.rise**2) ** 0.5
        return self.k * x * (1.0 - l0 / jnp.sqrt(self.w**2 + x**2)) + self.p


class MagneticOscillator(_Oscillator):
    """A mass on a spring `k` attracted by a magnet at offset `offset` and gap `gap`:
    F_r(x) = k x - beta (x - e) / ((x - e)^2 + d^2)^(3/2); damping c v + c2 v|v|. Its force
    between the wells is far from what Taylor data at the wells fix (the Hermite interpolant
    of the exact value, slope and curvature at both wells is 21 % off): a hard case."""

    masses: Float[Array, " dof"]
    k: float = 100.0
    beta: float = 200.0
    gap: float = 1.0
    offset: float = 0.1
    c: float = 0.5
    c2: float = 0.05
    topology: AbstractTopology = eqx.field(static=True, default=Independent(), converter=as_topology)

    def restoring(self, x):
        u = x - self.offset
        return self.k * x - self.beta * u / (u**2 + self.gap**2) ** 1.5


def stable_roots(model, lo: float = -5.0, hi: float = 5.0) -> np.ndarray:
    """Stable equilibria of a single-DOF model (F_r = 0, F_r' > 0) on [lo, hi]."""
    force = jax.jit(lambda x: model.restoring(x[None])[0])  # one compiled scalar force
    f = lambda x: float(force(jnp.asarray(x, dtype=float)))  # noqa: E731
    grid = np.linspace(lo, hi, 10001)
    val = np.asarray(jax.jit(jax.vmap(force))(jnp.asarray(grid)))  # the scan in one program
    idx = np.nonzero(np.sign(val[:-1]) != np.sign(val[1:]))[0]
    roots = np.array([brentq(f, grid[i], grid[i + 1], xtol=1e-14) for i in idx])
    return roots[[f(r + 1e-6) > f(r - 1e-6) for r in roots]]


def _system(name, model, description) -> System:
    stable = stable_roots(model)
    span = stable[-1] - stable[0]
    return System(
        name=name,
        truth=model,
        equilibria=stable[:, None],
        sweep=(0.2, 3.0),
        duration=60.0,
        fs=100.0,
        x_range=np.array([[stable[0] - 0.25 * span, stable[-1] + 0.25 * span]]),
        v_range=np.array([[-3.0, 3.0]]),
        orders={"gmr": (5, 5), "gmc": (7, 7)},
        description=description,
        units=("x", "x'", "F"),
    )


def shallow_arch() -> System:
    """Preloaded shallow arch (`ShallowArch`, per unit mass): wells at x = -1.090 and 0.884
    (local stiffness 24.3 and 14.4: 0.78 and 0.60 Hz), saddle at 0.176. The Hermite interpolant
    of the exact value and slope at both wells is 14.6 % off over the box, with the curvature
    2.6 %, with F''' 0.5 %."""
    return _system("arch", ShallowArch(masses=jnp.ones(1)),
                   "preloaded shallow arch (von Mises truss, non-polynomial restoring force)")


def magnetic_bistable() -> System:
    """Asymmetric magnetic bistable oscillator (`MagneticOscillator`, per unit mass): wells at
    x = -0.752 and 0.768; the hard non-polynomial case."""
    return _system("magnet", MagneticOscillator(masses=jnp.ones(1)),
                   "asymmetric magnetic bistable oscillator (non-polynomial restoring force)")
