"""`gmr simulate` and `free_run`: a model's free run under a recording's input."""

import json

import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._cli._main import main


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    d = tmp_path_factory.mktemp("sim")
    s = g.systems.bistable_joint("position_independent")
    rec = g.systems.make_recordings(s, np.deg2rad(1.0), seed=2, duration=1.5)[1]
    g.save_recording(rec, d / "rec.npz")
    g.save_model(s.truth, d / "truth.json")
    return d, s, rec


def test_free_run_of_the_truth_matches(case):
    d, s, rec = case
    fr = g.free_run(s.truth, rec).value
    assert fr.x.shape == fr.x_measured.shape == (rec.n_samples - fr.start, 1)
    assert fr.nrmse[0] < 0.05  # 60 dB noise on x, v and the input; model = truth


def test_simulate_cli_writes_figure_and_nrmse(case, capsys):
    d, _, _ = case
    out = d / "out"
    assert main(["simulate", str(d / "truth.json"), str(d / "rec.npz"), "--out", str(out), "--x-unit", "rad"]) == 0
    printed = capsys.readouterr().out
    assert "DOF 0: NRMSE" in printed
    doc = json.loads((out / "simulate.json").read_text())
    assert doc["result"] == "successful" and len(doc["nrmse"]) == 1 and doc["nrmse"][0] < 0.05
    for name in ("simulate.png", "simulate.pdf", "simulate.md"):
        assert (out / name).stat().st_size > 1000 or name == "simulate.md"
    assert f"{100 * doc['nrmse'][0]:.4g} %" in printed


def test_simulate_diverged_is_exit_1_not_a_number(case, capsys):
    d, _, _ = case
    bad = {"format": "gmr-model/1", "masses": [1.0], "terms": [
        {"dof": 0, "physics": "stiffness", "order": 1, "coefficient": 2244.0},
        {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": -1755.0}]}
    (d / "bad.json").write_text(json.dumps(bad))
    capsys.readouterr()
    rc = main(["simulate", str(d / "bad.json"), str(d / "rec.npz"), "--out", str(d / "bad")])
    err = capsys.readouterr()
    assert rc == 1 and "diverged" in err.err and "NRMSE" not in err.out
    doc = json.loads((d / "bad" / "simulate.json").read_text())
    assert doc["result"] == "diverged" and "nrmse" not in doc
    with pytest.raises(g.GMRComputationError, match="diverged"):
        g.free_run(g.load_model(d / "bad.json"), d / "rec.npz")
