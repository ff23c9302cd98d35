"""Paper cases (Sec. 2.3, 3.1): accuracy of the default route and of the paper's route, GMC-SINDy
measured beside them."""

import warnings

import numpy as np
import pytest

import gmr_jax as g
from gmr_jax.metrics._metrics import damping_error, equilibria, restoring_error

from _truth import restoring_l2


@pytest.fixture(scope="module")
def joint_data():
    out = {}
    for damping in ("position_independent", "position_dependent"):
        s = g.systems.bistable_joint(damping)
        out[damping] = (s, g.systems.make_recordings(s, np.deg2rad(0.5), snr_db=60.0, seed=3))
    return out


@pytest.mark.parametrize("damping,term", [("position_independent", ("velocity_damping", 3, 10.0)),
                                          ("position_dependent", ("position_damping", 2, 50.0))])
def test_joint_small_amplitude(joint_data, damping, term):
    s, recs = joint_data[damping]
    res = g.reconstruct(recs, g.Library(5, 5))
    m = res.value
    assert restoring_error(m, s.truth, 0, s.x_range[0]) < 0.01
    # the damping at the recorded speeds; beyond them the records do not fix it, and the band says so
    speed = max(float(np.max(np.abs(r.v))) for r in recs)
    assert damping_error(m, s.truth, 0, s.x_range[0], [-speed, speed]) < 0.02
    # the restoring law is the cubic of Table B2: its linear and cubic coefficients within 1 %, the
    # orders above within their standard errors of 0
    k, se = np.asarray(m.stiffness)[0], np.asarray(m.stderr["stiffness"])[0]
    np.testing.assert_allclose(k[[1, 3]], [-2244, 1755], rtol=0.01)
    assert np.all(np.abs(k[4:]) <= 2 * se[4:] + 1e-9 * np.abs(k[3])), (k, se)
    phys, order, value = term
    np.testing.assert_allclose(np.asarray(getattr(m, phys))[0, order], value, rtol=0.02)
    # standard errors come with the model
    assert m.stderr is not None and np.isfinite(np.asarray(m.stderr["stiffness"])[0, 3])
    stable = [x for x, st in equilibria(m, 0, s.x_range[0]) if st]
    np.testing.assert_allclose(stable, [-1.1308, 1.1308], atol=5e-3)
    assert all(min(sc["r2"]) > 0.99 for sc in res.stats["training"].values())
    assert res.stats["dofs"][0].stats["coordination"] == "evidence"
    # the paper's route on the same records: Table B2's coefficients
    paper = g.reconstruct(recs, g.Library(5, 5), coordination="gls").value
    assert restoring_error(paper, s.truth, 0, s.x_range[0]) < 0.01
    np.testing.assert_allclose(np.asarray(paper.stiffness)[0, [1, 3]], [-2244, 1755], rtol=0.01)
    np.testing.assert_allclose(np.asarray(getattr(paper, phys))[0, order], value, rtol=0.02)


def test_gmc_sindy_runs_and_degrades(joint_data):
    s, recs = joint_data["position_dependent"]
    gm = g.gmc_sindy(recs, g.Library(7, 7))
    # at 0.5 degrees the global-library fit loses the damping (paper Fig. 6c); measured, not assumed
    assert damping_error(gm.value, s.truth, 0, s.x_range[0], s.v_range[0]) > 0.2
    # and says where its damping feeds energy in (audit: absurd baseline laws came without a word); checked on the
    # model's own damping force at the point named, and against a grid of the span it names
    said = [w for w in gm.stats["warnings"] if "GMC-SINDy model is not admissible" in w]
    assert len(said) == 1 and "its damping feeds energy in (D v < 0) at x = " in said[0], gm.stats["warnings"]
    x0, v0 = (float(said[0].split(f"{k} = ")[1].split(",")[0].split(";")[0]) for k in ("x", "v"))
    assert float(gm.value.damping(np.array([x0]), np.array([v0]))[0]) * v0 < 0
    # the paper route's model on the same data is admissible: no such warning
    assert not any("not admissible" in w for w in g.reconstruct(recs, g.Library(5, 5)).stats["warnings"])


@pytest.mark.slow  # a second NES reconstruction (Library(3, 3)); the default tier checks the NES at the
# default orders (test_sanity.py::test_clean_builtin_data_give_no_warning)
def test_nes_three_equilibria():
    s = g.systems.tristable_nes()
    recs = g.systems.make_recordings(s, 1e-3, snr_db=60.0, seed=0, duration=5.0)
    said = []
    m = g.reconstruct(recs, g.Library(3, 3), progress=said.append).value
    assert said[0] == "posterior of the global law" and "checks" in said[-1]
    assert restoring_error(m, s.truth, 0, s.x_range[0]) < 0.02
    got, want = equilibria(m, 0, s.x_range[0]), equilibria(s.truth, 0, s.x_range[0])
    assert [st for _, st in got] == [st for _, st in want] == [True, False, True, False, True]
    np.testing.assert_allclose([x for x, _ in got], [x for x, _ in want], atol=1e-3)


def test_single_equilibrium_is_a_clear_error(joint_data):
    _, recs = joint_data["position_independent"]
    with pytest.raises(g.GMRInputError, match="at least two distinct equilibria"):
        g.reconstruct(recs[:1])
    with pytest.raises(g.GMRInputError, match="same equilibrium"):
        g.reconstruct([recs[0], recs[0]])


def test_missing_derivatives_are_estimated(joint_data):
    s, recs = joint_data["position_independent"]
    bare = [g.Recording(t=r.t, x=r.x, base_acc=r.base_acc, name=r.name) for r in recs]
    res = g.reconstruct(bare, g.Library(5, 5))
    assert restoring_error(res.value, s.truth, 0, s.x_range[0]) < 0.03


def test_wells_recorded_with_different_sensors(joint_data):
    """One well's file x only, the other's x, v, a (audit 8: the local fits' stats did not stack, an internal
    error): fitted as any other pair."""
    s, recs = joint_data["position_independent"]
    mixed = [g.Recording(t=recs[0].t, x=recs[0].x, base_acc=recs[0].base_acc, name=recs[0].name), recs[1]]
    res = g.reconstruct(mixed, g.Library(5, 5))
    assert restoring_error(res.value, s.truth, 0, s.x_range[0]) < 0.03


def test_keep_exempts_terms_from_the_threshold():
    """A small but well-determined x v term: a large manual threshold removes it, `keep`
    brings it back with the least-squares value (and a finite standard error)."""
    rng = np.random.default_rng(0)
    lib = g.Library(3, 1)
    x = 0.01 * rng.standard_normal(4000)
    v = rng.standard_normal(4000)
    y = 200.0 * x + 0.5 * v + 20.0 * x * v + 1e-3 * rng.standard_normal(4000)
    solver = g.STLS(threshold=20.0, alpha=0.0, normalize_columns=True)  # normalised: x 126, v 32, x v 13
    i_xv = list(lib.terms()).index(("position_damping", 1))
    plain = g.fit_local(x, v, y, lib, solver, None).value
    assert float(plain.coef[i_xv]) == 0.0
    keep = np.array([t in (("stiffness", 0), ("stiffness", 1), ("velocity_damping", 1), ("position_damping", 1))
                     for t in lib.terms()])
    kept = g.fit_local(x, v, y, lib, solver, None, keep=keep).value
    assert abs(float(kept.coef[i_xv]) - 20.0) < 0.01
    assert 0 < float(kept.covariance[i_xv, i_xv]) < 1e-5


def test_noise_free_records_give_the_truths_degree():
    """Noise-free records of the bistable joint (a cubic): the evidence puts the degree at the
    cubic's, and the law is the cubic to rounding (a higher interpolant that exact local data
    "confirm" is the failure this guards)."""
    s = g.systems.bistable_joint("position_independent")
    recs = g.systems.make_recordings(s, np.deg2rad(1.0), snr_db=None, duration=4.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = g.reconstruct(recs, g.Library(*s.orders["gmr"]))
    stiff = np.asarray(sol.value.stiffness)[0]
    assert sol.stats["dofs"][0].stats["degree"] == 3
    assert restoring_l2(s, stiff)[0] < 1e-6
