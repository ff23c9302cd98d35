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


def test_crossings_count_passages_halfway_from_the_saddle_to_the_other_well():
    # wells at -1 and +1, saddle 0: a crossing needs x past +-0.5; noise about the saddle is none
    from gmr_jax._simulate._free_run import crossings

    model = g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -1.0},
                                 {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1.0}])
    path = np.concatenate([np.full(50, -1.0), np.linspace(-1, 0.4, 20), 0.1 * np.sin(np.arange(40)),  # no
                           np.linspace(0, 1, 20), np.full(30, 1.0), np.linspace(1, -1, 30),  # two
                           np.linspace(-1, 1.1, 30)])[:, None]  # three
    assert crossings(model, path, None).tolist() == [3]
    assert crossings(model, path, path[::-1]).tolist() == [3]
    assert crossings(model, path, np.full_like(path, np.nan)).tolist() == [-1]
    one_well = g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": 1.0}])
    assert crossings(one_well, path, None).tolist() == [-1]


def test_short_runs_judge_a_model_on_a_cross_well_record_a_free_run_leaves(tmp_path, capsys):
    # a double well driven across its saddle, recorded with 60 dB noise. The truth's free run follows
    # the record (it did not before the input smoothing kept the drive: 4.5 % off over one period);
    # a model 1 % off in its cubic stiffness leaves it (sensitive dependence), while runs of one drive
    # period from the recorded state stay within a few percent
    def double_well(k3):
        return g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -2.0},
                                    {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": k3},
                                    {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.05}])

    ts = np.arange(0, 60, 0.01)
    drive = g.BaseSine(0.5, 0.25)
    x, v = (np.asarray(a) for a in g.simulate(double_well(1.5), drive, ts, np.array([-np.sqrt(2 / 1.5)])).value)
    rng = np.random.default_rng(0)
    noisy = lambda s: s + np.std(s) * 1e-3 * rng.standard_normal(s.shape)  # noqa: E731
    b = np.asarray([drive(t)[0] for t in ts])
    rec = g.Recording(t=ts, x=noisy(x), v=noisy(v), base_acc=b, name="cross")
    exact = g.free_run(double_well(1.5), rec).value
    assert exact.horizon == pytest.approx(4.0, rel=0.05)
    assert exact.nrmse[0] < 0.05 and exact.horizon_nrmse[0] < 0.01, (exact.nrmse, exact.horizon_nrmse)
    hops = int(exact.crossings[0, 0])
    # independent: sign changes of the noise-free truth (also counting an excursion past the saddle that
    # turns back before halfway, which the hysteresis does not)
    sign = np.sign(x[:, 0])
    assert hops > 10 and 0 <= int(np.sum(sign[1:] != sign[:-1])) - hops <= 2 and exact.crossings[1, 0] == hops
    off = g.free_run(double_well(1.515), rec).value
    assert off.nrmse[0] > 0.3 and off.horizon_nrmse[0] < 0.05, (off.nrmse, off.horizon_nrmse)
    g.save_recording(rec, tmp_path / "cross.npz")
    g.save_model(double_well(1.515), tmp_path / "m.json")
    assert main(["simulate", str(tmp_path / "m.json"), str(tmp_path / "cross.npz"), "--out", str(tmp_path / "o")]) == 0
    printed = capsys.readouterr().out
    doc = json.loads((tmp_path / "o" / "simulate.json").read_text())
    assert doc["horizon_nrmse"][0] == pytest.approx(off.horizon_nrmse[0]) and doc["crossings"]["measured"] == [hops]
    assert "crosses between wells" in printed and "runs of 4 s from the recorded state" in printed


def test_crossing_record_caveat_says_when_the_short_runs_fail_too():
    """On a record that crosses between wells, the free run's error is put down to chaos only where the one-period
    runs follow the record; where they fail too (a truss law fitted from one sine per well: 73.5 %) it says the
    model is wrong where the record goes."""
    from types import SimpleNamespace

    from gmr_jax._cli._simulate import SHORT_RUN_FAILS, _horizon_lines

    fr = lambda short: SimpleNamespace(horizon=10.0, horizon_nrmse=np.array([short]),  # noqa: E731
                                       crossings=np.array([[6], [2]]), nrmse=np.array([0.8]))
    chaos = "\n".join(_horizon_lines(fr(0.05)))
    assert "chaotic" in chaos and "does not follow" not in chaos
    wrong = "\n".join(_horizon_lines(fr(0.735)))
    assert "off by 73.5 % too" in wrong and "does not follow this record" in wrong and "even with an exact" not in wrong
    assert SHORT_RUN_FAILS < 0.735


def test_a_record_in_other_units_than_the_model_is_refused_at_once(case, capsys):
    """The joint's truth (rad) on its record in mrad: the model's accelerations at the recorded states are ~1e6 x and
    more the record's own; refused with the factor and the fix (audit: a chain model in m on a record in mm ran for
    over ten minutes without an answer), by the API and by `gmr simulate` (exit status 2, one line)."""
    import dataclasses

    d, s, rec = case
    milli = dataclasses.replace(rec, x=rec.x * 1e3, v=rec.v * 1e3, a=rec.a * 1e3, base_acc=rec.base_acc * 1e3)
    with pytest.raises(g.GMRInputError, match=r"accelerations at .* are .* times the record's own .* not in the units"):
        g.free_run(s.truth, milli)
    g.save_recording(milli, d / "milli.npz")
    capsys.readouterr()
    assert main(["simulate", str(d / "truth.json"), str(d / "milli.npz"), "--out", str(d / "milli")]) == 2
    err = capsys.readouterr().err
    assert "not in the units the model was fitted in" in err and "Traceback" not in err
