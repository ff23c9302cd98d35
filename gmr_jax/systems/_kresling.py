"""Kresling-inspired multi-stable deployable chains (paper Sec. 3.2, Fig. 8; Sec. 4, Fig. 12).

Each cell is a bistable truss unit inspired by the Kresling origami pattern: two rigid regular
polygons (n sides, circumradius R) at height h, the top one twisted by phi relative to the
bottom one, joined by two families of n elastic bars (the creases of the origami),

    a = sqrt(h² + 4R² sin²(phi/2 - pi/(2n))),   b = sqrt(h² + 4R² sin²(phi/2 + pi/(2n))),

with energy U = (n/2) [k_a (a - a0)² + k_b (b - b0)²]. The rest lengths a0, b0 are chosen so
that both bar families are stress free at two heights: the folded height h_f and the deployed
height h_d, with twists phi_f and phi_d = pi - phi_f, cos phi_f = -(h_d² - h_f²) / (4R² cos(pi/n)).
These are the two stable states; between them the bars cannot both be at rest, which makes the
energy barrier. The restoring force F(x) = dU/dx is geometric and not a polynomial.

The deformation coordinate of a cell is x = h - h_f (m): the folded state is x = 0 and the
deployed state x = L = h_d - h_f (the interwell distance).

**Twist.** One relation phi(h) closes the model (`twist`):

- `"linear"` (default): phi varies linearly with h between the two stress-free states,
  phi(x) = phi_f + (phi_d - phi_f) x / L, as if the top plate were guided by a helical track.
  The energy along this path is the exact truss energy; F is its total derivative (the guide
  supplies the torque). It is smooth for every h, has exactly the two stress-free wells, wells of
  similar stiffness (deployed/folded 1.17, as in the paper's Table B5), and is close to, but not,
  a polynomial over the folding range [-0.1 L, 1.1 L] (best least-squares cubic 5.7 %, quintic
  0.15 %, degree 7 0.004 % relative L2 error), so an order-5 global model can reach a few
  per mille, but only if the local fits resolve the curvature (F'') at both wells: a cubic
  Hermite model from the local stiffnesses alone is off by ~20 %.
- `"torque_free"`: the top plate turns freely, phi(h) = argmin_phi U(h, phi) (dU/dphi = 0),
  found by a fixed number of safeguarded Newton steps from the linear twist (jittable); its
  derivatives come from the implicit function theorem (a custom JVP), not from unrolling, so
  forces, stiffnesses and parameter gradients are exact and cheap to compile. A harder truth
  (closer to the paper's prototype, Table B7): the deployed well is ~8x stiffer than the
  folded one, and the curve needs a degree-7 polynomial (best quintic ~3.5 %, best
  degree-7 fit ~0.1 % over the folding range).

**Damping.** F_d = [c0 + c2 ((x - L/2)/(L/2))²] v: viscous c0 at the saddle region rising to
c0 + c2 at both wells (position-dependent, a polynomial of x: exactly representable by the
library's x^j v terms).

Gravity is not modelled (the structure lies horizontally or is weight-compensated along its
guide rod, as the paper's axial prototype).
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._model._model import AbstractMechanicalModel
from .._topology import AbstractTopology, Chain, as_topology
from ._system import System

TWISTS = ("linear", "torque_free")


class KreslingCell(eqx.Module):
    """One bistable Kresling-type truss cell (or, with batched leaves, several of them).

    Every method takes a scalar deformation x = h - h_folded; vmap over the module for several
    cells (`jax.vmap(lambda c, x: c.force(x))(cells, xs)`).

    **Attributes:**

    - `radius`: circumradius R of the polygons (m).
    - `h_folded`, `h_deployed`: the two stress-free (stable) heights (m), h_f < h_d.
    - `k_a`, `k_b`: axial stiffness of one bar of each family (N/m).
    - `c0`, `c2`: damping (N s/m), F_d = [c0 + c2 ((x - L/2)/(L/2))²] v.
    - `n_sides`: polygon sides n (static).
    - `twist`: "linear" or "torque_free" (static, see the module docstring).
    - `newton_steps`: Newton iterations of the torque-free twist (static).
    """

    radius: Float[ArrayLike, "*cells"]
    h_folded: Float[ArrayLike, "*cells"]
    h_deployed: Float[ArrayLike, "*cells"]
    k_a: Float[ArrayLike, "*cells"]
    k_b: Float[ArrayLike, "*cells"]
    c0: Float[ArrayLike, "*cells"] = 0.0
    c2: Float[ArrayLike, "*cells"] = 0.0
    n_sides: int = eqx.field(static=True, default=6)
    twist: str = eqx.field(static=True, default="linear")
    newton_steps: int = eqx.field(static=True, default=12)

    def __check_init__(self):
        if self.twist not in TWISTS:
            raise ValueError(f"twist must be one of {TWISTS}, got {self.twist!r}")
        if self.n_sides < 3:
            raise ValueError(f"n_sides must be >= 3, got {self.n_sides}")

    # -- geometry ------------------------------------------------------------------------
    @property
    def interwell(self):
        """L = h_d - h_f: the deformation of the deployed state (m)."""
        return jnp.asarray(self.h_deployed) - jnp.asarray(self.h_folded)

    def stress_free_twists(self):
        """(phi_f, phi_d): twists of the folded and deployed states (rad), phi_d = pi - phi_f."""
        n = self.n_sides
        hf, hd, r = self.h_folded, self.h_deployed, self.radius
        cos_f = -(hd**2 - hf**2) / (4 * r**2 * math.cos(math.pi / n))
        phi_f = jnp.arccos(cos_f)
        return phi_f, jnp.pi - phi_f

    def bar_lengths_at(self, h, phi):
        """Bar lengths (a, b) at height h and twist phi."""
        c = math.pi / (2 * self.n_sides)
        r2 = 4 * self.radius**2
        a = jnp.sqrt(h**2 + r2 * jnp.sin(phi / 2 - c) ** 2)
        b = jnp.sqrt(h**2 + r2 * jnp.sin(phi / 2 + c) ** 2)
        return a, b

    def rest_lengths(self):
        """(a0, b0): bar lengths at the stress-free states."""
        phi_f, _ = self.stress_free_twists()
        return self.bar_lengths_at(jnp.asarray(self.h_folded, float), phi_f)

    def truss_energy(self, h, phi):
        """U(h, phi) = (n/2) [k_a (a - a0)² + k_b (b - b0)²] (J)."""
        a0, b0 = self.rest_lengths()
        a, b = self.bar_lengths_at(h, phi)
        return 0.5 * self.n_sides * (self.k_a * (a - a0) ** 2 + self.k_b * (b - b0) ** 2)

    def twist_angle(self, x):
        """Twist phi (rad) at deformation x, by the chosen `twist` relation."""
        phi_f, phi_d = self.stress_free_twists()
        if self.twist == "linear":
            return phi_f + (phi_d - phi_f) * x / self.interwell
        return _torque_free_twist(self, jnp.asarray(self.h_folded + x, float))

    def height(self, x):
        return self.h_folded + x

    def bar_lengths(self, x):
        """(a, b) at deformation x."""
        return self.bar_lengths_at(self.height(x), self.twist_angle(x))

    # -- mechanics -----------------------------------------------------------------------
    def energy(self, x):
        """Stored energy U(x) (J); zero at both stable states."""
        return self.truss_energy(self.height(x), self.twist_angle(x))

    def force(self, x):
        """Restoring force F(x) = dU/dx (N), positive in tension (resisting extension).

        Linear twist: in closed form, F = n [k_a (a - a0) a' + k_b (b - b0) b'] with
        a' = (h + R² sin(2α) φ') / a, α = φ/2 - π/(2n), φ' = (φ_d - φ_f)/L (and b with
        β = φ/2 + π/(2n)): the same value as the derivative of `energy` (tested), at a fraction
        of the cost in long simulations. Torque-free twist: derivative of `energy`."""
        x = jnp.asarray(x, float)
        if self.twist != "linear":
            return jax.grad(self.energy)(x)
        phi_f, phi_d = self.stress_free_twists()
        dphi = (phi_d - phi_f) / self.interwell
        h = self.height(x)
        phi = phi_f + dphi * x
        c = math.pi / (2 * self.n_sides)
        r2 = self.radius**2
        a0, b0 = self.rest_lengths()
        a, b = self.bar_lengths_at(h, phi)
        da = (h + r2 * jnp.sin(phi - 2 * c) * dphi) / a
        db = (h + r2 * jnp.sin(phi + 2 * c) * dphi) / b
        return self.n_sides * (self.k_a * (a - a0) * da + self.k_b * (b - b0) * db)

    def stiffness(self, x):
        """Tangent stiffness dF/dx (N/m)."""
        return jax.grad(self.force)(jnp.asarray(x, float))

    def damping(self, x, v):
        """F_d = [c0 + c2 ((x - L/2)/(L/2))²] v (N)."""
        s = (x - 0.5 * self.interwell) / (0.5 * self.interwell)
        return (self.c0 + self.c2 * s**2) * v

    def equilibria(self, n_grid: int = 257, bisections: int = 60):
        """Equilibria and energy barrier (jittable; vmap it for several cells).

        **Returns:** a dict with `stable` (2,) = (0, L) (folded, deployed), `unstable` the saddle
        between them (the maximum of U on a grid, refined by bisection on F), `barrier`
        U(saddle) - U(folded) (J; both wells are at zero energy, so this is also the barrier seen
        from the deployed state) and `stiffness` (2,) the tangent stiffness at the two stable
        states (N/m).
        """
        L = self.interwell
        grid = jnp.linspace(0.0, 1.0, n_grid) * L
        u = jax.vmap(self.energy)(grid)
        j = jnp.clip(jnp.argmax(u[1:-1]) + 1, 1, n_grid - 2)

        def bisect(_, lohi):
            lo, hi = lohi
            mid = 0.5 * (lo + hi)
            right = self.force(mid) > 0  # F > 0 on the folded side of the saddle
            return jnp.where(right, mid, lo), jnp.where(right, hi, mid)

        lo, hi = jax.lax.fori_loop(0, bisections, bisect, (grid[j - 1], grid[j + 1]))
        x = 0.5 * (lo + hi)
        stable = jnp.stack([jnp.zeros_like(L), L])
        return {
            "stable": stable,
            "unstable": x,
            "barrier": self.energy(x) - self.energy(stable[0]),
            "stiffness": jax.vmap(self.stiffness)(stable),
        }


def _newton_twist(cell: KreslingCell, h):
    """phi with dU/dphi(h, phi) = 0: safeguarded Newton from the linear twist."""
    phi_f, phi_d = cell.stress_free_twists()
    phi = phi_f + (phi_d - phi_f) * (h - cell.h_folded) / cell.interwell
    dU = jax.grad(cell.truss_energy, argnums=1)
    d2U = jax.grad(dU, argnums=1)
    max_step = 0.25 * (phi_f - phi_d)

    def newton(_, p):
        g, k = dU(h, p), d2U(h, p)
        # Newton where the energy is convex in phi, else a descent step; clipped.
        step = jnp.where(k > 0, -g / jnp.where(k > 0, k, 1.0), -jnp.sign(g) * max_step)
        return p + jnp.clip(step, -max_step, max_step)

    return jax.lax.fori_loop(0, cell.newton_steps, newton, phi)


@jax.custom_jvp
def _torque_free_twist(cell: KreslingCell, h):
    return _newton_twist(cell, h)


@_torque_free_twist.defjvp
def _torque_free_twist_jvp(primals, tangents):
    # Implicit function theorem on g(cell, h, phi) = dU/dphi = 0: no differentiation through
    # the Newton iterations (cheap to compile, exact at convergence, any order).
    cell, h = primals
    phi = _torque_free_twist(cell, h)

    def g(c, hh, p):
        return jax.grad(c.truss_energy, argnums=1)(hh, p)

    _, g_dot = jax.jvp(lambda c, hh: g(c, hh, phi), (cell, h), tangents)
    g_phi = jax.grad(g, argnums=2)(cell, h, phi)
    return phi, -g_dot / g_phi


class KreslingChain(AbstractMechanicalModel):
    """A serial chain of `KreslingCell`s (cell 0 at the base), one mass on top of each cell.

    Equation of motion of `AbstractMechanicalModel` (topology "chain"): x_i is the deformation
    of cell i (m), `masses[i]` (kg) the plate on top of it.

    **Attributes:** `masses` (dof,); `cells`: a `KreslingCell` whose leaves have shape (dof,).
    """

    masses: Float[Array, " dof"]
    cells: KreslingCell
    topology: AbstractTopology = eqx.field(static=True, default=Chain(), converter=as_topology)

    def restoring(self, x: Float[Array, " dof"]) -> Float[Array, " dof"]:
        return jax.vmap(lambda c, xi: c.force(xi))(self.cells, x)

    def damping(self, x: Float[Array, " dof"], v: Float[Array, " dof"]) -> Float[Array, " dof"]:
        return jax.vmap(lambda c, xi, vi: c.damping(xi, vi))(self.cells, x, v)

    def energy(self, x: Float[Array, " dof"]) -> Float[Array, ""]:
        """Total stored energy (J)."""
        return jnp.sum(jax.vmap(lambda c, xi: c.energy(xi))(self.cells, x))

    @property
    def interwell(self) -> Float[Array, " dof"]:
        return self.cells.interwell


@eqx.filter_jit
def _equilibria(cells: KreslingCell) -> dict:
    if jnp.ndim(cells.radius) == 0:
        return cells.equilibria()
    return jax.vmap(lambda c: c.equilibria())(cells)


def cell_equilibria(model: "KreslingChain | KreslingCell") -> dict:
    """Stable states (folded, deployed), saddle and energy barrier of every cell.

    **Returns:** a dict of NumPy arrays: `stable` (dof, 2) deformations of the folded (0) and
    deployed (L) states, `unstable` (dof,), `barrier` (dof,) in J (the energy to climb from
    either well to the saddle: both wells are at zero energy) and `stiffness` (dof, 2), the
    tangent stiffness at the two stable states in N/m. A single unbatched cell gives shapes
    (2,), (), (), (2,).
    """
    cells = model.cells if isinstance(model, KreslingChain) else model
    return {k: np.asarray(v) for k, v in _equilibria(cells).items()}


@eqx.filter_jit
def _folded_stiffness(cells: KreslingCell):
    return jax.vmap(lambda c: c.stiffness(0.0))(cells)


def kresling_chain(
    stiffness: ArrayLike,
    masses: ArrayLike,
    *,
    radius: ArrayLike = 0.05,
    h_folded: ArrayLike = 0.02,
    h_deployed: ArrayLike = 0.05,
    bar_ratio: float = 1.0,
    damping_ratio: ArrayLike = 0.04,
    damping_well_fraction: float = 0.5,
    n_sides: int = 6,
    twist: str = "linear",
) -> KreslingChain:
    """Build a Kresling chain from engineering targets.

    **Arguments:**

    - `stiffness` (dof,): tangent stiffness of each cell at its folded state (N/m); the bar
      stiffnesses are scaled to give it (k_b = k_a / `bar_ratio`).
    - `masses` (dof,): plate masses (kg).
    - `radius`, `h_folded`, `h_deployed`: geometry (m), scalars or per cell.
    - `damping_ratio`: per cell, c_well = 2 ζ sqrt(k_f m_i) is the damping coefficient at the
      wells; `damping_well_fraction` of it is position dependent (c2), the rest viscous (c0).
    - `n_sides`, `twist`: see `KreslingCell`.
    """
    k = np.asarray(stiffness, float).reshape(-1)
    m = np.asarray(masses, float).reshape(-1)
    d = k.shape[0]
    if m.shape[0] != d:
        raise ValueError(f"{d} stiffnesses but {m.shape[0]} masses")
    geo = {
        name: np.broadcast_to(np.asarray(val, float), (d,)).copy()
        for name, val in (("radius", radius), ("h_folded", h_folded), ("h_deployed", h_deployed))
    }
    lim = 4 * geo["radius"] ** 2 * math.cos(math.pi / n_sides)
    bad = (
        (geo["h_deployed"] <= geo["h_folded"])
        | (geo["h_folded"] <= 0)
        | (geo["h_deployed"] ** 2 - geo["h_folded"] ** 2 >= lim)
    )
    if np.any(bad):
        raise ValueError(
            "need 0 < h_folded < h_deployed and h_deployed² - h_folded² < 4R² cos(pi/n) "
            "(no stress-free twist otherwise)"
        )
    unit = KreslingCell(
        jnp.asarray(geo["radius"]),
        jnp.asarray(geo["h_folded"]),
        jnp.asarray(geo["h_deployed"]),
        jnp.ones(d),
        jnp.full(d, 1.0 / bar_ratio),
        jnp.zeros(d),
        jnp.zeros(d),
        n_sides=n_sides,
        twist=twist,
    )
    k_unit = np.asarray(_folded_stiffness(unit))
    scale = k / k_unit
    zeta = np.broadcast_to(np.asarray(damping_ratio, float), (d,))
    c_well = 2 * zeta * np.sqrt(k * m)
    cells = KreslingCell(
        radius=jnp.asarray(geo["radius"]),
        h_folded=jnp.asarray(geo["h_folded"]),
        h_deployed=jnp.asarray(geo["h_deployed"]),
        k_a=jnp.asarray(scale),
        k_b=jnp.asarray(scale / bar_ratio),
        c0=jnp.asarray((1 - damping_well_fraction) * c_well),
        c2=jnp.asarray(damping_well_fraction * c_well),
        n_sides=n_sides,
        twist=twist,
    )
    return KreslingChain(masses=jnp.asarray(m), cells=cells)


# -- built-in benchmarks -------------------------------------------------------------------

#: 5-cell chain: folded-state stiffness graded 1 : 1.6 : 3 : 5 : 10 from the base (the paper's
#: Table B5 grading), 40 g plates, 6-sided cells R = 50 mm, h_f = 20 mm, h_d = 50 mm (L = 30 mm).
KRESLING5_STIFFNESS = (20.0, 32.0, 60.0, 100.0, 200.0)
KRESLING5_MASSES = (0.04, 0.04, 0.04, 0.04, 0.04)
#: Nominal base-displacement amplitude (m) for `make_recordings(kresling5(), ...)`: amplitude
#: ratios (half peak-to-peak / L) about 5.1, 2.6, 2.4, 1.3, 0.35 % (folded) and 5.7, 2.8, 2.5,
#: 1.4, 0.38 % (deployed), base to tip (0.5 mm: 8.5 ... 0.6 %; 1 mm: 16 ... 1.1 %).
KRESLING5_AMPLITUDE = 3e-4
#: Damping ratio of the deployment-basin benchmark chain: the smallest of 0.04, 0.1, 0.2, 0.3 at
#: which the truth's own 100 x 100 map keeps >= 95 % of its points when every stiffness changes
#: by 1 % (95.3 %; 0.1: 88.5 %; 0.04: 71.9 %, and 89.7 % already at +0.1 %), so that the map tests
#: the model rather than the chaos of a lightly damped chain. The quasi-static regime then deploys
#: the cells mostly in order of stiffness (61 % of points at f <= 0.5 Hz end in 0-0-0-0-0,
#: 1-0-0-0-0, ..., 1-1-1-1-1; 33 % at 0.04), closer to the paper's Fig. 11 description.
#: Measured by studies/kresling_basins_ceiling.py.
KRESLING5_DEPLOYMENT_DAMPING = 0.2
#: Base amplitude (m) for `make_recordings(kresling5(damping_ratio=0.2), ...)`: amplitude ratios
#: about 5.2, 2.9, 1.2, 0.5, 0.14 % (folded), base to tip: the nominal chain's 5 % at the base.
KRESLING5_DEPLOYMENT_AMPLITUDE = 5e-4


def _interwell_box(chain: KreslingChain, margin: float = 0.1):
    L = np.asarray(chain.interwell)
    return np.stack([-margin * L, (1 + margin) * L], axis=1)


def _chain_system(name: str, chain: KreslingChain, twist: str, sweep, amplitude: float) -> System:
    """A built-in Kresling benchmark: trained on the fully folded and fully deployed
    configurations, 30 s base chirp at 1 kHz, metrics box 10 % beyond both wells, |v| <= 0.1 m/s."""
    L = np.asarray(chain.interwell)
    return System(
        name=name if twist == "linear" else f"{name}_{twist}",
        truth=chain,
        equilibria=np.stack([np.zeros_like(L), L]),
        sweep=sweep,
        duration=30.0,
        fs=1000.0,
        x_range=_interwell_box(chain),
        v_range=np.tile([[-0.1, 0.1]], (L.shape[0], 1)),
        orders={"gmr": (5, 5), "gmc": (5, 5)},
        description=f"{L.shape[0]}-cell Kresling-inspired bistable truss chain ({twist} twist), base "
        f"excited (nominal amplitude {amplitude * 1e3:g} mm)",
        units=("x [m]", "x' [m/s]", "F [N]"),
        designs=np.zeros(L.shape[0], int),
    )


def kresling5(twist: str = "linear", damping_ratio: float = 0.04) -> System:
    """The 5-DOF Kresling-inspired deployable chain (paper Sec. 3.2, Fig. 8).

    Cells numbered from the base; the base cell is the softest (folded-state stiffness
    20, 32, 60, 100, 200 N/m; 40 g plates; linear modes 1.25, 4.8, 7.6, 11.2, 17.4 Hz folded).
    Training data: base chirp 0.5-10 Hz over 30 s around the fully folded (0-0-0-0-0) and fully
    deployed (1-1-1-1-1) configurations; `KRESLING5_AMPLITUDE` (0.3 mm) gives amplitude ratios
    of a few percent of the interwell distance at the base, shrinking towards the tip.
    Metrics box: x from 10 % before the folded to 10 % past the deployed state, |v| <= 0.1 m/s.
    `twist="torque_free"` gives the harder, strongly asymmetric variant. `damping_ratio` at the
    wells (default 0.04); `KRESLING5_DEPLOYMENT_DAMPING` (0.2) is the deployment-basin benchmark's
    (see `studies/kresling_basins.py`), with base amplitude `KRESLING5_DEPLOYMENT_AMPLITUDE`
    for the same ~5 % amplitude ratio at the base cell.
    """
    chain = kresling_chain(KRESLING5_STIFFNESS, KRESLING5_MASSES, twist=twist, damping_ratio=damping_ratio)
    name = "kresling5" if damping_ratio == 0.04 else f"kresling5_z{damping_ratio:g}"
    return _chain_system(name, chain, twist, (0.5, 10.0), KRESLING5_AMPLITUDE)


#: 3-cell prototype-like chain (paper Sec. 4, Fig. 12): one stiff and one soft cell, echoing the
#: prototype's Table B7 (folded-state stiffness about 4 : 5 : 1 there, in the paper's numbering,
#: which may run from the tip; milder here), 50 g plates.
KRESLING3_STIFFNESS = (40.0, 60.0, 25.0)
KRESLING3_MASSES = (0.05, 0.05, 0.05)
#: Nominal base amplitude (m): amplitude ratios about 5.5, 3.0, 5.5 % (folded), 6.0, 3.1, 5.9 %.
KRESLING3_AMPLITUDE = 3e-4


def kresling3(twist: str = "linear") -> System:
    """A 3-cell Kresling chain like the paper's experimental prototype (Sec. 4), trained on the
    0-0-0 and 1-1-1 configurations with a base chirp 0.5-12 Hz over 30 s."""
    chain = kresling_chain(KRESLING3_STIFFNESS, KRESLING3_MASSES, twist=twist)
    return _chain_system("kresling3", chain, twist, (0.5, 12.0), KRESLING3_AMPLITUDE)
