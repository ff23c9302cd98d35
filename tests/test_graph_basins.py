"""Basin sweeps of lattices (`Graph`) and loads on any mass (`SweepSettings(load="node:K")`)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._basins._lanes import lanes_field


@pytest.mark.parametrize("topology", ["chain", "independent"])
def test_a_node_load_is_a_force_on_that_mass(topology):
    terms = [{"dof": i, "physics": p, "order": o, "coefficient": c}
             for i in range(3) for p, o, c in (("stiffness", 1, -20.0 - i), ("stiffness", 3, 3e4),
                                               ("velocity_damping", 1, 0.4))]
    m = g.from_terms([0.05, 0.04, 0.03], terms, topology)
    rng = np.random.default_rng(1)
    x, v = jnp.asarray(rng.normal(0, 0.03, (3, 8))), jnp.asarray(rng.normal(0, 0.5, (3, 8)))
    t, f, a = (jnp.asarray(rng.uniform(0.01, 0.1, 8)), jnp.asarray(rng.uniform(0.5, 3, 8)),
               jnp.asarray(rng.uniform(0.1, 2, 8)))
    pulse = a * jnp.sin(2 * jnp.pi * f * t)
    want = jax.vmap(lambda xi, vi, p: m.accelerations(xi, vi, 0.0, jnp.zeros(3).at[1].set(p)),
                    in_axes=(1, 1, 0), out_axes=1)(x, v, pulse)
    with jax.numpy_rank_promotion("allow"):
        got = lanes_field(m, "node:1", 3, per_lane=False)(t, (x, v), (m, f, a, 0.5 / f))
    np.testing.assert_allclose(np.asarray(got[1]), np.asarray(want), rtol=1e-10, atol=1e-9)
    wells = g.stable_wells(m, [[-0.05, 0.05]] * 3)
    tip = g.basin_map(m, [0.5, 2.0], [0.3, 1.5], wells, settings=g.SweepSettings(load="tip")).value
    last = g.basin_map(m, [0.5, 2.0], [0.3, 1.5], wells, settings=g.SweepSettings(load="node:2")).value
    np.testing.assert_array_equal(np.asarray(tip.config), np.asarray(last.config))


@pytest.fixture(scope="module")
def grid():
    s = g.systems.grid(2, 2)
    wells = g.stable_wells(s.truth, s.x_range)
    return s, wells


def test_configuration_is_a_stable_equilibrium_of_the_pattern(grid):
    s, wells = grid
    bistable = np.isfinite(wells[:, 1])
    assert bistable.sum() == 4 and wells.shape[0] == s.truth.n_elements
    pattern = np.where(bistable, [1, 0, 0, 1] + [0] * (wells.shape[0] - 4), 0)
    u = g.configuration(s.truth, wells, pattern)
    d = np.asarray(s.truth.topology.deformations(jnp.asarray(u)))
    np.testing.assert_allclose(d[:4], wells[np.arange(4), pattern[:4]], atol=0.1)  # couplers stressed
    force = s.truth.topology.node_forces(s.truth.restoring(jnp.asarray(d)))
    assert np.max(np.abs(np.asarray(force))) < 1e-8
    with pytest.raises(g.GMRInputError, match="pattern"):
        g.configuration(s.truth, wells, [0, 1])


def test_graph_sweep_classifies_by_the_elements(grid):
    """From every element in its second well, a pull on node 0 flips that node's element (or not);
    each point agrees with a plain simulation classified by the deformations."""
    s, wells = grid
    m = s.truth
    top = np.where(np.isfinite(wells[:, 1]), 1, 0)
    x0 = g.configuration(m, wells, top)
    f, A = np.array([0.05, 0.3]), np.array([-0.2, -40.0])
    st = g.SweepSettings(settle_time=150.0, load="node:0")
    bm = g.basin_map(m, f, A, wells, x0=x0, settings=st).value
    assert bm.wells.shape == (2, 2, m.n_elements) and bm.x_final.shape == (2, 2, m.n_dof)
    counts = np.asarray(bm.counts())
    assert counts.max() == 4 and counts.min() == 3  # the pull flips node 0 at some points only
    for i in range(2):
        for j in range(2):
            t1 = 0.5 / f[j] + 150.0

            sol = g.simulate(m, Pull(f[j], A[i], n_dof=m.n_dof), jnp.array([0.0, t1]), jnp.asarray(x0))
            d = np.asarray(m.topology.deformations(sol.value[0][-1]))
            want = [int(np.nanargmin(np.abs(d[e] - wells[e]))) for e in range(4)]
            assert list(np.asarray(bm.wells[i, j])[:4]) == want


class Pull(g.AbstractInput):
    """The Eq. (25) half-sine force on node 0."""

    f: float
    a: float
    n_dof: int = eqx.field(static=True, default=1)

    def __call__(self, t):
        p = jnp.where(t <= 0.5 / self.f, self.a * jnp.sin(2 * jnp.pi * self.f * t), 0.0)
        return jnp.zeros(()), jnp.zeros(self.n_dof).at[0].set(p)


def test_graph_sweep_refusals(grid):
    s, wells = grid
    with pytest.raises(g.GMRInputError, match="x0"):
        g.basin_map(s.truth, [1.0], [1.0], wells)
    x0 = g.configuration(s.truth, wells, np.zeros(wells.shape[0], int))
    with pytest.raises(g.GMRInputError, match="nodes 0..3"):
        g.basin_map(s.truth, [1.0], [1.0], wells, x0=x0, settings=g.SweepSettings(load="node:4"))
    with pytest.raises(g.GMRInputError, match="lanes"):
        g.basin_map(s.truth, [1.0], [1.0], wells, x0=x0, settings=g.SweepSettings(batching="joint"))
    with pytest.raises(g.GMRInputError, match="node:K"):
        g.SweepSettings(load="node:x")


def test_cli_basins_on_a_graph_model(tmp_path, capsys):
    """`gmr basins` on a graph model file: a push on node 0 from every element in its first
    well; basins.npz carries each element's well and the count of elements switched."""
    from gmr_jax._cli._main import main

    graph = g.Graph(2, [[-1, 0], [-1, 1], [0, 1]])
    terms = []
    for e in (0, 1):  # bistable grounding elements: F = 40 d (d + 0.5)(d - 0.5), damping 0.5 d'
        terms += [{"element": e, "physics": "stiffness", "order": 1, "coefficient": -10.0},
                  {"element": e, "physics": "stiffness", "order": 3, "coefficient": 40.0},
                  {"element": e, "physics": "velocity_damping", "order": 1, "coefficient": 0.5}]
    terms += [{"element": 2, "physics": "stiffness", "order": 1, "coefficient": 1.0},
              {"element": 2, "physics": "velocity_damping", "order": 1, "coefficient": 0.1}]
    model = g.from_terms([1.0, 1.0], terms, graph)
    path = tmp_path / "lattice.json"
    g.save_model(model, path)
    out = tmp_path / "b"
    code = main(["basins", str(path), "--f", "0.5:2:3", "--A", "1:40:3", "--load", "node:0",
                 "--x-range=-1:1", "--settle-time", "30", "--out", str(out)])
    assert code == 0, capsys.readouterr()
    res = np.load(out / "basins.npz")
    assert res["wells"].shape == (3, 3, 3) and res["counts"].shape == (3, 3)
    assert set(np.unique(res["counts"]).tolist()) <= {-1, 0, 1, 2} and res["counts"].max() >= 1
    assert (out / "basins.png").exists()
    assert main(["basins", str(path), "--f", "1:2:2", "--A", "1:2:2", "--load", "node:2", "--x-range=-1:1",
                 "--out", str(out)]) == 2
