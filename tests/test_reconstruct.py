"""Paper cases (Sec. 2.3, 3.1): GMR accuracy targets, GMC-SINDy measured beside it."""

import warnings

import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._reconstruct._local_rules import low_order_terms, velocity_terms_not_shared
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
    assert damping_error(m, s.truth, 0, s.x_range[0], s.v_range[0]) < 0.05
    # Table B2 shape: cubic restoring and the right damping term dominate
    k = np.asarray(m.stiffness)[0]
    np.testing.assert_allclose(k[1], -2244, rtol=0.01)
    np.testing.assert_allclose(k[3], 1755, rtol=0.01)
    phys, order, value = term
    np.testing.assert_allclose(np.asarray(getattr(m, phys))[0, order], value, rtol=0.02)
    # standard errors come with the model
    assert m.stderr is not None and np.isfinite(np.asarray(m.stderr["stiffness"])[0, 3])
    stable = [x for x, st in equilibria(m, 0, s.x_range[0]) if st]
    np.testing.assert_allclose(stable, [-1.1308, 1.1308], atol=5e-3)
    assert all(min(sc["r2"]) > 0.99 for sc in res.stats["training"].values())
    # the default coordination ("auto") keeps the paper's route on the paper's case, to the bit
    # (issue 15: the joint regression replaces it only where it is inadmissible)
    assert res.stats["dofs"][0].stats["coordination"] == "gls"
    paper = g.reconstruct(recs, g.Library(5, 5), coordination="gls").value
    for block in ("stiffness", "velocity_damping", "position_damping"):
        np.testing.assert_array_equal(np.asarray(getattr(m, block)), np.asarray(getattr(paper, block)))


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
    assert said[0] == "local fits at 3 wells" and said[1].startswith("coordination") and "sanity" in said[-1]
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
    keep = low_order_terms(lib)  # x^0, x^1, v, x v: what `reconstruct` exempts
    assert keep.tolist() == [True, True, False, False, False, True, True]
    kept = g.fit_local(x, v, y, lib, solver, None, keep=keep).value
    assert abs(float(kept.coef[i_xv]) - 20.0) < 0.01
    assert 0 < float(kept.covariance[i_xv, i_xv]) < 1e-5


def test_unshared_velocity_damping_mask():
    lib = g.Library(3, 3)
    terms = lib.terms()
    coef = np.zeros((2, lib.n_terms))
    col = {t: i for i, t in enumerate(terms)}
    coef[:, col[("velocity_damping", 1)]] = 0.3  # viscous: part of C(x) v, never judged here
    coef[0, col[("velocity_damping", 3)]] = 5.0  # v^3 at one well only: not shared
    coef[:, col[("velocity_damping", 2)]] = 1.0  # v|v| at both wells: shared
    coef[0, col[("position_damping", 1)]] = 2.0  # x v differs by well legitimately
    mask = velocity_terms_not_shared(coef, lib)
    assert [t for t, m in zip(terms, mask) if m] == [("velocity_damping", 3)]


@pytest.mark.slow  # a 5-cell reproduction, three times
def test_damping_terms_found_at_one_well_only_are_dropped():
    """Kresling chain (damping ratio 0.2, 0.75 mm, seed 4): the base cell's folded-well fit selected v|v|, v^3,
    v^3|v| (each > 3 sigma) in place of the unselected x^2 v; averaged by Eq. (21) they put 8 % error on the global
    damping. The sharing rule, the refit of a well whose screen zeroed some damping terms and x^2 v kept where every
    well resolves it (`_extend_position_damping`) each remove them: with and without sharing, the base cell's
    damping within 0.5 %, and the cells where every well agrees untouched by the sharing."""
    system = g.systems.kresling5(damping_ratio=0.2)
    recs = g.systems.make_recordings(system, 7.5e-4, snr_db=60.0, seed=4)
    box = system.x_range[0], system.v_range[0]
    # shared_design off: the cells' shared curvature (a prior on every local refit) also removes it
    raw = g.reconstruct(recs, g.Library(5, 5), shared_damping=False, extend_restoring=False, shared_design=False)
    default = g.reconstruct(recs, g.Library(5, 5), shared_damping=False)
    res = g.reconstruct(recs, g.Library(5, 5), extend_restoring=False, shared_design=False)
    for sol in (raw, default, res):
        assert damping_error(sol.value, system.truth, 0, *box) < 0.005  # measured 0.011-0.014 % (the artefact: 8 %)
    for i in range(1, 5):  # cells where every well agrees are untouched
        assert res.stats["dofs"][i].stats["dropped_velocity_damping"] == []
        np.testing.assert_array_equal(res.stats["dofs"][i].local_coef, raw.stats["dofs"][i].local_coef)


def test_screen_truncates_the_restoring_series_from_the_top_only():
    """An unresolved q^3 under a resolved q^4 is kept (the coordination would take a zero there as
    exact); an unresolved top order is dropped; a zero STLS chose stays a known zero."""
    from gmr_jax._reconstruct._local_rules import _screen

    lib = g.Library(5, 1)  # 1, q .. q^5, sgn(v), v, q v
    se = np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0])
    coef = np.array([[5.0, 9.0, 4.0, 2.0, 6.0, 1.0, 0.5, 8.0, 0.2],   # q^3 at t = 2 under q^4 at 6; q^5 at 1
                     [5.0, 9.0, 0.0, 2.0, 6.0, 0.0, 0.0, 8.0, 4.0]])  # q^2 a zero STLS chose
    fits = g.LocalFit(equilibrium=np.zeros(2), coef=coef, covariance=np.stack([np.diag(se**2)] * 2),
                      threshold=np.zeros(2), rss=np.ones(2), n_samples=np.full(2, 100.0))
    out = np.asarray(_screen(fits, 3.0, lib).coef)
    np.testing.assert_array_equal(out[0], [5.0, 9.0, 4.0, 2.0, 6.0, 0.0, 0.0, 8.0, 0.0])
    np.testing.assert_array_equal(out[1], [5.0, 9.0, 0.0, 2.0, 6.0, 0.0, 0.0, 8.0, 4.0])
    assert np.asarray(_screen(fits, 3.0, lib).covariance)[0, 3, 3] == 1.0
    plain = np.asarray(_screen(fits, 3.0).coef)  # without the library: every term on its own
    assert plain[0, 3] == 0.0


def test_screen_drops_an_unresolved_top_order_above_zeros():
    """The restoring orders above the top one are zeros with zero standard error (0 >= 3 x 0):
    they are not resolved orders, so an unresolved q^3 under them is dropped (the bug that kept
    every fitted order under a zero)."""
    from gmr_jax._reconstruct._local_rules import _screen

    lib = g.Library(5, 1)
    coef = np.array([[5.0, 9.0, 4.0, 0.6, 0.0, 0.0, 0.0, 8.0, 0.0]])
    cov = np.diag([1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0])[None]
    fits = g.LocalFit(equilibrium=np.zeros(1), coef=coef, covariance=cov, threshold=np.zeros(1), rss=np.ones(1),
                      n_samples=np.full(1, 100.0))
    np.testing.assert_array_equal(np.asarray(_screen(fits, 3.0, lib).coef)[0], [5.0, 9.0, 4.0, 0, 0, 0, 0, 8.0, 0])


def test_noise_free_records_give_the_truths_degree():
    """Noise-free records of the bistable joint (a cubic): the global law is the cubic, not a higher
    interpolant that exact local data "confirm" (audit D F6: noise-free records gave degree 7 here, degree 17
    with twelve spurious "significant" terms on a tri-stable quintic)."""
    s = g.systems.bistable_joint("position_independent")
    recs = g.systems.make_recordings(s, np.deg2rad(1.0), snr_db=None, duration=4.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = g.reconstruct(recs, g.Library(*s.orders["gmr"]))
    stiff = np.asarray(sol.value.stiffness)[0]
    assert np.trim_zeros(stiff, "b").size - 1 == 3
    assert restoring_l2(s, stiff)[0] < 1e-8
