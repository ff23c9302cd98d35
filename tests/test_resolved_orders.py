"""Issue 15, Kresling accuracy targets: what the local data resolve decides the local restoring
order (`_extend_restoring`) and the global degree is always a confining (odd) one (`hermite_gls`)."""

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _truth import restoring_l2  # tests/_truth.py

import gmr_jax as g
from gmr_jax._fit._library import STIFFNESS
from gmr_jax._reconstruct._degree import average, least_risk_degree, span_curve
from gmr_jax._reconstruct._local_rules import (
    _extend_restoring,
    _fit_wells,
    _screen,
    low_order_terms,
)
from gmr_jax._reconstruct._reconstruct import _calibrated, _Failure
from gmr_jax._reconstruct._shape_prior import refit_with_prior


def _wells(a4, n=4000, amp=0.08, noise=1e-4, seed=0):
    """Two wells of a local law a1 q + a2 q^2 + a3 q^3 + a4 q^4 + 0.2 v, multi-tone q."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 400.0
    xs, vs, ys = [], [], []
    for x0, sign in ((-1.0, 1.0), (1.0, -1.0)):
        q = sum(amp / 3 * np.sin(2 * np.pi * f * t + rng.uniform(0, 6.3)) for f in (1.1, 2.9, 6.7))
        v = np.gradient(q, t)
        y = 2.0 * q + sign * 1.5 * q**2 + 1.0 * q**3 + sign * a4 * q**4 + 0.2 * v
        xs.append(x0 + q), vs.append(v), ys.append(y + noise * rng.standard_normal(n))
    return (jnp.asarray(np.array(a)) for a in (xs, vs, ys, np.ones((2, n))))


def _fits(xs, vs, ys, w, lib):
    # a threshold far above every term: the support is what `keep` exempts (q^0..q^3, v, x v)
    solver = g.STLS(threshold=1e6, alpha=0.0, normalize_columns=True, unbias=True)
    keep = jnp.asarray(low_order_terms(lib, 3))
    return _fit_wells(xs, vs, ys, w, lib, solver, None, keep).value, solver


def test_a_resolved_term_left_out_by_the_threshold_is_added_and_unbiases_the_lower_ones():
    lib = g.Library(5, 1)
    xs, vs, ys, w = _wells(a4=40.0)
    fits, solver = _fits(xs, vs, ys, w, lib)
    i2, i4 = lib.terms().index((STIFFNESS, 2)), lib.terms().index((STIFFNESS, 4))
    a2 = np.array([1.5, -1.5])
    se2 = np.sqrt(np.asarray(fits.covariance)[:, i2, i2])
    assert np.all(np.asarray(fits.coef)[:, i4] == 0)
    # q^4 left out: q^2 is off by many standard errors (q^4 and q^2 are correlated about a well)
    biased = np.abs(np.asarray(fits.coef)[:, i2] - a2) / se2
    new, added = _extend_restoring(fits, xs, vs, ys, w, lib, solver, 3.0, 0, _Failure("test", True))
    assert added == [[4], [4]]  # q^5 (absent from the truth) is not added
    coef = np.asarray(new.coef)
    se2 = np.sqrt(np.asarray(new.covariance)[:, i2, i2])
    assert np.all(np.abs(coef[:, i2] - a2) < 4 * se2), (coef[:, i2], se2)
    assert np.all(np.abs(coef[:, i4] - np.array([40.0, -40.0])) < 0.05 * 40.0)
    assert np.max(biased) > 10, biased


def test_nothing_is_added_where_the_next_term_is_not_resolved():
    lib = g.Library(5, 1)
    xs, vs, ys, w = _wells(a4=0.0, seed=1)
    fits, solver = _fits(xs, vs, ys, w, lib)
    new, added = _extend_restoring(fits, xs, vs, ys, w, lib, solver, 3.0, 0, _Failure("test", True))
    assert added == [[], []]
    np.testing.assert_array_equal(np.asarray(new.coef), np.asarray(fits.coef))


def _mean_centred_wells(n=4000, amp=0.08, noise=2e-3, seed=2):
    """Two wells as a recording gives them: q = x - mean(x), so the local law carries the force at
    the mean, a_0 = -a_2 mean(q^2) (the force has zero mean), which no fit without q^2 resolves."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 400.0
    xs, vs, ys = [], [], []
    for x0, sign in ((-1.0, 1.0), (1.0, -1.0)):
        q = sum(amp / 3 * np.sin(2 * np.pi * f * t + rng.uniform(0, 6.3)) for f in (1.1, 2.9, 6.7))
        q = q - q.mean()
        v = np.gradient(q, t)
        y = 2.0 * q + sign * 1.5 * (q**2 - np.mean(q**2)) + 0.2 * v
        xs.append(x0 + q), vs.append(v), ys.append(y + noise * rng.standard_normal(n))
    return (jnp.asarray(np.array(a)) for a in (xs, vs, ys, np.ones((2, n))))


def test_a_curvature_added_to_a_local_fit_brings_back_the_force_at_the_mean():
    """The screen drops q^0 from a fit that stops at q^1 (the force at the mean is 0 to first
    order); q^2 refitted without it is biased by a third to two thirds of itself, with it not."""
    lib = g.Library(3, 1)
    xs, vs, ys, w = _mean_centred_wells()
    solver = g.STLS(threshold=1e6, alpha=0.0, normalize_columns=True, unbias=True)
    fits = _screen(_fit_wells(xs, vs, ys, w, lib, solver, None, jnp.asarray(low_order_terms(lib, 1))).value, 3.0)
    i0, i2 = lib.terms().index((STIFFNESS, 0)), lib.terms().index((STIFFNESS, 2))
    assert np.all(np.asarray(fits.coef)[:, i0] == 0)  # screened: the sample mean of the force is ~0
    new, added = _extend_restoring(fits, xs, vs, ys, w, lib, solver, 3.0, 0, _Failure("test", True))
    assert added == [[2], [2]]
    coef, cov = np.asarray(new.coef), np.asarray(new.covariance)
    a2 = np.array([1.5, -1.5])
    se2 = np.sqrt(cov[:, i2, i2])
    assert np.all(np.abs(coef[:, i2] - a2) < 4 * se2), (coef[:, i2], se2)
    # independent: least squares on the same columns without the constant is far off
    for k in range(2):
        q = np.asarray(xs[k]) - np.mean(np.asarray(xs[k]))
        cols = np.column_stack([q, q**2, np.asarray(vs[k]), q * np.asarray(vs[k])])
        b = np.linalg.lstsq(cols, np.asarray(ys[k]), rcond=None)[0][1]
        assert abs(b - a2[k]) > 10 * se2[k] and abs(b - a2[k]) > 0.2 * abs(a2[k]), (b, se2[k])


def test_a_borrowed_curvature_is_refitted_with_the_force_at_the_mean():
    lib = g.Library(3, 1)  # 1, x, x^2, x^3, sgn v, v, x v
    xs, vs, ys, _ = _mean_centred_wells(seed=3)
    q, v, y = (np.asarray(a[0]) for a in (xs, vs, ys))
    q = q - q.mean()
    theta = np.asarray(lib(q, v))
    own = np.array([False, True, False, False, False, True, False])  # q^0 screened, stops at q^1
    c_own = np.zeros(lib.n_terms)
    c_own[own] = np.linalg.lstsq(theta[:, own], y, rcond=None)[0]
    rss = float(np.sum((y - theta @ c_own) ** 2))
    span = 2.0
    rho = 1.5 * span / 2.0  # the truth's a_2 L / a_1
    coef, _ = refit_with_prior(q, v, y, np.ones_like(q), lib, c_own, rss, q.size, span, {2: (rho, 1e8)})
    # a vague prior: the least-squares fit on 1, q, q^2, v (the constant brought back)
    cols = np.array([0, 1, 2, 5])
    np.testing.assert_allclose(coef[cols], np.linalg.lstsq(theta[:, cols], y, rcond=None)[0], rtol=1e-6)
    assert coef[2] == pytest.approx(1.5, rel=0.05)


def _taylor(coef, x0, order):
    p = np.polynomial.Polynomial(coef)
    out, fact = [], 1.0
    for j in range(order + 1):
        out.append(p(x0) / fact)
        p = p.deriv()
        fact *= j + 1
    return out


def test_confining_gls_never_chooses_an_even_degree():
    # a term resolved at one well only (local orders 2 and 3): the exact interpolant has even degree
    # 6 and cannot confine; the GLS takes the highest odd degree below it, fitted to all conditions
    truth = [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.3]  # -x + x^3 + 0.3 x^7: no quintic fits it
    nodes = jnp.asarray([-1.0, 1.0])
    taylor = jnp.asarray([_taylor(truth, x0, 3) for x0 in (-1.0, 1.0)])
    order = jnp.asarray([2, 3])
    cov = jnp.broadcast_to(1e-10 * jnp.eye(4), (2, 4, 4))
    coef, degree, _, stats = g.hermite_gls(nodes, taylor, order, cov, confining=True)
    assert int(stats["K_hermite"]) == 6 and int(degree) == 5
    coef = np.trim_zeros(np.asarray(coef), "b")
    assert coef.size == 6 and coef[-1] > 0  # confining quintic
    # where an odd K' passes the test it is still the smallest one; where K is odd and nothing
    # below passes, the exact interpolant (paper, Eq. 18)
    _, degree, _, _ = g.hermite_gls(nodes, taylor, jnp.asarray([3, 3]), cov, confining=True)
    assert int(degree) == 7
    loose = jnp.broadcast_to(jnp.diag(jnp.asarray([1e-10, 1e-10, 1e-10, 1e6])), (2, 4, 4))
    _, degree, _, _ = g.hermite_gls(nodes, taylor, jnp.asarray([3, 3]), loose, confining=True)
    assert int(degree) in (3, 5)
    # a damping polynomial C(x) need not confine: there an even degree stays possible
    _, degree, _, _ = g.hermite_gls(nodes, taylor, order, cov)
    assert int(degree) == 6


def test_gls_max_degree_gives_the_least_squares_law_of_that_degree():
    # the conditions pin a nonic whose leading term is negative (it turns outward beyond the data:
    # torque-free Kresling cells that borrowed q^4, q^5 got such nonics, 0.3-0.43 spans below the
    # folded well); `reconstruct` then bounds the degree (`_degree.confine_borrowed`): the septic, fitted to
    # all the conditions by least squares
    truth = [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 2.0, 0.0, -0.2]
    nodes = jnp.asarray([-1.0, 1.0])
    taylor = jnp.asarray([_taylor(truth, x0, 5) for x0 in (-1.0, 1.0)])
    order = jnp.asarray([4, 5])
    cov = jnp.broadcast_to(1e-10 * jnp.eye(6), (2, 6, 6))
    free, degree, _, _ = g.hermite_gls(nodes, taylor, order, cov, confining=True)
    free = np.trim_zeros(np.asarray(free), "b")
    assert int(degree) == 9 and free[-1] < 0
    np.testing.assert_allclose(free, truth, atol=1e-6)
    coef, degree, _, _ = g.hermite_gls(nodes, taylor, order, cov, confining=True, max_degree=jnp.asarray(8))
    coef = np.asarray(coef)
    assert int(degree) == 7 and coef[7] > 0 and np.all(coef[8:] == 0)
    # the same septic by NumPy: least squares on the 11 Taylor conditions (equal weights)
    rows, rhs = [], []
    for x0, r in ((-1.0, 4), (1.0, 5)):
        for j in range(r + 1):
            rows.append([math.comb(k, j) * x0 ** (k - j) if k >= j else 0.0 for k in range(8)])
            rhs.append(_taylor(truth, x0, r)[j])
    ref = np.linalg.lstsq(np.asarray(rows), np.asarray(rhs), rcond=None)[0]
    np.testing.assert_allclose(coef[:8], ref, rtol=1e-7, atol=1e-9)
    x = np.array([-50.0, 50.0])
    assert np.polynomial.polynomial.polyval(x[1], coef) > 0 > np.polynomial.polynomial.polyval(x[0], coef)


def _noisy_high_orders(c, rel4, z, lib):
    """Two wells (+-1) of the double well F = x (x^2 - 1)(1 + 0.3 x^2 + 0.1 x^4 + c x^6) (degree 9),
    conditions q^0..q^4 at each: q^0..q^3 precise (1e-4 of F'), q^4 with relative standard
    deviation `rel4` (a borrowed order: the donors' error), perturbed by z standard deviations."""
    truth = (np.polynomial.Polynomial([0, -1, 0, 1]) * np.polynomial.Polynomial([1, 0, 0.3, 0, 0.1, 0, c])).coef
    names = lib.terms()
    eq = np.array([-1.0, 1.0])
    coef, cov = np.zeros((2, lib.n_terms)), np.zeros((2, lib.n_terms, lib.n_terms))
    for w, x0 in enumerate(eq):
        t = _taylor(truth, x0, 4)
        for k in range(5):
            i = names.index((STIFFNESS, k))
            sd = rel4 * abs(t[4]) if k == 4 else 1e-4 * abs(t[1])
            coef[w, i], cov[w, i, i] = t[k] + z[w, k] * sd, sd**2
        i = names.index(("velocity_damping", 1))
        coef[w, i], cov[w, i, i] = 0.1, 1e-6
    fits = g.LocalFit(equilibrium=jnp.asarray(eq), coef=jnp.asarray(coef), covariance=jnp.asarray(cov),
                      threshold=jnp.zeros(2), rss=jnp.ones(2), n_samples=jnp.full(2, 100.0))
    return fits, truth


@pytest.mark.slow  # 9-12 s: the default tier's 5 min (stop 51); CI runs the slow tier too
def test_least_risk_estimate_of_a_lower_degree_is_unbiased():
    # `least_risk_degree` rests on: the degree-7 GLS law is the projection of the exact nonic, so
    # (F_7 - F_9)^2 - var F_9 + 2 var F_7 estimates E (F_7 - F)^2 without bias. Monte Carlo over the
    # conditions' noise (200 draws): the mean estimate equals the mean actual squared error
    lib = g.Library(5, 1)
    x = np.linspace(-1.1, 1.1, 221)
    rng = np.random.default_rng(2)
    est, act = [], []
    for _ in range(200):
        fits, truth = _noisy_high_orders(0.05, 0.02, rng.standard_normal((2, 5)), lib)
        top = g.coordinate(fits, lib, method="gls", confining=True)
        low = g.coordinate(fits, lib, method="gls", confining=True, max_degree=jnp.asarray(7))
        assert int(top.stats["K_r"]) == 9 and int(low.stats["K_r"]) == 7
        f_top, v_top = span_curve(top, x)
        f_low, v_low = span_curve(low, x)
        est.append(np.mean((f_low - f_top) ** 2 - v_top + 2 * v_low))
        act.append(np.mean((f_low - np.polynomial.polynomial.polyval(x, truth)) ** 2))
    diff = np.asarray(est) - np.asarray(act)
    assert abs(np.mean(diff)) < 3.5 * np.std(diff) / np.sqrt(diff.size), (np.mean(est), np.mean(act))
    assert np.mean(act) > 10 * np.std(diff) / np.sqrt(diff.size)  # the bias is there to be estimated


def test_least_risk_degree_lowers_only_where_the_high_orders_are_uncertain():
    lib = g.Library(5, 1)
    x = np.linspace(-1.1, 1.1, 221)
    z = np.zeros((2, 5))
    z[:, 4] = (2.0, -2.0)
    # q^4 borrowed 10 % uncertain, 2 sd off at each well: the chi-squared test rejects the septic
    # (p ~ 0.02) and takes the exact nonic, which follows the error; the septic does not
    fits, truth = _noisy_high_orders(0.005, 0.1, z, lib)
    top = g.coordinate(fits, lib, method="gls", confining=True)
    low = g.coordinate(fits, lib, method="gls", confining=True, max_degree=jnp.asarray(7))
    assert int(top.stats["K_r"]) == 9 and float(low.stats["p_r"]) < 0.05
    best, notes = least_risk_degree(top, fits, lib, 10.0)
    assert int(best.stats["K_r"]) == 7 and int(best.stats["max_degree_r"]) == 7 and "degree 7 instead of 9" in notes[0]
    f = np.polynomial.polynomial.polyval(x, truth)
    err = [np.sqrt(np.mean((span_curve(s, x)[0] - f) ** 2)) for s in (top, best)]
    assert err[1] < 0.2 * err[0], err
    # every condition precise: the nonic is kept
    fits, truth = _noisy_high_orders(0.05, 1e-4, np.zeros((2, 5)), lib)
    top = g.coordinate(fits, lib, method="gls", confining=True)
    best, notes = least_risk_degree(top, fits, lib, 10.0)
    assert best is top and notes == []


def test_the_average_of_two_nested_laws_has_the_mixture_covariance():
    # `average` takes cov(F_7, F_9) = var F_7 (nested GLS laws: the septic is the projection of the
    # exact nonic with the conditions' inverse covariance as weights). Checked exactly, from the two
    # laws' Jacobians in the local coefficients; then over the conditions' noise (300 draws): the
    # average is the linear combination and its scatter matches the mixture. (A Monte Carlo estimate
    # of the cross-covariance itself cannot check the identity here: the nonic is ~18x noisier than
    # the septic mid-span, so 300 draws estimate cov / var F_7 only to about +-1; at stop 35 such an
    # estimate, 0.42, was misread as the weights breaking the identity.)
    lib = g.Library(5, 1)
    x = np.linspace(-1.1, 1.1, 111)
    rng = np.random.default_rng(5)
    fits, _ = _noisy_high_orders(0.05, 0.05, rng.standard_normal((2, 5)), lib)
    low = g.coordinate(fits, lib, method="gls", confining=True, max_degree=jnp.asarray(7))
    assert int(low.stats["K_r"]) == 7
    basis = x[:, None] ** np.arange(low.value.stiffness.size)[None, :]

    def law(coef, **kw):
        f = g.LocalFit(fits.equilibrium, coef, fits.covariance, fits.threshold, fits.rss, fits.n_samples)
        return g.coordinate(f, lib, throw=False, **kw).value.stiffness

    j_top = jax.jacfwd(lambda c: law(c, method="hermite"))(fits.coef).reshape(basis.shape[1], -1)
    j_low = jax.jacfwd(lambda c: law(c, method="gls", confining=True, max_degree=jnp.asarray(7)))(fits.coef)
    j_low = j_low.reshape(basis.shape[1], -1)
    sigma = jax.scipy.linalg.block_diag(*fits.covariance)
    cross = np.einsum("ij,jk,ik->i", basis @ j_low, sigma, basis @ j_top)
    np.testing.assert_allclose(cross, span_curve(low, x)[1], rtol=1e-6)
    # a law that is not the GLS projection (unweighted least squares) breaks the identity: the check can fail
    vand = np.vstack([[[math.comb(j, k) * x0 ** (j - k) if j >= k else 0.0 for j in range(8)] for k in range(5)]
                      for x0 in (-1.0, 1.0)])
    picks = [i for w in range(2) for i in range(w * lib.n_terms, w * lib.n_terms + 5)]
    j_ols = np.zeros(j_low.shape)
    j_ols[:8, picks] = np.linalg.pinv(vand)
    off = np.einsum("ij,jk,ik->i", basis @ j_ols, sigma, basis @ j_top) / np.einsum("ij,jk,ik->i", basis @ j_ols,
                                                                                 sigma, basis @ j_ols)
    assert np.max(np.abs(off - 1)) > 0.1, off
    w, avgs = 0.9, []
    for _ in range(300):
        fits, _ = _noisy_high_orders(0.05, 0.05, rng.standard_normal((2, 5)), lib)
        top = jax.device_get(g.coordinate(fits, lib, method="hermite"))
        low = jax.device_get(g.coordinate(fits, lib, method="gls", confining=True, max_degree=jnp.asarray(7)))
        avg = average(top, low, w)
        (f, v), (f_t, v_t), (f_l, v_l) = span_curve(avg, x), span_curve(top, x), span_curve(low, x)
        np.testing.assert_allclose(f, (1 - w) * f_t + w * f_l, rtol=1e-9, atol=1e-12)
        predicted = v - w * (1 - w) * (f_l - f_t) ** 2  # the propagated part, without the spread between the laws
        np.testing.assert_allclose(predicted, (1 - w) ** 2 * v_t + (1 - (1 - w) ** 2) * v_l, rtol=1e-9)
        avgs.append(f)
    ratio = np.var(np.asarray(avgs), axis=0, ddof=1) / predicted
    assert 0.85 < np.median(ratio) < 1.15 and np.all((ratio > 0.7) & (ratio < 1.3)), ratio


def test_an_averaged_law_keeps_its_band_when_the_joint_regression_refits_the_damping():
    # "gls + joint damping" (the paper's restoring law, the damping refitted jointly): an averaged
    # restoring law keeps the calibrated mixture of its two laws as its block, the joint damping's block
    # stays as the regression gave it. (Before, the mixture was recalibrated as if it were the top law.)
    lib = g.Library(5, 1)
    rng = np.random.default_rng(0)
    for _ in range(20):
        fits, _ = _noisy_high_orders(0.05, 0.05, rng.standard_normal((2, 5)), lib)
        top = jax.device_get(g.coordinate(fits, lib, method="gls", confining=True))
        best, _ = least_risk_degree(top, fits, lib, 10.0)
        if "averaged_weight" in best.stats:
            break
    else:
        pytest.fail("no draw averaged two laws")
    ns = np.asarray(best.value.stiffness).shape[0]
    _, alone = _calibrated(best, fits, lib, "gls", True, confining=True)
    damping = np.diag([3.0, 5.0])  # a stand-in for the joint regression's damping block
    joint_aux = np.zeros((ns + 2, ns + 2))
    joint_aux[:ns, :ns], joint_aux[ns:, ns:] = np.asarray(best.aux)[:ns, :ns], damping
    value = g.GlobalCoefficients(best.value.stiffness, jnp.zeros(2), jnp.zeros(1))
    joint = g.Solution(value=value, result=best.result, stats=dict(best.stats), aux=jnp.asarray(joint_aux))
    _, cov = _calibrated(joint, fits, lib, "gls + joint damping", True, confining=True)
    np.testing.assert_allclose(cov[:ns, :ns], alone[:ns, :ns], rtol=1e-12)
    np.testing.assert_allclose(cov[ns:, ns:], damping)
    assert not np.allclose(alone[:ns, :ns], np.asarray(best.aux)[:ns, :ns])  # calibration changed the block


@pytest.mark.parametrize("c, rel4", [(0.05, 0.02), (0.02, 0.05)])
def test_averaging_two_laws_beats_picking_the_least_estimated_risk(c, rel4):
    # Where the C_p estimates of the nonic and the septic lie within their noise of each other
    # (torque-free Kresling, seed 4, cell 4: nonic 7.1 % off, septic 1.2 %, estimates 0.93 / 0.98 %),
    # picking the least decides by chance; the weighted average (Mallows model averaging) has the
    # lower risk. 40 draws of the conditions' noise: its mean squared error over the span is below
    # both the least-C_p pick's and the exact nonic's
    lib = g.Library(5, 1)
    x = np.linspace(-1.1, 1.1, 111)
    rng = np.random.default_rng(0)
    err = {"top": [], "cp": [], "avg": []}
    for _ in range(40):
        fits, truth = _noisy_high_orders(c, rel4, rng.standard_normal((2, 5)), lib)
        f = np.polynomial.polynomial.polyval(x, truth)
        top = g.coordinate(fits, lib, method="gls", confining=True)
        low = g.coordinate(fits, lib, method="gls", confining=True, max_degree=jnp.asarray(7))
        (f_t, v_t), (f_l, v_l) = span_curve(top, x), span_curve(low, x)
        pick = f_l if np.mean((f_l - f_t) ** 2 - v_t + 2 * v_l) < np.mean(v_t) else f_t
        best, _ = least_risk_degree(top, fits, lib, 10.0)
        for key, curve in (("top", f_t), ("cp", pick), ("avg", span_curve(best, x)[0])):
            err[key].append(np.mean((curve - f) ** 2))
    mse = {k: float(np.mean(v)) for k, v in err.items()}
    assert mse["avg"] < 0.9 * mse["cp"] and mse["avg"] < mse["top"], mse


def test_redundant_conditions_do_not_confirm_an_even_law():
    """Tri-stable NES (paper orders 3, 3), 30 dB, seed 0: F''' resolved at one well only (t = 3.3)
    gave an exact degree-9 problem whose GLS took degree 8 (F -> -inf on both sides, an extra pair of
    sign changes within the span), kept because one redundant condition "confirmed" its shape:
    6 % off. Redundancy confirms a law turning outward (the NES truth does), never an even degree."""
    s = g.systems.tristable_nes()
    recs = g.systems.make_recordings(s, 5e-4, snr_db=30.0, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = g.reconstruct(recs, g.Library(*s.orders["gmr"]))
    st = res.stats["dofs"][0].stats
    assert any("even degree 8" in w for w in st["paper_route_rejected"]), st["paper_route_rejected"]
    k = np.trim_zeros(np.asarray(res.value.stiffness[0]), "b")
    assert (k.size - 1) % 2 == 1
    # independent: relative L2 over the box by NumPy against the truth (was 5.99 %; now 1.34 %)
    err, model, truth = restoring_l2(s, k, 801)
    assert err < 0.02
    # no zero of F beyond the truth's five within the box
    assert np.sum(np.diff(np.sign(model)) != 0) == np.sum(np.diff(np.sign(truth)) != 0)


@pytest.mark.slow
def test_an_even_law_gives_way_to_the_joint_one_even_where_no_motion_reaches_its_escape():
    """Magnetic bistable, 30 dB, most excited well at 0.45 % of the interwell distance, seed 1:
    F'' resolved at one well only gives an exact quartic (F -> +inf on both sides) whose escape
    lies beyond the energy bound; kept, it was 72 % off over the box (the value-and-slope law 45 %).
    An even degree cannot confine, so it is never kept for want of a reachable escape."""
    s = g.systems.magnetic_bistable()
    recs = g.systems.make_recordings(s, 4.377e-4, snr_db=30.0, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = g.reconstruct(recs)
    st = res.stats["dofs"][0].stats
    assert any("even degree 4" in w for w in st["paper_route_rejected"]), st["paper_route_rejected"]
    assert st["coordination"] == "joint"
    k = np.trim_zeros(np.asarray(res.value.stiffness[0]), "b")
    assert (k.size - 1) % 2 == 1 and k[-1] > 0  # odd degree, F -> +inf as x -> +inf: confining
    # independent: the relative L2 error over the box, by NumPy against the truth
    xs = np.linspace(*s.x_range[0], 801)
    truth = np.array([float(s.truth.restoring(jnp.asarray([x]))[0]) for x in xs])
    err = np.linalg.norm(np.polynomial.polynomial.polyval(xs, k) - truth) / np.linalg.norm(truth)
    assert err < 0.5, err


def _kresling_1mm(seed, *settings, twist="linear"):
    """The 5-cell Kresling chain at 1 mm, 60 dB, `seed`: the system and, per keyword set in
    `settings`, the reconstruction (Library(5, 5)) and its per-cell restoring errors."""
    system = g.systems.kresling5(twist=twist, damping_ratio=g.systems.KRESLING5_DEPLOYMENT_DAMPING)
    recs = g.systems.make_recordings(system, 1e-3, snr_db=60, seed=seed)
    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for kw in settings:
            res = g.reconstruct(recs, g.Library(5, 5), **kw)
            out.append((res, [g.metrics.restoring_error(res.value, system.truth, c, system.x_range[c])
                              for c in range(5)]))
    return system, out


@pytest.mark.slow  # torque-free 5-cell training data and two reconstructions (~2 min)
def test_torque_free_kresling_every_cell_within_three_percent():
    # issue 15: with q^4 of the deployed wells kept where resolved, cells 1-3 reach the exact-
    # Taylor oracle (cell 3 was 4.25 %); cells 4-5 do not resolve F''' at these amplitudes and
    # borrow it from the others (cells of one design, `_shape_prior`): tip cell 33 % -> < 3 %
    _, ((res, errs), (_, alone_errs)) = _kresling_1mm(3, {}, {"shared_design": False}, twist="torque_free")
    assert max(errs) < 0.03, errs
    assert 4 in res.stats["dofs"][2].stats["restoring_orders_added"][1]
    assert all(3 in b for b in res.stats["dofs"][4].stats["shared_design"]["borrowed"])
    # cell 4: the nonic with the borrowed orders turned outward within the motions' energy; the septic
    # fitted to all the local conditions confines (7.1 % when the cell went on alone, stop 29)
    cell4 = res.stats["dofs"][3].stats
    assert cell4["shared_design"]["used"] and int(cell4["K_r"]) == 7 and errs[3] < 0.015, (cell4["K_r"], errs)
    assert any("turns outward" in w and "degree 7" in w for w in cell4["paper_route_rejected"])
    assert not any(w.startswith("DOF 3: the restoring force turns outward") for w in res.stats["warnings"])
    tip = alone_errs[4]
    assert tip > 0.25, tip  # per cell, the tip's quintic from F, F', F'' (the oracle's 33 %)


@pytest.mark.slow  # nominal 5-cell training data and two reconstructions (~1 min)
def test_nominal_kresling_one_well_term_gives_an_odd_quintic_not_the_exact_sextic():
    # issue 15: 1 mm seed 3, cell 4 resolves F''' at the deployed well only; per cell, the exact
    # sextic was 6.55 % off (and cannot confine), the GLS quintic is at the F, F', F'' oracle's 1.3 %
    # (its leading term is negative: it turns outward, but beyond the cell's energy bound);
    # with the cells' shared design every cell is within the 0.5 % target
    _, ((alone, alone_errs), (_, errs)) = _kresling_1mm(3, {"shared_design": False}, {})
    cell = alone.stats["dofs"][3]
    assert int(cell.stats["K_r"]) == 5 and cell.stats["coordination"] == "gls"
    err = alone_errs[3]
    assert err < 0.015, err
    assert max(errs) < 0.005, errs


@pytest.mark.slow  # torque-free 5-cell training data, one reconstruction (~1 min)
def test_torque_free_kresling_borrowed_nonic_gives_way_to_the_septic_of_lower_risk():
    # issue 15: 1 mm seed 1, cells 4-5 borrowed q^2..q^4; the exact nonics through the borrowed q^4
    # (3-4 % off the truth) were 3.83 / 2.70 % off; the septics, of lower estimated risk over the
    # span, 1.34 / 1.37 % (`least_risk_degree`; cell 3's nonic, 2.46 % off, is now averaged with its
    # septic: 1.32 %)
    _, ((res, errs),) = _kresling_1mm(1, {}, twist="torque_free")
    assert max(errs) < 0.03, errs
    for c in (3, 4):
        st = res.stats["dofs"][c].stats
        assert st["shared_design"]["used"] and int(st["K_r"]) == 7 and errs[c] < 0.02, (c, st["K_r"], errs)
        assert any("degree 7 instead of 9" in w for w in st["paper_route_rejected"])
