"""How the DOFs of a model are connected: the equations of motion of the contracts.

- `Independent()`: each DOF its own mass on the (moving) ground,
  m_i a_i + F_i(x_i, v_i) = force_i, with a_i = x_i'' + base_acc.
- `Chain()`: a serial chain of cells numbered from the base; x_i is the deformation of cell i,
  the absolute acceleration of mass i is a_i = x_0'' + ... + x_i'' + base_acc, and cell i
  carries the inertia of every mass beyond it (paper Eq. 9, written base-first):
  (H a)_i + F_i(x_i, v_i) = sum_{k>=i} force_k, (H a)_i = sum_{k>=i} m_k a_k.
- `Graph(nodes, elements)`: masses at D nodes, E elements [a, b] between two nodes or a node and
  the ground (-1); the coordinates x are the node displacements relative to the base, element e
  deforms by delta_e = x_b - x_a (x_{-1} = 0), and m a = force - B^T F(delta, delta'), with B
  (E, D) the incidence matrix (B[e, b] = 1, B[e, a] = -1). `Chain()` is the graph
  [[-1, 0], [0, 1], ...] and `Independent()` the graph [[-1, 0], [-1, 1], ...].

A model's laws act on element deformations (`deformations`); for chains and independent DOFs the
coordinates are the element deformations themselves.

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

    def deformations(self, x):
        """Deformation of each element (..., E) from the coordinates x (..., D)."""
        return x

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


class Graph(AbstractTopology):
    """Masses at `nodes` nodes coupled by `elements` [a, b] (node indices, -1 = the ground or moving
    base): element e deforms by x_b - x_a, node balance m a = force - B^T F (module docstring).

    **Attributes:**

    - `nodes`: number of nodes D (the model's masses, one per node).
    - `elements`: E pairs (a, b) of node indices in -1..D-1, a != b.

    Examples:
        Two masses on the ground in series, and a spring from the ground to the second (a loop):

        >>> import gmr_jax as gmr
        >>> graph = gmr.Graph(2, [[-1, 0], [0, 1], [-1, 1]])
        >>> graph.n_elements, graph.incidence.tolist()
        (3, [[1.0, 0.0], [-1.0, 1.0], [0.0, 1.0]])
        >>> gmr.Graph.chain(3).elements
        ((-1, 0), (0, 1), (1, 2))
    """

    name: ClassVar[str] = "graph"
    nodes: int = eqx.field(static=True)
    elements: tuple[tuple[int, int], ...] = eqx.field(static=True, converter=lambda e: tuple(
        (int(a), int(b)) for a, b in np.asarray(e, dtype=np.int64).reshape(-1, 2)))

    def __check_init__(self):
        check_elements(self.elements, self.nodes, "Graph")

    @classmethod
    def chain(cls, n: int) -> "Graph":
        """The graph of a serial chain of n cells from the base: [[-1, 0], [0, 1], ...]."""
        return cls(n, [(i - 1, i) for i in range(n)])

    @classmethod
    def independent(cls, n: int) -> "Graph":
        """The graph of n independent DOFs, each on the ground: [[-1, 0], [-1, 1], ...]."""
        return cls(n, [(-1, i) for i in range(n)])

    @property
    def n_elements(self) -> int:
        return len(self.elements)

    @property
    def incidence(self) -> np.ndarray:
        """B (E, D): B[e, b] = 1, B[e, a] = -1 (ground ends dropped), so delta = B x."""
        b = np.zeros((self.n_elements, self.nodes))
        for e, (i, j) in enumerate(self.elements):
            if j >= 0:
                b[e, j] += 1.0
            if i >= 0:
                b[e, i] -= 1.0
        return b

    def deformations(self, x):
        xp = _xp(x)
        ends = np.asarray(self.elements, dtype=np.int64).reshape(-1, 2)
        ext = xp.concatenate([x, xp.zeros(x.shape[:-1] + (1,), x.dtype)], axis=-1)  # index -1: ground
        return ext[..., ends[:, 1]] - ext[..., ends[:, 0]]

    def node_forces(self, element_forces):
        """B^T f (..., D): the net force the elements exert against each node's motion."""
        return element_forces @ _xp(element_forces).asarray(self.incidence)

    def carried(self, per_mass):
        raise GMRInputError(
            "a graph's elements do not each carry a known share of the nodes' inertia (a node can sum "
            "several elements); fit a graph with gmr_jax.reconstruct(recordings, topology=graph, "
            "coordination='evidence'), which identifies the element laws jointly from every node's balance")

    def accelerations(self, restoring_damping, masses, base_acc, force):
        return (force - self.node_forces(restoring_damping)) / masses - base_acc

    def displacements(self, x):
        return x

    def tip(self, x):
        return x[..., -1]

    def to_dict(self) -> dict:
        """The model file's topology entry `{"kind": "graph", "elements": [[a, b], ...]}`."""
        return {"kind": "graph", "elements": [list(e) for e in self.elements]}

    def __eq__(self, other):
        if isinstance(other, str):
            return other == self.name
        return isinstance(other, Graph) and (self.nodes, self.elements) == (other.nodes, other.elements)

    def __hash__(self):
        return hash((self.name, self.nodes, self.elements))

    def __repr__(self):
        return f"Graph(nodes={self.nodes}, elements={[list(e) for e in self.elements]})"


_ELEMENTS_FIX = ("elements are [a, b] pairs of node indices 0..D-1, or -1 for the ground (moving base), "
                 "with a != b")


def check_elements(elements, nodes, source: str) -> None:
    """`GMRInputError` for an element list that is not a graph on `nodes` nodes: an index outside
    -1..D-1, an element from a node to itself, a node that no element touches."""
    if isinstance(nodes, bool) or not isinstance(nodes, (int, np.integer)) or nodes < 1:
        raise GMRInputError(f"{source}: 'nodes' must be a positive integer (the number of masses), got {nodes!r}")
    if len(elements) == 0:
        raise GMRInputError(f"{source}: the graph has no elements; {_ELEMENTS_FIX}")
    for e, (a, b) in enumerate(elements):
        for end in (a, b):
            if not -1 <= end < nodes:
                raise GMRInputError(f"{source}: element {e} [{a}, {b}] names node {end}, outside -1..{nodes - 1} "
                                    f"(the graph has {nodes} nodes); fix the index or the node count")
        if a == b:
            raise GMRInputError(f"{source}: element {e} [{a}, {b}] joins a node to itself; an element joins two "
                                f"different nodes, or a node and the ground (-1)")
    touched = {n for e in elements for n in e}
    free = sorted(set(range(nodes)) - touched)
    if free:
        raise GMRInputError(f"{source}: node(s) {free} belong to no element (disconnected): nothing holds their "
                            f"mass; add an element to each (e.g. [-1, {free[0]}] to the ground) or remove the node")


TOPOLOGIES = {"chain": Chain(), "independent": Independent()}


def as_topology(topology) -> AbstractTopology:
    """A topology object from itself or its name ("chain" | "independent")."""
    if isinstance(topology, AbstractTopology):
        return topology
    if isinstance(topology, str) and topology in TOPOLOGIES:
        return TOPOLOGIES[topology]
    raise GMRInputError(f"topology must be one of {tuple(TOPOLOGIES)} or a gmr_jax.Graph, got {topology!r}")


def as_graph(topology: AbstractTopology, n: int) -> Graph:
    """The graph of a topology with n DOFs (a chain or independent DOFs as elements)."""
    topology = as_topology(topology)
    if isinstance(topology, Graph):
        return topology
    return Graph.chain(n) if isinstance(topology, Chain) else Graph.independent(n)
