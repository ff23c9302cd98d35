"""Identifiability before discovery (issue 14): the mass of a homogeneous equation is held, a
candidate the data cannot separate from the model's terms (or from another candidate beyond
them) is listed as not separable and never reported as a finding."""

import numpy as np
import pytest

import gmr_jax
from gmr_jax._discover._identify import (VIF_HARD, VIF_MAX, ambiguous, closest, determined, explained, homogeneous,
                                         mass_believable, screen)
from gmr_jax._discover._equation import Rows
from studies.scenarios import Scenario, build_full

K = (2 * np.pi * 2.0) ** 2
C = 2 * 0.05 * np.sqrt(K)
LIN = {"dof": 0, "physics": "stiffness", "order": 1, "coefficient": K}
VISC = {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": C}
T = gmr_jax.Term
RULE = gmr_jax.SelectionRule(n_boot=60)


def test_explained_is_the_uncentred_r2_of_least_squares(rng):
    X = rng.normal(size=(400, 3))
    c = X @ [1.0, -2.0, 0.5] + 0.3 * rng.normal(size=400)
    coef, *_ = np.linalg.lstsq(X, c, rcond=None)
    r = c - X @ coef
    assert explained(c, X) == pytest.approx(1 - r @ r / (c @ c), rel=1e-10)
    assert explained(c, np.zeros((400, 0))) == 0.0 and explained(np.zeros(400), X) == 0.0
    assert explained(X[:, 1] * 3.0, X) == pytest.approx(1.0)


def test_screen_flags_a_column_the_others_reproduce(rng):
    t = np.linspace(0, 10, 2000)
    v = np.cos(2 * np.pi * 2.5 * t)
    B = v[:, None]
    drag, coul, noise = np.sign(v) * v**2, np.sign(v), rng.normal(size=t.size)
    near = v + 0.03 * rng.normal(size=t.size)  # 99.9 % v
    keep, ns, vifs = screen(B, np.stack([drag, coul, noise, near], 1), ["v"], ["v|v|", "sgn(v)", "n", "v'"],
                            ["quadratic_drag", "coulomb_friction", "noise", "near_v"])
    # one frequency: v|v| is 98 % v (VIF ~26): collinear, it competes but must be determined;
    # sgn(v) 90 % (VIF 5); the near copy of v is not separable at all
    assert keep == [0, 1, 2]
    assert VIF_MAX <= vifs["v|v|"] < VIF_HARD and vifs["sgn(v)"] < VIF_MAX
    assert [e["physics"] for e in ns] == ["near_v"] and ns[0]["with"] == "v" and ns[0]["vif"] >= VIF_HARD
    assert closest(drag, B, ["v"]) == ("v", pytest.approx(0.98, abs=0.01))
    assert vifs["n"] == pytest.approx(1.0, abs=0.01)


def test_determined_needs_an_interval_clear_of_zero_and_tight():
    assert determined(21.2, np.array([18.1, 24.8]))          # EMPS Coulomb: +-16 %
    assert not determined(1.0, np.array([-0.2, 2.2]))        # includes zero
    assert not determined(1.0, np.array([0.3, 1.9]))         # +-80 %
    assert determined(-3.0, np.array([-3.6, -2.5]))          # negative coefficients too


def test_ambiguous_kept_term_is_one_a_substitute_fits_as_well(rng):
    t = np.linspace(0, 10, 2000)
    v = np.cos(2 * np.pi * 2.5 * t)
    B = v[:, None]
    drag, cub, noise = np.sign(v) * v**2, v**3, rng.normal(size=t.size)
    Xc = np.stack([drag, cub, noise], 1)
    y = 0.3 * drag + 1e-3 * rng.normal(size=t.size)
    # one frequency: beyond v, drag and v^3 are both a third harmonic, either fits
    amb = ambiguous(B, Xc, [1], y, n_eff=200.0)
    assert [(k, j) for k, j, _ in amb] == [(1, 0)]
    # broadband v (a sum of incommensurate tones): the true term fits clearly better, no ambiguity
    vb = np.cos(2 * np.pi * 1.1 * t) + 0.7 * np.cos(2 * np.pi * 2.9 * t + 1) + 0.5 * np.cos(2 * np.pi * 4.3 * t + 2)
    Xb = np.stack([np.sign(vb) * vb**2, vb**3, noise], 1)
    yb = 0.3 * vb**3 + 1e-3 * rng.normal(size=t.size)
    assert ambiguous(vb[:, None], Xb, [1], yb, n_eff=200.0) == []


def test_homogeneous_and_believable_mass():
    rows = [Rows(np.zeros(3), np.zeros((3, 0)), None, applied_sq=0.0, inertia_sq=2.0)]
    assert homogeneous(rows)
    assert not homogeneous(rows + [Rows(np.zeros(3), np.zeros((3, 0)), None, applied_sq=1e-3, inertia_sq=2.0)])
    assert mass_believable(1.0, 0.4) and not mass_believable(1.0, -0.9) and not mass_believable(1.0, np.nan)


@pytest.mark.slow  # a discovery scenario end to end (~12 s cold); the identifiability rules themselves are tested above
def test_base_excited_independent_dof_holds_the_mass_and_finds_the_friction():
    """Issue 14, finding 1: base excitation, independent topology (what `gmr fit` writes), hidden
    Coulomb friction. Before: mass 1 -> 2e-8, every coefficient scaled to ~0, "nothing missing"."""
    eff = (T(0, "velocity_damping", 0), 0.15, T(0, "velocity_damping", 1))
    sc = Scenario("base", (1.0,), "independent", (LIN, VISC), eff, amplitude=20.0, duration=12.0,
                  excite="base", snr_db=50.0)
    b = build_full(sc)
    rep = gmr_jax.discover(b.model, b.est, b.hold, rule=RULE).value
    idf = rep.identifiability[0]
    assert idf.mass == "held" and "no force input" in idf.why
    np.testing.assert_array_equal(np.asarray(rep.model.masses), [1.0])
    assert [f["physics"] for f in rep.findings] == ["coulomb_friction"]
    assert rep.findings[0]["coefficient"] == pytest.approx(b.c_eff, rel=0.1)
    k1 = float(np.asarray(rep.model.stiffness)[0, 1])
    assert k1 == pytest.approx(K, rel=0.02)  # nothing slid towards zero
    assert rep.after["nrmse"] < 0.5 * rep.before["nrmse"]
    assert "held, DOF 0: mass: no force input" in rep.summary()
    d = rep.to_dict()
    assert d["identifiability"][0]["mass"] == "held" and d["not_separable"] == []


@pytest.mark.slow
def test_one_frequency_drag_is_not_separable_and_not_a_finding():
    """At one forcing frequency quadratic drag is 98 % viscous damping (VIF ~26); small (10 %)
    and at 30 dB what is left of it is not determined: no finding, listed as collinear with v."""
    eff = (T(0, "velocity_damping", 2), 0.10, T(0, "velocity_damping", 1))
    sc = Scenario("drag1f", (1.0,), "independent", (LIN, VISC), eff, amplitude=20.0, duration=12.0,
                  band=(2.5, 2.5), snr_db=30.0)
    b = build_full(sc)
    rep = gmr_jax.discover(b.model, b.est, b.hold, rule=RULE).value
    assert rep.findings == []
    phys = [e["physics"] for e in rep.not_separable]
    assert "quadratic_drag" in phys
    assert "not separable" in rep.summary()


@pytest.mark.slow
def test_spring_against_mass_at_one_frequency_is_not_a_finding_and_a_worse_refit_is_flagged():
    """The EMPS trap: a spring the model lacks, one forcing frequency, so x and a are collinear
    and stiffness trades off against the mass. No finding; the re-calibrated model is worse on
    the holdout and the report says to keep the given one."""
    eff = (T(0, "stiffness", 1), 0.30, T(0, "velocity_damping", 1))
    cub = {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 2.0 * K}
    sc = Scenario("k1f", (1.0,), "independent", (VISC, cub), eff, amplitude=20.0, duration=12.0,
                  band=(2.5, 2.5), snr_db=50.0)
    b = build_full(sc)
    rep = gmr_jax.discover(b.model, b.est, b.hold, rule=RULE).value
    assert rep.findings == []
    assert "linear_stiffness" in [e["physics"] for e in rep.not_separable]
    assert rep.after["nrmse"] > rep.before["nrmse"]
    assert rep.warnings and "keep the given model" in rep.warnings[0]
    assert "warning: the augmented model is worse" in rep.summary()


def test_weak_rows_ignore_a_constant_offset_of_x():
    """The sampled psi'' sums to zero (as its integral does), so a constant added to x (an
    unobserved equilibrium) changes no inertia row of the weak form."""
    from gmr_jax._discover._equation import test_functions

    for support in (15, 41, 201):
        psi, d2 = test_functions(support, 1e-3)
        assert abs(d2.sum()) <= 1e-12 * np.abs(d2).sum()
        assert d2[0] == 0.0 and d2[-1] == 0.0
