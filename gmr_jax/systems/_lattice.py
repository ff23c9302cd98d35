"""Lattices of bistable elements on a `Graph`: a 2 x 8 ladder and a 4 x 4 grid.

Every bistable element is one design, a preloaded von Mises truss (the shallow arch's law,
`ShallowArch`): F(d) = k d (1 - L0 / sqrt(w^2 + d^2)) + p, L0 = sqrt(w^2 + rise^2), damping
c d' + c2 d'|d'|; its deformation d is the difference of its end nodes' displacements. The
couplings are linear springs of a second design, F = s d with viscous damping. The truth is not
a polynomial: a reconstruction can only approximate it.

- Ladder (`ladder`): two rails of 8 nodes, each a serial chain of bistable elements from the
  ground, and a linear rung between the rails at every level (24 elements, 8 loops).
- Grid (`grid`): a 4 x 4 array of nodes, each held to the ground by a bistable element, with
  linear couplers between neighbours along rows and columns (40 elements).
- Grounded ladder (`grounded_ladder`): a 2 x 8 ladder whose every node is held to the ground by a
  bistable element, with linear couplers along the rails and linear rungs (38 elements, 7 loops).
  Its first well is the deeper one, so from all second wells a snap at one end can run along the
  rails as a transition wave (the serial ladder cannot carry one: at zero load its trusses in
  series are independently bistable).

The recorded configurations put every bistable element at each of its two wells: all in the
first well, all in the second, and two complementary patterns (alternating along the rails for
the ladder, the checkerboards for the grid, the two halves of the rails for the grounded ladder,
whose couplers are too stiff to hold an alternating pattern). Each equilibrium is solved by Newton
on the node force balance B^T F(B u) = 0 from the configuration's wells and checked stable (the
stiffness matrix B^T diag(F'(B u)) B positive definite) and to hold its pattern.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._basins._wells import newton_equilibrium
from .._model._model import AbstractMechanicalModel
from .._recordings._noise import add_noise
from .._recordings._recording import Recording
from .._simulate._inputs import AbstractInput
from .._simulate._integrate import Integrator
from .._simulate._simulate import simulate
from .._topology import Graph
from ._system import System

#: von Mises truss of the bistable elements (per unit mass): k, w, rise, preload p, damping c, c2
TRUSS = {"k": 100.0, "w": 2.0, "rise": 1.0, "p": 2.0, "c": 0.18, "c2": 0.05}


class Lattice(AbstractMechanicalModel):
    """Masses on a `Graph` whose elements are preloaded von Mises trusses or linear springs:

        F_e(d) = k_e d (1 - L0_e / sqrt(w_e^2 + d^2)) + p_e + s_e d,   F_d,e = c_e d' + c2_e d'|d'|,

    with L0_e = sqrt(w_e^2 + rise_e^2) (k_e = p_e = 0: a linear spring of stiffness s_e).

    **Attributes:** `masses` (nodes,); per element (E,): `k`, `w`, `rise`, `p`, `s`, `c`, `c2`;
    `topology` the `Graph`.
    """

    masses: Float[Array, " nodes"]
    k: Float[Array, " elements"]
    w: Float[Array, " elements"]
    rise: Float[Array, " elements"]
    p: Float[Array, " elements"]
    s: Float[Array, " elements"]
    c: Float[Array, " elements"]
    c2: Float[Array, " elements"]
    topology: Graph = eqx.field(static=True)

    def restoring(self, d):
        l0 = jnp.sqrt(self.w**2 + self.rise**2)
        return self.k * d * (1.0 - l0 / jnp.sqrt(self.w**2 + d**2)) + self.p + self.s * d

    def damping(self, d, dv):
        return self.c * dv + self.c2 * dv * jnp.abs(dv)


def _lattice(graph: Graph, bistable: np.ndarray, spring: float, spring_damping: float) -> Lattice:
    on = bistable.astype(float)

    def per(name, off=0.0):
        return jnp.asarray(np.where(bistable, TRUSS[name], off))

    return Lattice(masses=jnp.ones(graph.nodes), k=per("k"), w=per("w", 1.0), rise=per("rise"), p=per("p"),
                   s=jnp.asarray((1.0 - on) * spring), c=per("c", spring_damping), c2=per("c2"),
                   topology=graph)


def truss_wells() -> np.ndarray:
    """The two stable deformations of the bistable design (first < second)."""
    from ._nonpolynomial import ShallowArch, stable_roots

    t = TRUSS
    return stable_roots(ShallowArch(masses=jnp.ones(1), k=t["k"], w=t["w"], rise=t["rise"], p=t["p"]))


def stable_configuration(model: Lattice, u0) -> np.ndarray:
    """The equilibrium (node displacements) reached by Newton from u0; `ValueError` unless it is a
    stable equilibrium (force residual ~ 0, stiffness matrix positive definite)."""
    u, res, eig = (np.asarray(a) for a in newton_equilibrium(model, jnp.asarray(u0, float)))
    scale = float(np.max(np.abs(model.restoring(model.topology.deformations(jnp.asarray(u0, float))))) + 1.0)
    if not (np.all(np.isfinite(u)) and np.max(np.abs(res)) < 1e-9 * scale and np.min(eig) > 0):
        raise ValueError(f"no stable equilibrium near the configuration (residual {np.max(np.abs(res)):.2e}, "
                         f"smallest stiffness eigenvalue {np.min(eig):.3g})")
    return u


def _system(name, graph, bistable, patterns, node_of_pattern, spring, description) -> System:
    """A lattice `System` recorded around the configurations `patterns` (C, n_bistable) of 0/1 wells;
    `spring` the linear elements' stiffness (scalar or per element)."""
    model = _lattice(graph, bistable, spring, 0.05)
    wells = truss_wells()
    span = wells[-1] - wells[0]
    eq = np.stack([stable_configuration(model, node_of_pattern(wells[np.asarray(pt)])) for pt in patterns])
    dfm = np.asarray(graph.deformations(eq))  # (C, E)
    held = (dfm[:, bistable] > 0.5 * (wells[0] + wells[-1])) == np.asarray(patterns, bool)
    if not np.all(held):
        raise ValueError(f"{name}: the couplings do not hold the recorded patterns of wells "
                         f"({int(np.sum(~held))} elements leave theirs); use weaker couplings")
    lo = np.where(bistable, wells[0] - 0.25 * span, dfm.min(0) - 0.25 * span)
    hi = np.where(bistable, wells[-1] + 0.25 * span, dfm.max(0) + 0.25 * span)
    return System(
        name=name, truth=model, equilibria=eq, sweep=(0.05, 2.5), duration=120.0, fs=50.0,
        x_range=np.stack([lo, hi], axis=1), v_range=np.tile([[-1.0, 1.0]], (graph.n_elements, 1)),
        orders={"gmr": (5, 5), "gmc": (7, 7)}, description=description, units=("x", "x'", "F"),
        designs=np.where(bistable, 0, 1), drive="force")


def ladder(levels: int = 8, rung: float = 4.0) -> System:
    """A 2 x `levels` ladder (`Lattice`, per unit mass): rails of bistable trusses from the ground
    (nodes 0..levels-1 and levels..2 levels-1), a linear rung of stiffness `rung` at every level.
    Elements: rail A, rail B, then the rungs. Recorded around four configurations: all first
    wells, all second wells, and each rail alternating second-first-... and first-second-..."""
    n = levels
    rail = [(-1, 0)] + [(i - 1, i) for i in range(1, n)]
    elements = rail + [(a + n if a >= 0 else -1, b + n) for a, b in rail] + [(i, i + n) for i in range(n)]
    graph = Graph(2 * n, elements)
    bistable = np.arange(len(elements)) < 2 * n
    alt = np.arange(n) % 2
    patterns = [np.zeros(2 * n, int), np.ones(2 * n, int), np.tile(1 - alt, 2), np.tile(alt, 2)]

    def nodes(d):  # each rail's node displacements: its elements' deformations cumulated
        return np.concatenate([np.cumsum(d[:n]), np.cumsum(d[n:])])

    return _system(f"ladder2x{n}", graph, bistable, patterns, nodes, rung,
                   f"2 x {n} ladder of bistable von Mises trusses with linear rungs")


def grid(rows: int = 4, cols: int = 4, coupler: float = 0.2) -> System:
    """A `rows` x `cols` grid (`Lattice`, per unit mass): node r cols + c held to the ground by a
    bistable truss, linear couplers of stiffness `coupler` between row and column neighbours.
    Elements: the grounding trusses (node order), then the couplers. Recorded around four
    configurations: all first wells, all second wells, and the two checkerboards."""
    d = rows * cols
    couplers = ([(r * cols + c, r * cols + c + 1) for r in range(rows) for c in range(cols - 1)]
                + [(r * cols + c, (r + 1) * cols + c) for r in range(rows - 1) for c in range(cols)])
    graph = Graph(d, [(-1, i) for i in range(d)] + couplers)
    bistable = np.arange(graph.n_elements) < d
    board = (np.arange(d) // cols + np.arange(d) % cols) % 2
    patterns = [np.zeros(d, int), np.ones(d, int), board, 1 - board]
    return _system(f"grid{rows}x{cols}", graph, bistable, patterns, lambda w: w, coupler,
                   f"{rows} x {cols} grid of grounded bistable von Mises trusses with linear couplers")


def grounded_ladder(levels: int = 8, coupler: float = 1.8, rung: float = 1.8) -> System:
    """A 2 x `levels` ladder (`Lattice`, per unit mass) of nodes each held to the ground by a
    bistable truss (rail A: nodes 0..levels-1, rail B: levels..2 levels-1), linear couplers of
    stiffness `coupler` between neighbours along each rail and linear rungs of stiffness `rung`.
    Elements: the grounding trusses (node order), rail A's couplers, rail B's, then the rungs.
    Recorded around four configurations: all first wells, all second wells, and the rails' lower
    half in one well and upper half in the other, both ways."""
    n = levels
    couplers = [(i - 1, i) for i in range(1, n)] + [(n + i - 1, n + i) for i in range(1, n)]
    graph = Graph(2 * n, [(-1, i) for i in range(2 * n)] + couplers + [(i, i + n) for i in range(n)])
    bistable = np.arange(graph.n_elements) < 2 * n
    upper = np.tile((np.arange(n) >= n // 2).astype(int), 2)
    patterns = [np.zeros(2 * n, int), np.ones(2 * n, int), upper, 1 - upper]
    s = np.full(graph.n_elements, float(coupler))
    s[2 * n + len(couplers):] = rung
    return _system(f"grounded_ladder2x{n}", graph, bistable, patterns, lambda w: w, s,
                   f"2 x {n} ladder of grounded bistable von Mises trusses with linear couplers and rungs")


class MultiSine(AbstractInput):
    """A force on every node, sum_k amplitude[i, k] cos(2 pi f_k t + phase[i, k]); no base motion."""

    freqs: Float[Array, " tones"]
    amplitude: Float[Array, "dof tones"]
    phase: Float[Array, "dof tones"]
    n_dof: int = eqx.field(static=True, default=1)

    def __call__(self, t):
        return jnp.zeros(()), jnp.sum(self.amplitude * jnp.cos(2 * jnp.pi * self.freqs[None, :] * t + self.phase), axis=-1)


def linear_rms(model: Lattice, u, freqs, phase) -> np.ndarray:
    """RMS deformation (E,) of every element under the unit multisine `phase` (D, K), from the
    model linearised at the equilibrium u: delta_k = B (K - w^2 M + i w C)^-1 f_k."""
    g = model.topology
    B = jnp.asarray(g.incidence)
    d = g.deformations(u)
    stiff = B.T @ (jnp.diagonal(jax.jacfwd(model.restoring)(d))[:, None] * B)  # laws act element-wise
    damp = B.T @ (model.c[:, None] * B)
    w = 2 * np.pi * np.asarray(freqs)
    H = jnp.linalg.inv(stiff[None] - (w**2)[:, None, None] * jnp.diag(model.masses)[None]
                       + 1j * w[:, None, None] * damp[None])  # (K, D, D)
    resp = jnp.einsum("ed,kdj,jk->ek", B, H, jnp.exp(1j * jnp.asarray(phase)))
    return np.sqrt(0.5 * np.sum(np.abs(np.asarray(resp)) ** 2, axis=1))


@eqx.filter_jit
def _responses(model, inputs, ts, x0s):
    d = model.n_dof
    integ = Integrator(max_steps=500_000)
    sols = jax.vmap(lambda inp, x0: simulate(model, inp, ts, x0, integrator=integ, throw=False))(inputs, x0s)
    xs, vs = sols.value

    def one(inp, x, v):
        f = jax.vmap(lambda t: inp(t)[1])(ts)
        xdd = jax.vmap(lambda x_, v_, f_: model.accelerations(x_, v_, 0.0, f_))(x, v, f)
        return model.absolute_accelerations(xdd, jnp.zeros(ts.shape[0])), f

    a, f = jax.vmap(one)(inputs, xs, vs)
    return xs, vs, a, f, sols.result


def force_recordings(system: System, amplitude: float, *, snr_db=60.0, seed=0, duration=None) -> list[Recording]:
    """`make_recordings` of a force-driven lattice (see there)."""
    duration = duration or system.duration
    model = system.truth
    d = model.n_dof
    ts = jnp.arange(int(round(duration * system.fs)) + 1) / system.fs
    rng = np.random.default_rng(seed)
    base = 1.0 / duration  # tones on the record's frequency grid, about 100 of them over the band
    lo, hi = (int(np.ceil(system.sweep[0] / base)), int(np.floor(system.sweep[1] / base)))
    freqs = base * np.arange(lo, hi + 1, max(1, (hi - lo) // 100))
    x0s = np.asarray(system.equilibria, float).reshape(-1, d)
    phases = rng.uniform(0.0, 2 * np.pi, (x0s.shape[0], d, freqs.size))
    scale = [amplitude / (np.sqrt(2.0) * np.max(linear_rms(model, u, freqs, ph))) for u, ph in zip(x0s, phases)]
    amps = np.asarray(scale)[:, None, None] * np.ones_like(phases)
    inputs = MultiSine(jnp.asarray(np.broadcast_to(freqs, phases.shape[::2])), jnp.asarray(amps), jnp.asarray(phases),
                       n_dof=d)  # one input per configuration (vmapped)
    xs, vs, a, f, result = (np.asarray(z) for z in _responses(model, inputs, ts, jnp.asarray(x0s)))
    if not np.all(np.isfinite(xs)):
        raise RuntimeError(f"{system.name}: the truth simulation failed at amplitude {amplitude}")
    recs = []
    for i in range(x0s.shape[0]):
        sig = {"x": xs[i], "v": vs[i], "a": a[i], "force": f[i]}
        if snr_db is not None:
            sig = {k: add_noise(s, snr_db, rng) for k, s in sig.items()}
        recs.append(Recording(t=np.asarray(ts), masses=np.asarray(model.masses), name=f"{system.name}_C{i + 1}", **sig))
    return recs
