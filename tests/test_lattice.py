"""Built-in lattices of bistable elements on a graph: equilibria and recordings."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as gmr


@pytest.fixture(scope="module", params=["ladder", "grid"])
def system(request):
    return getattr(gmr.systems, request.param)()


def test_lattice_graphs_have_loops(system):
    graph = system.truth.topology
    assert isinstance(graph, gmr.Graph) and graph.nodes == 16
    assert graph.n_elements > graph.nodes  # more elements than nodes: loops
    assert system.designs.shape == (graph.n_elements,) and set(system.designs.tolist()) == {0, 1}


def test_lattice_equilibria_are_stable_equilibria(system):
    truth, graph = system.truth, system.truth.topology

    def residual(u):
        return graph.node_forces(truth.force(u, jnp.zeros_like(u)))

    for u in system.equilibria:
        u = jnp.asarray(u)
        scale = float(jnp.max(jnp.abs(truth.restoring(graph.deformations(u) * 0.5))))
        assert float(jnp.max(jnp.abs(residual(u)))) < 1e-9 * scale
        assert float(jnp.min(jnp.linalg.eigvalsh(jax.jacfwd(residual)(u)))) > 0.0


def test_every_bistable_element_visits_both_wells(system):
    deformation = np.asarray(system.truth.topology.deformations(jnp.asarray(system.equilibria)))
    bistable = system.designs == 0
    lo, hi = system.x_range[bistable].T
    span = (hi - lo) / 1.5  # x_range: the wells' span and 25 % beyond each
    first, second = lo + 0.25 * span, hi - 0.25 * span
    near = lambda w: np.abs(deformation[:, bistable] - w) < 0.1 * span  # noqa: E731
    assert np.all(near(first).any(axis=0)) and np.all(near(second).any(axis=0))
    assert system.equilibria.shape[0] <= 4


def test_lattice_recordings_follow_the_contract(system):
    span = np.ptp(system.x_range[0]) / 1.5
    recs = gmr.systems.make_recordings(system, 0.02 * span, snr_db=50.0, seed=0, duration=20.0)
    assert len(recs) == system.equilibria.shape[0]
    n = int(round(20.0 * system.fs)) + 1
    for rec, eq in zip(recs, system.equilibria):
        for key in ("x", "v", "a", "force"):
            assert getattr(rec, key).shape == (n, 16), key
        assert rec.base_acc is None and rec.masses.shape == (16,)
        np.testing.assert_allclose(rec.x.mean(axis=0), eq, atol=0.1 * span)  # small vibrations about it
        vib = np.asarray(system.truth.topology.deformations(rec.x)) - np.asarray(system.truth.topology.deformations(eq))
        amplitude = np.sqrt(2.0) * vib.std(axis=0).max()
        assert 0.005 * span < amplitude < 0.06 * span
