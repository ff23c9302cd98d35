"""Graph topology: chains and independent DOFs as graphs, graph and model files."""

import json

import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as gmr

TIGHT = gmr.Integrator(rtol=1e-11, atol=1e-13)


def _trajectory(model, inputs, ts, x0):
    x, v = gmr.simulate(model, inputs, ts, x0, integrator=TIGHT).value
    return np.asarray(model.topology.displacements(x))


def test_a_chain_simulated_as_a_graph_follows_the_same_trajectory():
    system = gmr.systems.kresling3()
    truth, x0 = system.truth, jnp.asarray(system.equilibria[0])
    graph = gmr.to_graph(truth)
    assert graph.topology == gmr.Graph(3, [[-1, 0], [0, 1], [1, 2]])
    ts = jnp.linspace(0.0, 0.3, 61)
    load = gmr.HalfSineTip(8.0, 3.0, n_dof=3)
    chain_nodes = _trajectory(truth, load, ts, x0)
    graph_nodes = _trajectory(graph, load, ts, truth.topology.displacements(x0))
    span = np.ptp(chain_nodes)
    assert span > 1e-3  # the load moves the chain
    assert np.max(np.abs(graph_nodes - chain_nodes)) < 1e-8 * span


def test_independent_dofs_simulated_as_a_graph_follow_the_same_trajectory():
    system = gmr.systems.bistable_joint()
    truth = gmr.from_terms([1.0, 2.0], [dict(t, dof=i) for i in (0, 1) for t in system.truth.terms()])
    graph = gmr.to_graph(truth)
    assert graph.topology == gmr.Graph(2, [[-1, 0], [-1, 1]])
    ts = jnp.linspace(0.0, 2.0, 101)
    base = gmr.BaseSine(0.05, 6.0, n_dof=2)
    x0 = jnp.asarray([system.equilibria[0, 0], system.equilibria[1, 0]])
    a, b = _trajectory(truth, base, ts, x0), _trajectory(graph, base, ts, x0)
    assert np.max(np.abs(a - b)) < 1e-8 * np.ptp(a)


def test_a_chain_model_as_a_graph_gives_the_same_forces():
    terms = [{"dof": i, "physics": p, "order": k, "coefficient": c * (1 + 0.3 * i)}
             for i in range(4) for p, k, c in [("stiffness", 1, -2.0), ("stiffness", 3, 5.0),
                                                 ("velocity_damping", 1, 0.1), ("position_damping", 2, 0.4)]]
    chain = gmr.from_terms([0.1, 0.2, 0.3, 0.4], terms, "chain")
    graph = gmr.to_graph(chain)
    rng = np.random.default_rng(0)
    x, v, f = (jnp.asarray(rng.normal(size=4)) for _ in range(3))
    u, w = chain.topology.displacements(x), chain.topology.displacements(v)
    np.testing.assert_allclose(graph.force(u, w), chain.force(x, v), rtol=1e-14)
    # node accelerations: the chain's relative accelerations cumulated
    np.testing.assert_allclose(graph.accelerations(u, w, 0.7, f),
                               chain.topology.displacements(chain.accelerations(x, v, 0.7, f)), rtol=1e-12)
    assert graph.equations() == chain.equations()


def test_graph_with_a_loop_balances_each_node():
    # two nodes on the ground joined by a third element: node 0 feels elements 0 and 2
    graph = gmr.Graph(2, [[-1, 0], [-1, 1], [0, 1]])
    terms = [{"element": e, "physics": "stiffness", "order": 1, "coefficient": k} for e, k in enumerate([1.0, 2.0, 3.0])]
    model = gmr.from_terms([1.0, 2.0], terms, graph)
    u = jnp.asarray([0.5, -0.25])
    acc = model.accelerations(u, jnp.zeros(2), 0.0, jnp.asarray([0.0, 1.0]))
    stiffness = np.array([[1.0 + 3.0, -3.0], [-3.0, 2.0 + 3.0]])
    np.testing.assert_allclose(acc, (np.array([0.0, 1.0]) - stiffness @ np.asarray(u)) / np.array([1.0, 2.0]))


def test_graph_model_file_round_trip(tmp_path):
    graph = gmr.Graph(3, [[-1, 0], [0, 1], [1, 2], [-1, 2]])
    terms = [{"element": e, "physics": "stiffness", "order": k, "coefficient": float(e + k)}
             for e in range(4) for k in (1, 3)]
    model = gmr.from_terms([1.0, 1.5, 2.0], terms, graph)
    path = tmp_path / "m.json"
    gmr.save_model(model, path)
    d = json.loads(path.read_text())
    assert d["topology"] == {"kind": "graph", "elements": [[-1, 0], [0, 1], [1, 2], [-1, 2]]}
    assert d["masses"] == [1.0, 1.5, 2.0] and all("element" in t and "dof" not in t for t in d["terms"])
    back = gmr.load_model(path)
    assert back.topology == graph and back.terms() == model.terms()
    # chain files keep the "dof" key and the string topology
    chain = gmr.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": 1.0}], "chain")
    gmr.save_model(chain, path)
    assert json.loads(path.read_text())["topology"] == "chain"


@pytest.mark.parametrize("change,msg", [
    ({"elements": [[-1, 0], [0, 3]]}, "outside -1..2"),
    ({"elements": [[-1, 0], [1, 1], [1, 2]]}, "joins a node to itself"),
    ({"masses": [1.0, 1.0]}, "2 masses for 3 nodes"),
    ({"elements": [[-1, 0], [0, 1]]}, "node(s) [2] belong to no element"),
    ({"elements": [[-1, 0], [0, 1.5], [1, 2]]}, "not an [a, b] pair of integers"),
    ({"nodes": 0}, "positive integer"),
    ({"extra": 1}, "exactly the keys"),
])
def test_bad_graph_files_name_the_problem(tmp_path, change, msg):
    d = {"nodes": 3, "masses": [1.0, 1.0, 1.0], "elements": [[-1, 0], [0, 1], [1, 2]]} | change
    path = tmp_path / "g.json"
    path.write_text(json.dumps(d))
    with pytest.raises(gmr.GMRInputError, match=msg.replace("[", r"\[").replace("(", r"\(").replace(")", r"\)")):
        gmr.load_graph(path)


def test_graph_file_round_trip(tmp_path):
    graph = gmr.Graph(3, [[-1, 0], [0, 1], [1, 2], [0, 2]])
    gmr.save_graph(tmp_path / "g.json", graph, [1.0, 2.0, 3.0])
    back, masses = gmr.load_graph(tmp_path / "g.json")
    assert back == graph and masses.tolist() == [1.0, 2.0, 3.0]
    with pytest.raises(gmr.GMRInputError, match="no such graph file"):
        gmr.load_graph(tmp_path / "missing.json")


def test_graph_terms_are_checked_in_element_words():
    graph = gmr.Graph(2, [[-1, 0], [0, 1]])
    with pytest.raises(gmr.GMRInputError, match="name their law with 'element'"):
        gmr.from_terms([1.0, 1.0], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": 1.0}], graph)
    with pytest.raises(gmr.GMRInputError, match=r"element\(s\) \[1\] have no term"):
        gmr.from_terms([1.0, 1.0], [{"element": 0, "physics": "stiffness", "order": 1, "coefficient": 1.0}], graph)
    with pytest.raises(gmr.GMRInputError, match="one mass per node"):
        gmr.from_terms([1.0], [{"element": 0, "physics": "stiffness", "order": 1, "coefficient": 1.0}], graph)
