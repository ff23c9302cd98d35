"""The joint coordination and the admissibility rule (issue 15)."""

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._coordination._joint import (
    JointSettings,
    inadmissible,
    joint_coordinate,
    restoring_fault_kinds,
)


def _samples(f, c, wells=(-1.0, 1.0), amp=0.05, n=3000, noise=1e-3, seed=0):
    """Small multi-tone vibrations about each well of F(x) = f(x), damping c v: per well
    (x, v, y = F(x) + c v + noise)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 200.0
    xs, vs, ys = [], [], []
    for w in wells:
        q = sum(amp / 3 * np.sin(2 * np.pi * fr * t + rng.uniform(0, 6.3)) for fr in (1.3, 3.1, 7.7))
        qd = np.gradient(q, t)
        x = w + q
        xs.append(x), vs.append(qd), ys.append(f(x) + c * qd + noise * rng.standard_normal(n))
    return np.array(xs), np.array(vs), np.array(ys)


def test_joint_recovers_a_polynomial_double_well_and_is_admissible():
    f = lambda x: -x + x**3  # noqa: E731
    xs, vs, ys = _samples(f, 0.3)
    stiff, vdamp, pdamp, cov, st = joint_coordinate(xs, vs, ys, np.ones_like(xs), np.array([-1.0, 1.0]),
                                                    np.ones(2), speed=5.0)
    x = np.linspace(-1.5, 1.5, 301)
    err = np.linalg.norm(np.polynomial.polynomial.polyval(x, stiff) - f(x)) / np.linalg.norm(f(x))
    assert err < 0.01
    assert st["joint_admissible"] and st["joint_degree"] % 2 == 1
    assert abs(vdamp[1] - 0.3) < 0.01  # viscous term
    assert inadmissible(stiff, vdamp, pdamp, [-1.0, 1.0], 5.0) == []
    ev = np.linalg.eigvalsh(0.5 * (cov + cov.T))
    assert ev.min() > -1e-9 * ev.max()  # a covariance


def test_joint_candidates_respect_the_settings():
    f = lambda x: -x + x**3  # noqa: E731
    xs, vs, ys = _samples(f, 0.3, seed=1)
    s = JointSettings(max_degree=5, max_damping_degree=1, velocity_orders=(3,), log_lambdas=(-8.0,))
    stiff, vdamp, pdamp, _, st = joint_coordinate(xs, vs, ys, np.ones_like(xs), np.array([-1.0, 1.0]), np.ones(2),
                                                  5.0, s)
    assert stiff.shape == (6,) and st["joint_degree"] in (3, 5)
    assert st["joint_n_candidates"] == 2 * 2 * 2 * 1 * 3  # degrees x C degrees x subsets x lambdas


def test_inadmissible_names_each_failure():
    eq = [-1.0, 1.0]
    assert inadmissible([0, -1, 0, 1], [0, 0.1], [0], eq, 3.0) == []
    even = inadmissible([0, -1, 0.2, 1, 0.5], [0, 0.1], [0], eq, 3.0)
    assert any("even degree 4" in r for r in even)
    spurious = np.polynomial.polynomial.polyfromroots([-1.8, -1.4, -1, 0, 1, 1.4, 1.8])  # wells at +-1.8 too
    assert any("changes sign 7 times" in r for r in inadmissible(spurious, [0, 0.1], [0], eq, 3.0))
    # the same faults by kind (what pooled laws are compared by, `_design_law`)
    assert restoring_fault_kinds([0, -1, 0, 1], eq) == {}
    assert restoring_fault_kinds(spurious, eq) == {"sign": 7}
    assert restoring_fault_kinds([0, -1, 0, 1.2, 0, -0.1], eq) == {"outward": 1}
    assert restoring_fault_kinds([0, -1, 0.2, 1, 0.5], eq).keys() >= {"even"}
    assert any("no damping" in r for r in inadmissible([0, -1, 0, 1], [0, 0], [0], eq, 3.0))
    # C(x) v with C = 0.1 - 0.2 x^2 goes negative beyond |x| = 0.71
    assert any("feeds energy in" in r for r in inadmissible([0, -1, 0, 1], [0, 0.1], [0, 0, -0.2], eq, 3.0))
    # v^3 with a negative coefficient: dissipative at low speed only
    assert any("feeds energy in" in r for r in inadmissible([0, -1, 0, 1], [0, 0.1, 0, -0.1], [0], eq, 3.0))
    # a negative friction: dissipative above |v| = 0.1 only, below the grid's lowest speed (0.075) its power is
    # within the tolerance of the grid check; it feeds energy in as v -> 0 wherever it is
    assert any("friction" in r and "feeds energy in" in r for r in inadmissible([0, -1, 0, 1], [-0.01, 0.1], [0],
                                                                                   eq, 3.0))
    assert inadmissible([0, -1, 0, 1], [0.01, 0.1], [0], eq, 3.0) == []


def test_joint_never_takes_a_negative_friction():
    """Data whose damping is 0.3 v - 0.02 sgn(v) (energy fed in at |v| < 0.067): the candidate with the friction
    term fits them best but cannot be admitted; the law keeps no negative friction."""
    f = lambda x: -x + x**3  # noqa: E731
    xs, vs, ys = _samples(f, 0.3, noise=1e-4)
    ys = ys - 0.02 * np.sign(vs)
    s = JointSettings(velocity_orders=(0,))
    _, vdamp, _, _, st = joint_coordinate(xs, vs, ys, np.ones_like(xs), np.array([-1.0, 1.0]), np.ones(2), 5.0, s)
    assert st["joint_n_admissible"] > 0 and vdamp[0] >= 0.0, vdamp


@pytest.fixture(scope="module")
def single_tone():
    """Issue 15's single-tone analogue (studies/single_tone.py): the non-polynomial arch,
    one base sine per well, displacement only, 30 dB, seed 0."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "studies"))
    import single_tone as st

    recs = st.tone_recordings("x", 30, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return st, recs, g.reconstruct(recs, coordination="gls", throw=False), g.reconstruct(recs, throw=False)


@pytest.mark.slow  # a study case end to end (two reconstructions of the
# single-tone arch, ~25 s cold); the default tier tests the rule on the NES and on sinusoidal joint records (test_sanity)
def test_default_replaces_an_inadmissible_paper_route(single_tone):
    """The paper's interpolant (even degree 10) explains each well's own data (R² 0.987; -1e4 before the
    local fits took off the noise their columns share with the target) but blows up between the wells,
    941 x off the truth; the default says so, takes the joint regression and gives an
    admissible model that explains both wells and is within 2 % (measured 1.16 % since the joint
    regression's columns pass through the filter's gain and the local fits take off the noise they share
    with the target; 5.68 % at stop 40, 2.4 % before; the Hermite interpolant of the exact value, slope and
    curvature at both wells: 2.6 %)."""
    st, _, paper, default = single_tone
    assert st.restoring_error(paper.value) > 10
    s = default.stats["dofs"][0].stats
    assert s["coordination"] == "joint" and s["joint_admissible"]
    assert any("blows up" in r for r in s["paper_route_rejected"])
    assert min(min(v["r2"]) for v in default.stats["training"].values()) > 0.95
    m = default.value
    assert inadmissible(m.stiffness[0], m.velocity_damping[0], m.position_damping[0], [-1.090, 0.884], 3.0) == []
    assert st.restoring_error(m) < st.restoring_error(paper.value)
    assert st.restoring_error(m) < 0.02


@pytest.mark.slow  # one more reconstruction of the fixture's records (~15 s)
def test_a_screen_that_zeroes_a_group_keeps_one_of_its_terms(single_tone):
    """The same records with `structured_noise`: the t-screen zeroes one well's collinear damping terms all at
    once; zeroed without a refit, that well's curvature is left far from the truth's. The screen keeps one term
    of such a group and refits (`_local_rules`): both wells' F''/2 within 5 % of the truth's -23.85 and 23.72,
    and the default law within 2 % on the span."""
    st, recs, _, _ = single_tone
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = g.reconstruct(recs, structured_noise=True, throw=False)
    names = sol.stats["library"].names()
    half_curvature = np.asarray(sol.stats["dofs"][0].local_coef)[:, names.index("x^2")]
    assert np.all(np.abs(half_curvature / np.array([-23.85, 23.72]) - 1) < 0.05), half_curvature
    assert st.restoring_error(sol.value) < 0.02


@pytest.mark.slow  # a study case end to end (~16 s cold): simulate, reconstruct, scipy cross-well run
def test_default_replaces_an_untested_outward_turn():
    """Displacement only, 50 dB: the paper's quintic explains both wells' data (R² 0.9999) but is
    the exact interpolant of F, F', F'' at two wells and turns outward 0.9 spans beyond them, so a
    cross-well motion escapes (it diverged, silently). The default replaces it by the joint
    regression, which explains both wells as well, confines, and stays bounded when driven across
    the wells (checked with scipy's integrator, not the library's)."""
    import sys
    from pathlib import Path

    from scipy.integrate import solve_ivp

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "studies"))
    import single_tone as st

    recs = st.tone_recordings("x", 50, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = g.reconstruct(recs, throw=False)
    s = sol.stats["dofs"][0].stats
    assert any("turns outward" in r for r in s["paper_route_rejected"])  # the paper's quintic (-1.6 x^5)
    assert s["coordination"] == "joint" and s["joint_admissible"] and s["escapes"] == []
    assert min(min(v["r2"]) for v in sol.stats["training"].values()) > 0.9998  # the paper route: 0.99989
    m = sol.value
    k = np.asarray(m.stiffness[0])
    assert np.trim_zeros(k, "b")[-1] > 0 and (np.trim_zeros(k, "b").size - 1) % 2 == 1
    ts, x, v, exc = st.cross_record()

    b, c, mass = np.asarray(m.velocity_damping[0]), np.asarray(m.position_damping[0]), float(m.masses[0])
    # the air drag the joint regression's score favours (v|v| by 5.7 over none) is kept: the tie among
    # near-equal laws picks the tamest of as many velocity terms, it does not drop one (measured 0.0571 for
    # the truth's 0.05; dropped, the one-period NRMSE of the cross-well record was 16.1 % for 5.2 %)
    assert s["joint_velocity_orders"] == [2] and abs(b[2] - st.SYSTEM.truth.c2) < 0.3 * st.SYSTEM.truth.c2
    # ... yet v^3 scores within 1 of it (the tie took the tamer v|v|): at cross-well speeds the records do not
    # decide the damping law, and rule 14 says so
    assert any("do not decide the damping law" in m for m in sol.stats["warnings"])
    w = 2 * np.pi * st.CROSS["frequency"]

    def rhs(t, y):  # m x'' + F(x) + sum_j B_j sgn(v)|v|^j + C(x) v = -m a_base, in NumPy
        q, qd = y
        f = np.polynomial.polynomial.polyval(q, k) + np.polynomial.polynomial.polyval(q, c) * qd
        f += sum(b[j] * np.sign(qd) * abs(qd) ** j for j in range(b.size))
        return [qd, -f / mass + st.CROSS["amplitude"] * w**2 * np.sin(w * t)]

    out = solve_ivp(rhs, (0.0, 30.0), [x[0], v[0]], max_step=0.02, rtol=1e-6)
    assert out.success and np.all(np.isfinite(out.y)) and np.max(np.abs(out.y[0])) < 3.0
    assert np.any(out.y[0] > st.SADDLE) and np.any(out.y[0] < st.SADDLE)  # it does cross the wells


def test_joint_reports_a_prior_data_conflict_and_the_check_warns():
    """The data cross a well that was not recorded (declared wells -2 and 0 of a tri-stable
    F = x (x^2 - 1)(x^2 - 4) / 4, one record swinging over [-2.3, 2.3]): every law that fits them
    has 5 sign changes, so none is admissible for two wells; the admissible choice is far off and
    its own band does not say so. The joint regression reports the conflict and the law the data
    prefer; rule 12 warns; before, nothing did (magnet at 0.05, 40 dB: 19 % off, 0.5 % band)."""
    from gmr_jax._coordination._joint import CONFLICT
    from gmr_jax._reconstruct._sanity import check_conflict

    f = lambda x: x * (x**2 - 1) * (x**2 - 4) / 4  # noqa: E731
    rng = np.random.default_rng(0)
    t = np.arange(3000) / 200.0
    q0 = sum(0.03 * np.sin(2 * np.pi * fr * t + rng.uniform(0, 6.3)) for fr in (1.3, 3.1, 7.7))
    x1 = 2.3 * np.sin(2 * np.pi * 0.7 * t) * (0.6 + 0.4 * np.sin(2 * np.pi * 0.11 * t))
    xs = np.stack([-2.0 + q0, x1])
    vs = np.gradient(xs, t, axis=1)
    ys = f(xs) + 0.3 * vs + 1e-3 * rng.standard_normal(xs.shape)
    s = JointSettings(max_degree=7, max_damping_degree=1, velocity_orders=(3,), log_lambdas=(-8.0, -4.0, 0.0),
                      log_lambdas_damping=(0.0,))
    stiff, _, _, cov, st = joint_coordinate(xs, vs, ys, np.ones_like(xs), np.array([-2.0, 0.0]), np.ones(2), 20.0, s,
                                            refine=False)
    assert st["joint_conflict"] > CONFLICT
    free = np.asarray(st["joint_unconstrained"])[: stiff.size]
    x = np.linspace(-2.3, 2.3, 201)
    scale = np.abs(f(x)).max()
    chosen_err = np.abs(np.polynomial.polynomial.polyval(x, stiff) - f(x)).max() / scale
    preferred_err = np.abs(np.polynomial.polynomial.polyval(x, stiff + free) - f(x)).max() / scale
    assert preferred_err < 0.01 < chosen_err  # the preferred law is the data's; the admissible one is not
    msg = check_conflict(0, stiff, cov[: stiff.size, : stiff.size], free, st["joint_conflict"], -2.3, 2.3)
    assert len(msg) == 1 and "cannot decide" in msg[0]
    # with that difference in the covariance, the 95 % band holds the truth over the data
    phi = np.polynomial.polynomial.polyvander(x, stiff.size - 1)
    full = cov[: stiff.size, : stiff.size] + np.outer(free, free)
    sd = np.sqrt(np.einsum("ij,jk,ik->i", phi, full, phi))
    assert np.mean(np.abs(phi @ stiff - f(x)) <= 1.96 * sd) > 0.9


@pytest.mark.slow
def test_magnet_hopping_record_warns_and_its_band_covers():
    """Magnetic oscillator at 0.05 (one record hops between the wells), 40 dB, seed 1. Plain least
    squares (`errors_in_variables=False`): before rule 12, 24.5 % restoring error, a 0.51 % band
    covering 6 % of the span and no word on it; now a half-decade penalty refinement (4.5 % on the
    span), a band that holds the truth on >= 90 % of the span, and rule 12's warning. With the
    defaults (the noise on x corrected for) most of that conflict was the noise's bias: conflict
    1283 -> 19.5, 0.42 % off on the span, and the band still holds the truth."""
    system = g.systems.magnetic_bistable()
    recs = g.systems.make_recordings(system, 0.05, snr_db=40.0, seed=1)
    eq = system.equilibria[:, 0]
    xs = np.linspace(eq.min(), eq.max(), 201)
    truth = np.array([float(system.truth.restoring(jnp.asarray([x]))[0]) for x in xs])
    scale = np.max(np.abs(truth))
    for eiv in (False, True):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            model = g.reconstruct(recs, g.Library(*system.orders["gmr"]), errors_in_variables=eiv, throw=False).value
        conflict = any("cannot decide" in str(w.message) for w in caught if issubclass(w.category, g.GMRDataWarning))
        band = [g.force_band(model, jnp.asarray([x]), level=0.95) for x in xs]
        inside = [float(b.lower[0]) <= t <= float(b.upper[0]) for b, t in zip(band, truth)]
        assert np.mean(inside) >= 0.9
        worst = np.max(np.abs(np.array([float(b.mean[0]) for b in band]) - truth)) / scale
        if eiv:
            assert worst < 0.01
        else:
            assert conflict and worst < 0.06


@pytest.mark.slow  # one reconstruction of a coverage-study case (~20 s)
def test_joint_damping_at_the_edge_of_dissipation():
    """Bistable joint with damping 50 x^2 v (zero at the saddle), 1 degree sweeps, 30 dB, seed 2
    (`studies/coverage.py`): the wells' values and slopes put the paper route's C(0) slightly below 0, so the
    damping is refitted jointly; every admissible law is rejected by the data (a law zero at a point sits at the
    edge of admissibility, which noise puts on either side). On the decade grid of penalties the best admissible
    one had C(0) = 13.7 (x^2 v 39.2) and a band 10 standard errors off at the saddle (coverage 2.4 %); the grid
    refined between the best admissible penalty and the next smaller gives C(0) = 0.95, x^2 v 49.2, and the
    conflict's discrepancy enters the band whole."""
    from _truth import damping_coverage  # tests/_truth.py

    system = g.systems.bistable_joint("position_dependent")
    recs = g.systems.make_recordings(system, np.deg2rad(1.0), snr_db=30.0, seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = g.reconstruct(recs, g.Library(*system.orders["gmr"]), throw=False)
    st = sol.stats["dofs"][0].stats
    assert st["coordination"] == "gls + joint damping" and st["joint_conflict"] > 10.0
    assert float(st["joint_log_lambda_damping"]) not in (-8.0, -4.0, 0.0)  # off the decade grid (-4.75)
    c = np.asarray(sol.value.velocity_damping)[0, 1]
    x2 = np.asarray(sol.value.position_damping)[0, 2]
    assert 0.0 <= c < 3.0 and abs(x2 / 50.0 - 1.0) < 0.05, (c, x2)  # measured 0.95, 49.2
    assert damping_coverage(sol.value, system) >= 0.9  # measured 100 %


def test_damping_only_regression_dissipates_at_every_speed():
    """The damping-only regression (the restoring force fixed) on damping -0.3 v + 2 v^3 (energy fed in below
    |v| = 0.39): a law with a negative viscous term under a v^3 that dominates at the speed bound is within 1e-3
    of the grid's largest |D v|; each speed is checked against its own (geometric down to 1e-4 of the bound), so
    the law keeps D v >= 0 at every speed."""
    from gmr_jax._coordination._joint import dissipation_speeds

    xs, vs, _ = _samples(lambda x: 0.0 * x, 0.0, amp=0.2, noise=1e-4)
    ys = -0.3 * vs + 2.0 * vs**3 + 1e-4 * np.random.default_rng(1).standard_normal(vs.shape)
    s = JointSettings(log_lambdas=(0.0,), damping_only=True, velocity_orders=(3,))
    speed = 20.0
    _, vdamp, pdamp, _, st = joint_coordinate(xs, vs, ys, np.ones_like(xs), np.array([-1.0, 1.0]), np.ones(2), speed, s)
    assert st["joint_admissible"]
    x = np.linspace(-2.0, 2.0, 41)[:, None]
    v = dissipation_speeds(speed, geometric=True)[None, :]
    power = np.polynomial.polynomial.polyval(x, pdamp) * v**2 + sum(b * v ** (j + 1) for j, b in enumerate(vdamp))
    assert np.all(power >= -1e-3 * np.max(np.abs(power), axis=0)), vdamp


@pytest.mark.slow  # two reconstructions of a coverage-study case (~20 s)
def test_joint_damping_dissipates_below_the_recorded_speeds():
    """Bistable joint with damping 10 v^3, 5 degree sweeps, 30 dB, seed 4 (`studies/coverage.py`): the joint
    damping was -3.76 v + 2.72 v|v| + 9.56 v^3, which feeds energy in below |v| = 0.5; the dissipation check
    compared it with the largest |D v| of its grid, at the speed bound, where v^3 dominates. Checked at each
    speed (geometric down to 1e-4 of the bound): 1.25 v + 9.90 v^3 with the velocity columns as measured, the
    band holding the truth on 80 % of the span (25 % before); corrected for the noise on v (the default),
    0.435 sgn(v) - 1.12 v + 10.04 v^3, 70 % (its linear term 2.4 standard deviations of the estimator's scatter
    low on this draw of the noise: over 20 redraws about the same clean v, 0.08 +- 0.38)."""
    from _truth import damping_coverage  # tests/_truth.py

    system = g.systems.bistable_joint("position_independent")
    recs = g.systems.make_recordings(system, np.deg2rad(5.0), snr_db=30.0, seed=4)
    x = np.linspace(*system.x_range[0], 41)[:, None]
    v = np.geomspace(1e-4, 10.0, 60)[None, :]
    for eiv, b3_tol, cover in ((False, 0.05, 0.7), (True, 0.01, 0.65)):  # measured 9.90 / 80 %, 10.04 / 70 %
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sol = g.reconstruct(recs, g.Library(*system.orders["gmr"]), throw=False, velocity_eiv=eiv)
        assert sol.stats["dofs"][0].stats["coordination"] == "gls + joint damping"
        assert all((r is not None and r["applied"]) == eiv for r in sol.stats["dofs"][0].stats["velocity_noise"])
        b = np.asarray(sol.value.velocity_damping)[0]
        c = np.asarray(sol.value.position_damping)[0]
        power = np.polynomial.polynomial.polyval(x, c) * v**2 + sum(b[j] * v ** (j + 1) for j in range(b.size))
        assert np.all(power >= 0.0), b  # D v >= 0 at every speed
        assert abs(b[3] / 10.0 - 1.0) < b3_tol, b
        assert damping_coverage(sol.value, system) >= cover


def test_truncation_at_the_cap_estimates_the_series_tail():
    """`_joint._truncation`: at the degree cap, the best laws of degrees K, K - 2, K - 4 (a series whose
    terms shrink by r per two degrees) give the convergence ratio and the geometric tail, spread over T_K and
    T_(K-1) on the span so that the band never pinches; below the cap, at a cap that is a choice
    (`JointSettings.truncation` False), nothing."""
    from gmr_jax._coordination import _joint

    layout = _joint._Layout(5, 0, ())
    lo, hi = -1.0, 1.0
    r = 0.3
    series = np.zeros(layout.p)
    laws = []
    for m, power in enumerate((1, 3, 5)):  # partial sums x, + r x^3, + r^2 x^5
        series[power] = r**m
        laws.append(series.copy())
    meta = [(1, 0, ()), (3, 0, ()), (5, 0, ())]
    theta, bic, lin = np.array(laws), np.array([30.0, 20.0, 0.0]), np.eye(layout.p)
    settings = JointSettings(max_degree=5, max_damping_degree=0, velocity_orders=())
    cov, ratio, tail = _joint._truncation(meta, theta, bic, lin, layout, (5, 0, ()), (lo, hi), settings)
    x = np.linspace(lo, hi, 401)
    rms = lambda f: np.sqrt(np.mean(f**2))
    expected_ratio = rms(r**2 * x**5) / rms(r * x**3)
    assert ratio == pytest.approx(expected_ratio, rel=3e-2)  # RMS on 201 points against 401
    assert tail == pytest.approx(expected_ratio / (1 - expected_ratio) * rms(r**2 * x**5), rel=3e-2)
    phi = np.polynomial.polynomial.polyvander(x, layout.k)
    sd = np.sqrt(np.einsum("ij,jk,ik->i", phi, cov[: layout.k + 1, : layout.k + 1], phi))
    assert rms(sd) == pytest.approx(tail, rel=0.15)  # the band's RMS over the span is about the tail
    assert sd.min() > 0.2 * tail  # T_K^2 + T_(K-1)^2 never vanishes: no pinch
    assert np.all(cov[layout.k + 1 :] == 0)  # the damping untouched
    # below the cap, or where the cap is a choice (`truncation=False`): nothing
    below = JointSettings(max_degree=7, max_damping_degree=0, velocity_orders=())
    assert _joint._truncation(meta, theta, bic, np.eye(8 + 1), _joint._Layout(7, 0, ()), (5, 0, ()), (lo, hi),
                              below)[2] == 0.0
    chosen_cap = JointSettings(max_degree=5, max_damping_degree=0, velocity_orders=(), truncation=False)
    assert _joint._truncation(meta, theta, bic, lin, layout, (5, 0, ()), (lo, hi), chosen_cap)[2] == 0.0


@pytest.mark.slow  # two reconstructions of a coverage-study case (~40 s)
def test_the_band_holds_the_truncation_at_the_degree_cap():
    """Magnetic bistable, 0.05 sweeps, 60 dB, seed 0 (`studies/coverage.py`): the joint law takes degree 13, the
    cap, at the smallest penalty (the data ask for more terms); it is 0.13 % off on the span. Without the
    truncation term its band was 0.09 % wide and held the truth on 85 % of the span; with the series' tail
    (the best laws of degrees 9, 11, 13, convergence ratio 0.18) on >= 90 % (measured 100 %, 0.24 % wide), with and
    without the velocity correction."""
    system = g.systems.magnetic_bistable()
    recs = g.systems.make_recordings(system, 0.05, snr_db=60.0, seed=0)
    eq = system.equilibria[:, 0]
    xs = np.linspace(eq.min(), eq.max(), 201)
    truth = np.array([float(system.truth.restoring(jnp.asarray([x]))[0]) for x in xs])
    cover = {}
    for eiv in (True, False):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sol = g.reconstruct(recs, g.Library(*system.orders["gmr"]), throw=False, velocity_eiv=eiv)
        st = sol.stats["dofs"][0].stats
        assert st["coordination"] == "joint" and st["joint_degree"] == 13
        assert st["joint_truncation_tail"] > 0
        band = [g.force_band(sol.value, jnp.asarray([x]), level=0.95) for x in xs]
        cover[eiv] = np.mean([float(b.lower[0]) <= t <= float(b.upper[0]) for b, t in zip(band, truth)])
    assert cover[True] >= 0.9 and cover[False] >= 0.9, cover  # measured 100 %


def test_velocity_noise_correction_unbiases_a_cubic_damping():
    """`_joint._velocity_noise` / `_velocity_gram`: a force 10 v^3 regressed on a noisy v (white, 10 % of
    its RMS) is attenuated and leaks into v (E[(v + e)^3] = v^3 + 3 s^2 v); the corrected columns and
    normal equations give back 10 within the scatter (mean over draws), with and without a row low-pass."""
    from gmr_jax._coordination._joint import RowFilter, _Layout, _velocity_gram, _velocity_noise, row_filter

    rng = np.random.default_rng(0)
    n = 4000
    t = np.arange(n) / 200.0
    v = (np.sin(2 * np.pi * 1.1 * t) + 0.5 * np.sin(2 * np.pi * 2.3 * t + 1.0))[None, :]  # one well
    u = 0.2 * np.cos(2 * np.pi * 1.1 * t)[None, :]
    y = 10.0 * v**3
    layout = _Layout(1, 0, (1, 3))  # columns T0, T1(u), v T0 (C(0)), v, v^3: v twice, so use the C(0) one
    keep = np.array([0, 1, 2, 4])
    s2 = (0.1 * np.std(v)) ** 2
    w = np.ones((1, n))
    for rows in (None, row_filter(1 / 200.0, 8.0)):
        plain, fixed = [], []
        for _ in range(30):
            vn = v + np.sqrt(s2) * rng.standard_normal(v.shape)
            cols = np.asarray(layout.columns(jnp.asarray(u), jnp.asarray(vn)))
            cols_c, vd = _velocity_noise(cols, u, vn, np.array([s2]), layout)
            for c, out in ((cols, plain), (cols_c, fixed)):
                cc, yy, ww = c, y, w
                if rows is not None:
                    from gmr_jax._coordination._joint import filtered_rows

                    cc, yy, ww, _ = filtered_rows(rows, c, y, w, w)
                scale = np.ones(layout.p)
                gram = np.einsum("wn,wnp,wnq->pq", ww, cc, cc)
                rhs = np.einsum("wn,wnp,wn->p", ww, cc, yy)
                if out is fixed:
                    gram = _velocity_gram(gram, vd, np.array([s2]), ww, rows, scale)[0]
                out.append(np.linalg.solve(gram[np.ix_(keep, keep)], rhs[keep])[-1])
        plain, fixed = np.array(plain), np.array(fixed)
        se = fixed.std(ddof=1) / np.sqrt(fixed.size)
        assert abs(fixed.mean() - 10.0) < 4 * se + 1e-3, (rows is None, fixed.mean(), se)
        assert plain.mean() < 10.0 - 6 * se  # uncorrected: attenuated (the test has teeth)
    assert isinstance(row_filter(1 / 200.0, 8.0), RowFilter)


def test_velocity_noise_sandwich_matches_the_scatter():
    """`_joint._sandwich`: with the columns corrected for the noise of v, the residual holds 30 v^2 e, largest
    where |v| is (and v^3 has its leverage), so sigma^2 A^-1 understates the v^3 coefficient's variance; the
    corrected score's sandwich gives the scatter over draws (within its sampling error), the plain form not."""
    from gmr_jax._coordination._joint import _Layout, _sandwich, _velocity_gram, _velocity_noise

    rng = np.random.default_rng(3)
    n = 6000
    t = np.arange(n) / 200.0
    ph = 2 * np.pi * np.cumsum(0.5 + 2.0 * t / t[-1]) / 200.0
    v = ((1.0 + 2.0 * np.exp(-(((0.5 + 2.0 * t / t[-1]) - 1.3) / 0.2) ** 2)) * np.sin(ph))[None, :]
    u = 0.2 * np.cos(ph)[None, :]
    layout = _Layout(1, 0, (3,))  # T0, T1(u), C(0) v, v^3
    s2 = (0.1 * np.std(v)) ** 2
    w = np.ones((1, n))
    est, se_sw, se_plain = [], [], []
    for _ in range(40):
        vn = v + np.sqrt(s2) * rng.standard_normal(v.shape)
        y = 10.0 * v**3 + 0.5 * rng.standard_normal(v.shape)
        cols = np.asarray(layout.columns(jnp.asarray(u), jnp.asarray(vn)))
        cols, vd = _velocity_noise(cols, u, vn, np.array([s2]), layout)
        scale = np.ones(layout.p)
        gram = np.einsum("wn,wnp,wnq->pq", w, cols, cols)
        gram, noise = _velocity_gram(gram, vd, np.array([s2]), w, None, scale)
        ainv = np.linalg.inv(gram)
        theta = ainv @ np.einsum("wn,wnp,wn->p", w, cols, y)
        sigma2 = float(np.sum((y - cols @ theta) ** 2) / (n - layout.p))
        cov = _sandwich(cols, y, w, theta, ainv, np.ones(layout.p, bool), gram, noise, sigma2)
        est.append(theta[-1]), se_sw.append(np.sqrt(cov[-1, -1])), se_plain.append(np.sqrt(sigma2 * ainv[-1, -1]))
    scatter = np.std(est, ddof=1)  # its own sampling error: about 11 % over 40 draws
    assert abs(np.mean(se_sw) / scatter - 1.0) < 0.3, (np.mean(se_sw), scatter)
    assert np.mean(se_plain) / scatter < 0.75, (np.mean(se_plain), scatter)  # the plain form: too narrow
    assert abs(np.mean(est) - 10.0) < 4 * scatter / np.sqrt(len(est))


@pytest.mark.slow  # one reconstruction to capture the regression's inputs, then 40 x 2 joint regressions (~20 s)
def test_a_velocity_term_is_kept_on_its_robust_covariance(monkeypatch):
    """`_joint._robust_velocity_set`: with the columns corrected for the noise of v, the score judges a velocity
    term on sigma^2 A^-1, several times too narrow where the residual grows with |v|, and keeps a v|v| beside the
    truth's v^3 in a quarter of the draws (10 of 40 on the full candidate set), pulling the viscous term negative; re-tested on the sandwich it is
    dropped, and the viscous term is unbiased (bistable joint, 10 v^3, 5 degrees, 30 dB on v, seed 4's sweeps with
    fresh draws of v's noise); the laws that hold it are no longer alternatives (rule 14 read them as better by 1-40
    in the score)."""
    import gmr_jax._reconstruct._reconstruct as recon
    from gmr_jax._coordination import _joint

    s = g.systems.bistable_joint("position_independent")
    recs = g.systems.make_recordings(s, np.deg2rad(5.0), snr_db=30.0, seed=4)
    clean = g.systems.make_recordings(s, np.deg2rad(5.0), snr_db=None, seed=4)
    noisy = [g.Recording(t=c.t, x=c.x, v=r.v, a=c.a, base_acc=c.base_acc, masses=c.masses, name=c.name)
             for r, c in zip(recs, clean)]
    captured = []

    def spy(*args, **kwargs):
        captured.append((args, kwargs))
        return _joint.joint_coordinate(*args, **kwargs)

    monkeypatch.setattr(recon, "joint_coordinate", spy)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        g.reconstruct(noisy, g.Library(*s.orders["gmr"]), throw=False, coordination="joint")
    (xs, vs, ys, weights, eq, var, speed, _), kwargs = captured[-1]
    v_clean = np.zeros_like(np.asarray(vs))
    for i, c in enumerate(clean):
        v_clean[i, : c.n_samples] = c.v[:, 0]
    sd = np.array([np.std((np.asarray(vs) - v_clean)[i][np.asarray(weights)[i] > 0]) for i in range(len(clean))])
    settings = _joint.JointSettings(max_degree=3, max_damping_degree=0, velocity_orders=(2, 3))
    rng = np.random.default_rng(777)
    kept, dropped, linear = 0, 0, []
    for _ in range(40):
        v = (v_clean + sd[:, None] * rng.standard_normal(v_clean.shape)) * (np.asarray(weights) > 0)
        _, vdamp, _, _, stats = _joint.joint_coordinate(xs, v, ys, weights, eq, var, speed, settings,
                                                        v_noise=kwargs["v_noise"])
        assert stats["joint_velocity_noise"]
        kept += 2 in stats["joint_velocity_orders"]
        if stats["joint_velocity_orders_dropped"]:  # the rejected term is out of the alternatives too
            dropped += 1
            assert 2 not in (stats["joint_damping_alternative_orders"] or []), stats
            assert stats["joint_damping_alternative_delta"] > 0, stats
        linear.append(float(vdamp[1]))
    mean, se = np.mean(linear), np.std(linear, ddof=1) / np.sqrt(40)
    assert kept <= 1 and abs(mean) < 3 * se, (kept, mean, se)
    assert dropped >= 5, dropped  # the score kept v|v| in these draws; the robust test took it out


@pytest.mark.slow  # two reconstructions of a velocity_noise-study case (~20 s)
def test_the_noise_of_a_measured_v_hands_the_damping_to_the_joint_regression(monkeypatch):
    """`_reconstruct._velocity_noise.V_NOISE_DAMPING`: bistable joint, 10 v^3, 5 degree sweeps, 30 dB, seed 1 (`studies/
    velocity_noise.py`): the paper route's damping is admissible, so it was kept, from local fits that take the
    noisy v as exact (v^3 attenuated, its share leaked into v); its band held the truth on 64 % of the span x
    v_range. The noise moves the joint damping law by more than a standard error, so the corrected joint damping
    replaces it, and says so: 100 %."""
    from _truth import damping_coverage  # tests/_truth.py

    import gmr_jax._reconstruct._velocity_noise as recon

    system = g.systems.bistable_joint("position_independent")
    recs = g.systems.make_recordings(system, np.deg2rad(5.0), snr_db=30.0, seed=1)
    out, default = {}, recon.V_NOISE_DAMPING
    for gate in (default, 0.0):
        monkeypatch.setattr(recon, "V_NOISE_DAMPING", gate)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sol = g.reconstruct(recs, g.Library(*system.orders["gmr"]), throw=False)
        st = sol.stats["dofs"][0].stats
        note = [w for w in st["paper_route_rejected"] if "noise of the measured v" in w]
        out[gate] = (st["coordination"], len(note), damping_coverage(sol.value, system))
    assert out[default][:2] == ("gls + joint damping", 1) and out[default][2] >= 0.9, out
    assert out[0.0][:2] == ("gls", 0) and out[0.0][2] < 0.9, out  # measured 64 %


def test_rule_14d_compares_the_damping_law_across_derivative_windows(monkeypatch):
    """Rule 14d's logic on stand-in fits: a refit whose velocity terms differ is warned with both laws; the same
    terms, a viscous-only choice or a refit inside the check (no recursion) are not."""
    import gmr_jax._reconstruct._window_check as wc

    def model(b):
        return g.GlobalModel(masses=np.ones(1), stiffness=np.array([[0.0, -1.0, 0.0, 1.0]]),
                             velocity_damping=np.array([b]), position_damping=np.zeros((1, 1)))

    t = np.arange(1000) * 0.01
    rec = g.Recording(t=t, x=0.1 * np.sin(t) + 1.0, base_acc=np.sin(t))
    cube, drag = model([0.0, 0.19, 0.0, 0.062]), model([0.0, 0.18, 0.048])
    fit = lambda recs: g.Solution(value=drag, result=g.RESULTS.successful, stats={})  # noqa: E731
    msgs, stats = wc.check(fit, [rec], cube, g.Independent(), False)
    assert len(msgs) == 1 and "0.19 v + 0.062 v^3" in msgs[0] and "0.18 v + 0.048 sgn(v)|v|^2" in msgs[0]
    assert stats[0]["same_terms"] is False
    same = lambda recs: g.Solution(value=model([0.0, 0.2, 0.0, 0.05]), result=g.RESULTS.successful, stats={})  # noqa: E731
    assert wc.check(same, [rec], cube, g.Independent(), False)[0] == []
    assert wc.check(fit, [rec], model([0.0, 0.2]), g.Independent(), False) == ([], {})  # viscous only: not run
    measured = g.Recording(t=t, x=rec.x, v=np.cos(t), a=np.zeros_like(t), base_acc=rec.base_acc)
    assert wc.check(fit, [measured], cube, g.Independent(), False) == ([], {})  # v measured: not run
    monkeypatch.setattr(wc, "_ACTIVE", __import__("contextvars").ContextVar("t", default=True))
    assert wc.check(fit, [rec], cube, g.Independent(), False) == ([], {})  # inside a check's refit


@pytest.mark.slow  # two reconstructions of single-tone records (~60 s cold)
def test_rule_14d_warns_where_the_derivative_window_decides_the_law():
    """The study case (studies/single_tone_budget.py): x only, 60 dB, 2.5x the base amplitude, seed 0: the default
    chooses v^3 for the truth's v|v| with no rule-14 warning; rule 14d names both laws. At 2x the law is the same
    at both windows, and nothing is said."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "studies"))
    import single_tone_budget as sb

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = g.reconstruct(sb.tone_recordings("x", 60, 0, 2.5), throw=False)
        calm = g.reconstruct(sb.tone_recordings("x", 60, 0, 2.0), throw=False)
    msgs = [m for m in sol.stats["warnings"] if "rests on how x was differentiated" in m]
    assert len(msgs) == 1 and "v^3" in msgs[0] and "sgn(v)|v|^2" in msgs[0], sol.stats["warnings"]
    assert sol.stats["dofs"][0].stats["window_check"]["same_terms"] is False
    assert not any("rests on how x was differentiated" in m for m in calm.stats["warnings"])
    assert calm.stats["dofs"][0].stats["window_check"]["same_terms"] is True
