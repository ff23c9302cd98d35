"""Reconstruction on a graph: every element's law from every node's balance (70 dB: the ladder's
law is within 2 % there; at 50-60 dB it is not yet, results/lattice.md)."""

import json
import warnings

import numpy as np
import pytest

import gmr_jax as gmr
from gmr_jax._cli._main import main


@pytest.fixture(scope="module")
def small_ladder():
    system = gmr.systems.ladder(levels=2)  # 4 nodes, 4 bistable rails, 2 rungs: a loop
    wells = [x for x, s in gmr.metrics.equilibria(system.truth, 0, tuple(system.x_range[0])) if s]
    recs = gmr.systems.make_recordings(system, 0.02 * (wells[-1] - wells[0]), snr_db=70.0, seed=0, duration=60.0)
    return system, wells, recs


@pytest.fixture(scope="module")
def small_fit(small_ladder):
    system, _, recs = small_ladder
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gmr.GMRDataWarning)
        return gmr.reconstruct(recs, topology=system.truth.topology, coordination="evidence", designs=system.designs)


def test_graph_fit_recovers_every_element_law(small_ladder, small_fit):
    system, wells, _ = small_ladder
    model = small_fit.value
    assert model.topology == system.truth.topology and model.n_elements == 6
    for e in range(6):
        if system.designs[e] == 0:  # bistable: over the interwell span, wells and saddle
            assert gmr.metrics.restoring_error(model, system.truth, e, (wells[0], wells[-1])) < 0.02
            truth = gmr.metrics.equilibria(system.truth, e, tuple(system.x_range[e]))
            found = gmr.metrics.equilibria(model, e, tuple(system.x_range[e]))
            assert [s for _, s in found] == [s for _, s in truth]
            assert max(abs(a - b) for (a, _), (b, _) in zip(found, truth)) < 0.02 * (wells[-1] - wells[0])
        else:  # a linear rung, over its range
            assert gmr.metrics.restoring_error(model, system.truth, e, tuple(system.x_range[e])) < 0.02


def test_graph_fit_elements_of_one_design_share_one_law(small_ladder, small_fit):
    system, _, _ = small_ladder
    k = np.asarray(small_fit.value.stiffness)
    for label in (0, 1):
        same = k[system.designs == label]
        assert np.all(same == same[0])
    assert not np.allclose(k[0], k[-1])


def test_graph_fit_refuses_wrong_designs_and_routes(small_ladder):
    system, _, recs = small_ladder
    with pytest.raises(gmr.GMRInputError, match="one integer label per element"):
        gmr.reconstruct(recs, topology=system.truth.topology, coordination="evidence", designs=[0, 1])
    with pytest.raises(gmr.GMRInputError, match="evidence"):
        gmr.reconstruct(recs, topology=system.truth.topology, coordination="gls")


def test_fit_cli_with_a_graph_file(small_ladder, small_fit, tmp_path, capsys):
    system, _, recs = small_ladder
    paths = []
    for r in recs:
        paths.append(str(tmp_path / f"{r.name}.npz"))
        gmr.save_recording(r, paths[-1])
    graph_file = tmp_path / "ladder.json"
    gmr.save_graph(graph_file, system.truth.topology, np.asarray(system.truth.masses))
    out = tmp_path / "model.json"
    designs = ",".join(str(int(v)) for v in system.designs)
    assert main(["fit", *paths, "--topology", str(graph_file), "--designs", designs, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "graph of 4 nodes and 6 elements" in printed and "element 5" in printed
    d = json.loads(out.read_text())
    assert d["topology"] == {"kind": "graph", "elements": [list(e) for e in system.truth.topology.elements]}
    assert all("element" in t and "dof" not in t for t in d["terms"]) and d["masses"] == [1.0] * 4
    model = gmr.load_model(out)
    np.testing.assert_allclose(np.asarray(model.stiffness), np.asarray(small_fit.value.stiffness), rtol=1e-6,
                               atol=1e-9)
    assert main(["show", str(out)]) == 0
    shown = capsys.readouterr().out
    assert "graph of 4 nodes and 6 elements" in shown and "element 5:" in shown
    assert main(["fit", *paths, "--topology", str(graph_file), "--designs", "0,x", "--out", str(out)]) == 2
    assert "--designs must be comma-separated integers" in capsys.readouterr().err
