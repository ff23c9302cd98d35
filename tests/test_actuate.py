"""Actuation design (`gmr.actuate`): the terminal surrogate's gradient, an optimized actuation
that verification confirms, result codes and input errors."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax import RESULTS, ActuateSettings, actuate
from gmr_jax._actuate._actuate import terminal_margin_half_sine
from gmr_jax._actuate._surrogate import parse_target
from gmr_jax._basins._sweep import classify


def _chain():
    """Two double-well cells (wells at -1 and +1), viscous damping plus quadratic drag
    sgn(v) v^2 (a sgn(v) term: the differentiated solves use its tanh surrogate; Coulomb
    friction itself would stall the exact-model solver at rest)."""
    terms = []
    for i, k in enumerate((2.0, 1.0)):
        terms += [
            {"dof": i, "physics": "stiffness", "order": 1, "coefficient": -k},
            {"dof": i, "physics": "stiffness", "order": 3, "coefficient": k},
            {"dof": i, "physics": "position_damping", "order": 0, "coefficient": 0.3},
            {"dof": i, "physics": "velocity_damping", "order": 2, "coefficient": 0.1},
        ]
    return g.from_terms([1.0, 1.0], terms, topology="chain")


MODEL = _chain()
WELLS = np.array([[-1.0, 1.0], [-1.0, 1.0]])
SETTINGS = ActuateSettings(f_range=(0.05, 1.0), A_range=(0.1, 3.0), n_f=6, n_A=6, n_seeds=2, max_walk=6,
                           sweep=g.SweepSettings(settle_time=30.0), sign_eps=1e-2)


def test_wells_and_smoothing():
    from gmr_jax._actuate._surrogate import needs_smoothing, saddles, smooth_model

    np.testing.assert_allclose(g.stable_wells(MODEL, [[-2, 2]] * 2), WELLS, atol=1e-6)
    np.testing.assert_allclose(saddles(MODEL, WELLS), [0.0, 0.0], atol=1e-9)
    assert needs_smoothing(MODEL) and smooth_model(MODEL, 1e-2).sign_eps == 1e-2


def test_margin_gradient_matches_finite_differences():
    # short settle and tight tolerances: the state is still moving, so the margin is O(1) smooth
    st = ActuateSettings(sweep=g.SweepSettings(settle_time=2.0, integrator=g.Integrator(rtol=1e-10, atol=1e-12, max_steps=100_000)), sign_eps=1e-2)
    f, A, h = 0.4, 1.5, 1e-5
    m, (gf, ga) = terminal_margin_half_sine(MODEL, WELLS, "1-1", f, A, settings=st)

    def val(ff, aa):
        return terminal_margin_half_sine(MODEL, WELLS, "1-1", ff, aa, settings=st)[0]

    fd_f = (val(f + h, A) - val(f - h, A)) / (2 * h)
    fd_a = (val(f, A + h) - val(f, A - h)) / (2 * h)
    assert np.isfinite(m) and abs(gf) > 1e-2 and abs(ga) > 1e-2
    np.testing.assert_allclose([gf, ga], [fd_f, fd_a], rtol=1e-4)


@pytest.mark.slow
def test_actuate_reaches_target_and_beats_grid():
    sol = actuate(MODEL, "1-1", settings=SETTINGS, wells=WELLS)
    act, st = sol.value, sol.stats
    assert sol.result == RESULTS.successful
    assert act.kind == "half_sine" and act.peak == act.A
    assert st["verified_config"] == 3 and st["verified_wells"] == [1, 1] and st["basin_map_config"] == 3
    assert st["verified_result"] == "successful"
    assert st["solves"] == st["forward_solves"] + 2 * st["gradient_evaluations"] + st["verify_solves"]
    assert st["gradient_evaluations"] > 0
    # independent check: plain simulation of the exact model, classified as basin_map does
    sim = g.simulate(MODEL, g.HalfSineTip(act.f, act.A, n_dof=2), jnp.array([0.0, 0.5 / act.f + 30.0]),
                     jnp.asarray(WELLS[:, 0]))
    w = jnp.asarray(WELLS)
    idx, config, _ = classify(sim.value[0][-1], sim.value[1][-1], sim.result._value, w, w[:, 1] - w[:, 0],
                              SETTINGS.sweep)
    assert int(config) == 3 and idx.tolist() == [1, 1]
    # no point of a finer grid over the same box reaches the target with a lower peak (2 % slack)
    f = np.linspace(0.05, 1.0, 16)
    A = np.linspace(0.1, 3.0, 16)
    conf = np.asarray(g.basin_map(MODEL, f, A, WELLS, settings=SETTINGS.sweep).value.config)
    a_grid = A[np.nonzero((conf == 3).any(axis=1))[0][0]]
    assert act.A <= 1.02 * a_grid
    assert st["solves"] < f.size * A.size * 2


def test_target_not_found_is_a_result_code():
    st = ActuateSettings(f_range=(0.5, 1.0), A_range=(0.01, 0.05), n_f=2, n_A=2, n_seeds=2,
                         sweep=SETTINGS.sweep)
    sol = actuate(MODEL, "0-1", settings=st, wells=WELLS, throw=False)
    assert sol.result == RESULTS.target_not_found
    assert sol.stats["solves"] == 4
    with pytest.raises(RuntimeError, match="No actuation in the search range"):
        actuate(MODEL, "0-1", settings=st, wells=WELLS)


@pytest.mark.parametrize(
    "target, match",
    [("0-1-1", "has 3 cells but the model has 2"), ("0-2", "one 0 or 1 per cell"), ("ab", "one 0 or 1 per cell"),
     ("0-0", "start configuration: nothing to do"), ("", "one 0 or 1 per cell")],
)
def test_bad_targets(target, match):
    with pytest.raises(g.GMRInputError, match=match):
        actuate(MODEL, target, settings=SETTINGS, wells=WELLS)


def test_parse_target_forms():
    assert parse_target("0-1-1-0-0", 5).tolist() == [0, 1, 1, 0, 0]
    assert parse_target("01100", 5).tolist() == [0, 1, 1, 0, 0]
    assert parse_target(6, 5).tolist() == [0, 1, 1, 0, 0]
    with pytest.raises(g.GMRInputError):
        parse_target(40, 5)


@pytest.mark.slow
def test_cli_actuate(tmp_path):
    from gmr_jax._cli._main import main

    path = tmp_path / "model.json"
    g.save_model(MODEL, path)
    out = tmp_path / "act"
    rc = main(["actuate", str(path), "--target", "1-1", "--out", str(out), "--f-range", "0.05:1", "--A-range",
               "0.1:3", "--settle-time", "30", "--grid", "6", "--seeds", "2", "--sign-eps", "0.01"])
    assert rc == 0
    res = json.loads((out / "actuation.json").read_text())
    assert res["kind"] == "half_sine" and res["A"] > 0 and res["f"] > 0
    assert res["reached"] is True and res["final_wells"] == [1, 1] and res["final_config"] == "1-1"
    assert res["result"] == "successful" and res["message"] == ""  # the name (it was "" on success)
    assert main(["actuate", str(path), "--target", "0-1-1", "--out", str(out), "--x-range=-2:2"]) == 2


@pytest.mark.slow
def test_samples_history_lowers_the_peak_and_is_verified():
    import dataclasses

    st = dataclasses.replace(SETTINGS, max_iter_samples=4, n_knots=16)
    sol = actuate(MODEL, "1-1", kind="samples", settings=st, wells=WELLS)
    act = sol.value
    assert act.kind == "samples" and act.t.shape == (16,) and act.force.shape == (16,)
    assert sol.stats["verified_config"] == 3
    assert act.peak == pytest.approx(np.max(np.abs(act.force)))
    assert act.peak < sol.stats["half_sine"]["peak"]  # never worse than the half-sine it starts from
    sim = g.simulate(MODEL, act.inputs(2), jnp.array([0.0, act.t[-1] + 30.0]), jnp.asarray(WELLS[:, 0]))
    np.testing.assert_allclose(np.asarray(sim.value[0][-1]), [1.0, 1.0], atol=0.1)


@pytest.mark.slow
def test_cli_actuate_takes_a_one_dof_independent_model(tmp_path):
    """`gmr fit` on single-DOF records writes an 'independent' model; its one mass is the tip."""
    from gmr_jax._cli._main import main

    one = g.from_terms([1.0], [
        {"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -2.0},
        {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 2.0},
        {"dof": 0, "physics": "position_damping", "order": 0, "coefficient": 0.3},
        {"dof": 0, "physics": "velocity_damping", "order": 2, "coefficient": 0.1},
    ], topology="independent")
    path = tmp_path / "one.json"
    g.save_model(one, path)
    out = tmp_path / "act"
    rc = main(["actuate", str(path), "--target", "1", "--out", str(out), "--f-range", "0.05:1",
               "--A-range", "0.1:3", "--settle-time", "30", "--grid", "6", "--seeds", "2", "--sign-eps", "0.01"])
    assert rc == 0
    res = json.loads((out / "actuation.json").read_text())
    assert res["reached"] is True and res["final_config"] == "1"


def test_a_cell_with_three_wells_is_refused():
    """The target is one bit per cell: a tri-stable cell's third well would be read as one of the first two
    (audit: accepted silently); it is refused, naming the cell and the fix."""
    tri = g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": k, "coefficient": c}
                               for k, c in ((1, 4.0), (3, -5.0), (5, 1.0))], topology="chain")
    with pytest.raises(g.GMRInputError, match=r"cell\(s\) \[0\] have more than two stable wells"):
        actuate(tri, "1", settings=SETTINGS, wells=np.array([[-2.0, 0.0, 2.0]]))


@pytest.mark.slow
def test_cli_actuate_tries_the_design_on_models_drawn_from_the_covariance(tmp_path):
    """The lowest-peak design sits on the model's basin boundary: `gmr actuate` sweeps it, and larger amplitudes,
    over models drawn from the file's covariance and says the share that deploys and the amplitude at which 95 %
    do (a narrow covariance: a few percent more); a file without a covariance is told the design has no margin."""
    from gmr_jax._cli._main import main

    terms = [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -2.0},
             {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 2.0},
             {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.3}]
    cov = [{"dof": 0, "terms": [["stiffness", 1], ["stiffness", 3], ["velocity_damping", 1]],
            "matrix": np.diag([0.01**2, 0.01**2, 0.003**2]).tolist()}]
    args = ["--target", "1", "--f-range", "0.05:1", "--A-range", "0.1:3", "--settle-time", "30", "--grid", "6",
            "--seeds", "2", "--draws", "16"]
    for name, kw in (("cov", {"covariance": cov}), ("plain", {})):
        g.save_model(g.from_terms([1.0], terms, topology="chain", **kw), tmp_path / f"{name}.json")
        assert main(["actuate", str(tmp_path / f"{name}.json"), "--out", str(tmp_path / name), *args]) == 0
    rob = json.loads((tmp_path / "cov" / "actuation.json").read_text())["robustness"]
    assert rob["draws"] == 16 and 0.0 <= rob["share_at_design"] <= 1.0
    a = json.loads((tmp_path / "cov" / "actuation.json").read_text())["A"]
    assert rob["robust_A"] is not None and a <= rob["robust_A"] <= 1.2 * a, rob
    assert rob["ladder"][0][:2] == [1.0, a] and rob["ladder"][0][2] == rob["share_at_design"]
    assert "models drawn from the file's covariance" in rob["sentence"]
    # the draws still moving at t1 are told apart from those that end in another configuration
    assert rob["share_at_design"] + rob["unsettled_at_design"] + rob["elsewhere_at_design"] == pytest.approx(1.0)
    # without --settle-time: the model's own (7 / sigma = 47 s), said, and used by the robustness check too
    assert main(["actuate", str(tmp_path / "cov.json"), "--out", str(tmp_path / "auto"),
                 *[a for a in args if a not in ("--settle-time", "30")]]) == 0
    auto = json.loads((tmp_path / "auto" / "actuation.json").read_text())["robustness"]
    assert auto["settle_time"] == 47.0 and auto["unsettled_at_design"] == 0.0
    plain = json.loads((tmp_path / "plain" / "actuation.json").read_text())["robustness"]
    assert plain["draws"] == 0 and "no covariance" in plain["sentence"]
    # --require-robust: exit status 3 where the design is reached but not robust, or its robustness cannot be said
    robust = json.loads((tmp_path / "cov" / "actuation.json").read_text())["robust"]
    assert robust is (rob["share_at_design"] >= 0.95)
    rc = main(["actuate", str(tmp_path / "cov.json"), "--out", str(tmp_path / "cov_r"), *args, "--require-robust"])
    assert rc == (0 if robust else 3)
    assert main(["actuate", str(tmp_path / "plain.json"), "--out", str(tmp_path / "plain_r"), *args,
                 "--require-robust"]) == 3
    assert (tmp_path / "plain_r" / "actuation.json").exists()  # written either way


def test_settle_time_comes_from_the_model_and_unsettled_draws_are_told_apart():
    """The settle time every classifying command uses by default is the model's own: 7 / sigma, sigma the slowest
    linearised decay rate about its wells (here c / 2m), rounded up, at least 10 s; an undamped model has none.
    Drawn models still moving at t1 are counted apart (`BasinProbability.unsettled`), not as 'ended elsewhere'."""
    from gmr_jax._basins._settle import model_settle_time

    terms = [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -2.0},
             {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 2.0},
             {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.3}]
    cov = [{"dof": 0, "terms": [["stiffness", 1], ["stiffness", 3], ["velocity_damping", 1]],
            "matrix": np.diag([0.01**2, 0.01**2, 0.003**2]).tolist()}]
    m = g.from_terms([1.0], terms, topology="chain", covariance=cov)
    wells = g.stable_wells(m, (-2, 2))
    assert model_settle_time(m, wells) == 47.0  # 7 / (0.3 / 2) = 46.7 s, rounded up to two digits
    assert model_settle_time(g.from_terms([1.0], terms[:2], topology="chain"), wells) is None
    f, A = np.array([0.2]), np.array([0.5, 1.0, 2.0])
    short = g.basin_probability(m, f, A, jax.random.key(0), 8, x_range=(-2, 2),
                                settings=g.SweepSettings(settle_time=2.0)).value
    lost = np.asarray(short.probability)[..., list(np.asarray(short.configs)).index(-1)]
    unsettled = np.asarray(short.unsettled)
    assert np.all(unsettled > 0) and np.allclose(unsettled, lost)  # none failed: every -1 is an unsettled draw
    long = g.basin_probability(m, f, A, jax.random.key(0), 8, x_range=(-2, 2),
                               settings=g.SweepSettings(settle_time=model_settle_time(m, wells))).value
    assert np.all(np.asarray(long.unsettled) == 0) and -1 not in np.asarray(long.configs).tolist()
