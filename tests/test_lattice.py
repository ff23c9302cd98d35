"""Built-in lattices of bistable elements on a graph: equilibria and recordings."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as gmr


@pytest.fixture(scope="module", params=["ladder", "grid", "grounded_ladder"])
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
    recs = gmr.systems.make_recordings(system, 0.03 * span, snr_db=50.0, seed=0)  # the whole record: nothing hops
    assert len(recs) == system.equilibria.shape[0]
    n = int(round(system.duration * system.fs)) + 1
    for rec, eq in zip(recs, system.equilibria):
        for key in ("x", "v", "a", "force"):
            assert getattr(rec, key).shape == (n, 16), key
        assert rec.base_acc is None and rec.masses.shape == (16,)
        np.testing.assert_allclose(rec.x.mean(axis=0), eq, atol=0.1 * span)  # small vibrations about it
        vib = np.asarray(system.truth.topology.deformations(rec.x)) - np.asarray(system.truth.topology.deformations(eq))
        amplitude = np.sqrt(2.0) * vib.std(axis=0).max()
        assert 0.01 * span < amplitude < 0.06 * span


def test_a_lattice_refuses_couplings_that_do_not_hold_its_recorded_patterns():
    with pytest.raises(ValueError, match="do not hold the recorded patterns"):
        gmr.systems.grounded_ladder(coupler=6.0, rung=6.0)


def _ladder_ends(model, system):
    wells = gmr.stable_wells(model, system.x_range)
    two = np.sum(np.isfinite(wells), axis=1) > 1
    return gmr.configuration(model, wells, np.where(two, 1, 0)), gmr.configuration(model, wells, np.zeros(len(wells), int))


@pytest.fixture(scope="module")
def grounded():
    system = gmr.systems.grounded_ladder()
    n = system.truth.topology.nodes // 2
    levels = np.full(system.truth.topology.n_elements, -1)
    levels[: 2 * n] = np.tile(np.arange(n), 2)
    return system, n, levels


def test_a_pull_on_the_grounded_ladder_runs_a_front_or_is_pinned(grounded):
    system, n, levels = grounded
    truth = system.truth
    start, target = _ladder_ends(truth, system)
    weak, strong = (gmr.transition_front(truth, start, target, gmr.HalfSineNodes(1.0, -a, (0, n), n_dof=2 * n), 40.0,
                                         levels) for a in (3.0, 10.0))
    assert weak.result == gmr.RESULTS.successful and strong.result == gmr.RESULTS.successful
    assert not bool(weak.propagated) and int(weak.reached) == -1 and np.isnan(float(weak.speed))
    assert np.allclose(np.asarray(weak.x)[-1], start, atol=0.05)  # back in the start configuration
    assert bool(strong.propagated) and int(strong.reached) == n - 1
    times = np.asarray(strong.times)
    assert np.all(np.isnan(times[2 * n:]))  # couplers and rungs are not watched
    rail = times[:n]
    assert np.all(np.diff(rail) > 0)  # level after level
    assert np.allclose(times[:n], times[n:2 * n], atol=0.05)  # the rails move together
    spacing = np.median(np.diff(rail[1:-1]))
    assert float(strong.speed) == pytest.approx(1.0 / spacing, rel=0.02)
    assert np.allclose(np.asarray(strong.x)[-1], target, atol=0.1)


def test_transition_front_refuses_bad_arguments(grounded):
    system, n, levels = grounded
    truth = system.truth
    start, target = _ladder_ends(truth, system)
    load = gmr.HalfSineNodes(1.0, -10.0, (0, n), n_dof=2 * n)
    with pytest.raises(gmr.GMRInputError, match="levels"):
        gmr.transition_front(truth, start, target, load, 10.0, levels[:5])
    with pytest.raises(gmr.GMRInputError, match="shape"):
        gmr.transition_front(truth, start[:3], target, load, 10.0, levels)
    with pytest.raises(gmr.GMRInputError, match="nothing to cross"):
        gmr.transition_front(truth, start, start, load, 10.0, levels)
    with pytest.raises(ValueError, match="mass indices"):
        gmr.HalfSineNodes(1.0, 1.0, (0, 2 * n), n_dof=2 * n)


@pytest.mark.slow
def test_a_model_from_small_vibrations_runs_the_truths_fronts(grounded):
    system, n, levels = grounded
    truth, graph = system.truth, system.truth.topology
    span = float(np.diff(gmr.stable_wells(truth, system.x_range)[0])[0])
    recs = gmr.systems.make_recordings(system, 0.02 * span, snr_db=50.0, seed=3)
    model = gmr.reconstruct(recs, topology=graph, designs=system.designs).value
    for a in (4.0, 10.0, 20.0):
        ft, fm = (gmr.transition_front(m, *_ladder_ends(m, system), gmr.HalfSineNodes(1.0, -a, (0, n), n_dof=2 * n),
                                       40.0, levels) for m in (truth, model))
        assert bool(ft.propagated) == bool(fm.propagated), a
        if bool(ft.propagated):
            assert float(fm.speed) == pytest.approx(float(ft.speed), rel=0.05)


def test_transition_front_on_a_chain_follows_each_cells_deformation():
    terms = [{"dof": i, "physics": p, "order": k, "coefficient": c} for i in range(3)
             for p, k, c in (("stiffness", 1, -1.0), ("stiffness", 3, 1.0), ("velocity_damping", 1, 0.3))]
    model = gmr.from_terms([1.0, 1.0, 1.0], terms, "chain")
    start, target = np.ones(3), -np.ones(3)  # a chain's coordinates are its cells' deformations
    fr = gmr.transition_front(model, start, target, gmr.HalfSineTip(0.5, -3.0, n_dof=3), 30.0, np.arange(3))
    x, ts, times = np.asarray(fr.x), np.asarray(fr.ts), np.asarray(fr.times)
    for i in range(3):  # the saddle of -x + x^3 between the wells is 0
        first = np.argmax(x[:, i] < 0.0) if np.any(x[:, i] < 0.0) else None
        if first is None:
            assert np.isnan(times[i])
        else:
            assert ts[first - 1] <= times[i] <= ts[first]
    assert np.any(np.isfinite(times))  # the pull at the tip switches a cell
    assert bool(fr.propagated) == bool(np.all(np.abs(x[-1] + 1.0) < 0.5))


def test_a_diverged_front_says_so():
    terms = [{"dof": 0, "physics": "stiffness", "order": 3, "coefficient": -1.0}]  # no wells: runs away
    model = gmr.from_terms([1.0], terms)
    fr = gmr.transition_front(model, np.ones(1), -np.ones(1), gmr.HalfSineTip(1.0, 1.0, n_dof=1), 20.0, [0])
    assert fr.result != gmr.RESULTS.successful and not bool(fr.propagated)
