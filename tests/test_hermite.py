import math
from math import comb

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._coordination._hermite import hermite_interpolate


def taylor_at(coef, x0, r):
    coef = np.asarray(coef)
    return np.array([sum(coef[k] * comb(k, j) * x0 ** (k - j) for k in range(j, len(coef))) for j in range(r + 1)])


def test_recovers_polynomial_and_degree_eq18():
    rng = np.random.default_rng(1)
    truth = rng.normal(size=8)  # degree 7
    nodes = np.array([-0.9, 0.1, 1.2])
    r = 3
    taylor = np.stack([taylor_at(truth, x, r) for x in nodes])
    order = np.array([2, 3, 2])
    coef, degree, cond = hermite_interpolate(jnp.asarray(nodes), jnp.asarray(taylor), jnp.asarray(order))
    assert int(degree) == (3 - 1) + 2 + 3 + 2  # Eq. (18)
    # the interpolant reproduces every known Taylor coefficient
    for i, x in enumerate(nodes):
        got = taylor_at(np.asarray(coef), x, r)
        np.testing.assert_allclose(got[: order[i] + 1], taylor[i, : order[i] + 1], rtol=1e-9, atol=1e-9)
    assert np.all(np.asarray(coef)[int(degree) + 1:] == 0)
    # full orders give back the degree-7 truth exactly
    coef, degree, _ = hermite_interpolate(jnp.asarray(nodes[:2]), jnp.asarray(taylor[:2]), jnp.asarray([3, 3]))
    np.testing.assert_allclose(np.asarray(coef)[:8], truth, rtol=1e-8, atol=1e-9)


def test_known_zero_is_data_not_unknown():
    # F = x^3 - x: Taylor at +-1 is (0, 2, +-3); dropping the quadratic gives a cubic with F'(+-1) = 2
    nodes = jnp.array([-1.0, 1.0])
    taylor = jnp.array([[0.0, 2.0, 0.0], [0.0, 2.0, 0.0]])
    coef, degree, _ = hermite_interpolate(nodes, taylor, jnp.array([1, 1]))
    assert int(degree) == 3
    np.testing.assert_allclose(np.asarray(coef)[:4], [0, -1, 0, 1], atol=1e-12)


def test_jit_vmap_grad():
    nodes = jnp.array([-1.1, 1.1])
    taylor = jnp.array([[0.1, 4.4, -5.9, 1.7], [-0.1, 4.5, 5.9, 1.8]])
    order = jnp.array([2, 3])
    f = jax.jit(hermite_interpolate)
    c1 = f(nodes, taylor, order)[0]
    c2 = hermite_interpolate(nodes, taylor, order)[0]
    np.testing.assert_allclose(c1, c2, rtol=1e-12)
    batch = jax.vmap(hermite_interpolate, (None, 0, None))(nodes, jnp.stack([taylor, 2 * taylor]), order)[0]
    np.testing.assert_allclose(batch[1], 2 * c1, rtol=1e-10)

    def loss(nodes, taylor):
        coef = hermite_interpolate(nodes, taylor, order)[0]
        return jnp.sum(jnp.polyval(coef[::-1], jnp.linspace(-1.5, 1.5, 7)) ** 2)

    gn, gt = jax.grad(loss, argnums=(0, 1))(nodes, taylor)
    eps = 1e-6
    for idx in [(0,), (1,)]:
        e = jnp.zeros_like(nodes).at[idx].set(eps)
        fd = (loss(nodes + e, taylor) - loss(nodes - e, taylor)) / (2 * eps)
        assert abs(fd - gn[idx]) <= 1e-5 * abs(fd) + 1e-6
    for idx in [(0, 1), (1, 3)]:
        e = jnp.zeros_like(taylor).at[idx].set(eps)
        fd = (loss(nodes, taylor + e) - loss(nodes, taylor - e)) / (2 * eps)
        assert abs(fd - gt[idx]) <= 1e-5 * abs(fd) + 1e-6


def _fits(equilibria, coefs, lib):
    n, p = coefs.shape
    return g.LocalFit(equilibrium=jnp.asarray(equilibria), coef=jnp.asarray(coefs),
                      covariance=jnp.zeros((n, p, p)), threshold=jnp.zeros(n), rss=jnp.zeros(n),
                      n_samples=jnp.full(n, 100.0))


def test_coordinate_joint_and_eq21():
    lib = g.Library(3, 3)
    xe = np.sqrt(2244 / 1755)
    coefs = np.zeros((2, lib.n_terms))
    s_idx, v_idx, p_idx = (lib.indices(k) for k in ("stiffness", "velocity_damping", "position_damping"))
    for i, x in enumerate([-xe, xe]):
        coefs[i, s_idx[1]] = 4488.0
        coefs[i, v_idx[3]] = 10.0 + (0.2 if i else -0.2)  # Eq. (21): averaged
        coefs[i, v_idx[1]] = 50 * x**2  # damping polynomial 50 x^2 v: Taylor (50 x^2, 100 x)
        coefs[i, p_idx[0]] = 100 * x
    sol = g.coordinate(_fits([-xe, xe], coefs, lib), lib)
    gc = sol.value
    np.testing.assert_allclose(np.asarray(gc.stiffness)[:4], [0, -2244, 0, 1755], atol=1e-8)
    np.testing.assert_allclose(float(gc.velocity_damping[3]), 10.0, rtol=1e-12)
    np.testing.assert_allclose(float(gc.velocity_damping[1]), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.asarray(gc.position_damping)[:4], [0, 0, 50, 0], atol=1e-9)
    # the paper's K_d = 3 (Eq. 20) is the exact interpolant; the GLS takes the lowest degree the local data
    # accept, here the true quadratic (the damping polynomial's test starts at degree 0)
    assert int(sol.stats["K_r"]) == 3 and int(sol.stats["K_d"]) == 2
    herm = g.coordinate(_fits([-xe, xe], coefs, lib), lib, method="hermite")
    assert int(herm.stats["K_d"]) == 3
    np.testing.assert_allclose(np.asarray(herm.value.position_damping)[:4], [0, 0, 50, 0], atol=1e-9)


def test_covariance_is_exact_linear_propagation():
    lib = g.Library(2, 1)
    rng = np.random.default_rng(0)
    coefs = rng.normal(size=(2, lib.n_terms)) + 1.0
    a = rng.normal(size=(2, lib.n_terms, lib.n_terms))
    cov = np.einsum("nij,nkj->nik", a, a) * 1e-4
    fits = eqx.tree_at(lambda f: f.covariance, _fits([-1.0, 1.3], coefs, lib), jnp.asarray(cov))
    sol = g.coordinate(fits, lib)

    def flat(c):
        return g.coordinate(eqx.tree_at(lambda f: f.coef, fits, c), lib).value.flat()

    jac = np.zeros((sol.value.flat().shape[0], 2, lib.n_terms))
    eps = 1e-6
    for i in range(2):
        for p in range(lib.n_terms):
            e = np.zeros_like(coefs)
            e[i, p] = eps
            jac[:, i, p] = (flat(jnp.asarray(coefs + e)) - flat(jnp.asarray(coefs - e))) / (2 * eps)
    want = np.einsum("gnp,npq,hnq->gh", jac, cov, jac)
    np.testing.assert_allclose(np.asarray(sol.aux), want, rtol=1e-5, atol=1e-12)


def test_coincident_equilibria_are_ill_posed():
    lib = g.Library(2, 1)
    coefs = np.ones((2, lib.n_terms))
    sol = g.coordinate(_fits([0.5, 0.5], coefs, lib), lib, throw=False)
    assert sol.result != g.RESULTS.successful
    with pytest.raises(Exception, match="coordination"):
        g.coordinate(_fits([0.5, 0.5], coefs, lib), lib, throw=True)


def test_gls_coordination_averages_local_noise():
    """Local cubics around three wells of a degree-7 law (the NES of Eq. 23), perturbed within
    their standard errors: the exact interpolant (K = 11) passes the noise on, the
    covariance-weighted fit picks a lower degree that the chi-squared test accepts and is
    closer to the truth. With zero covariance (exact data) both are the interpolant."""
    lib = g.Library(3, 1)
    alpha = np.array([-0.9, 168.6, 575.1, -2.0e5, -5.0e4, 6.5e7, 7.6e5, -4.7e9])
    p = np.polynomial.Polynomial(alpha)
    wells = [-0.0509, 0.0054, 0.0483]
    s_idx = lib.indices("stiffness")
    rng = np.random.default_rng(3)
    coefs = np.zeros((3, lib.n_terms))
    cov = np.zeros((3, lib.n_terms, lib.n_terms))
    for i, x in enumerate(wells):
        taylor = np.array([p.deriv(k)(x) / math.factorial(k) if k else p(x) for k in range(4)])
        se = np.abs(taylor) * np.array([1e-3, 1e-3, 5e-4, 2e-2]) + 1e-6
        coefs[i, s_idx] = taylor + se * rng.normal(size=4)
        cov[i, s_idx, s_idx] = se**2
    fits = eqx.tree_at(lambda f: f.covariance, _fits(wells, coefs, lib), jnp.asarray(cov))
    xs = np.linspace(-0.075, 0.075, 301)

    def err(sol):
        got = np.polynomial.Polynomial(np.asarray(sol.value.stiffness))(xs)
        return np.linalg.norm(got - p(xs)) / np.linalg.norm(p(xs))

    herm = g.coordinate(fits, lib, method="hermite")
    gls = g.coordinate(fits, lib)
    assert int(herm.stats["K_r"]) == 11
    assert 5 <= int(gls.stats["K_r"]) < 11 and float(gls.stats["p_r"]) > 0.05
    assert err(gls) < 0.5 * err(herm), (err(gls), err(herm))
    exact = _fits(wells, coefs, lib)
    np.testing.assert_allclose(np.asarray(g.coordinate(exact, lib).value.stiffness),
                               np.asarray(g.coordinate(exact, lib, method="hermite").value.stiffness),
                               rtol=1e-9, atol=1e-6)
    with pytest.raises(ValueError, match="method"):
        g.coordinate(fits, lib, method="spline")


def test_a_removed_term_weighs_as_what_its_data_bound():
    """Three wells of a quintic, their local Taylor vectors exact to 1e-8; at the middle well STLS removed
    q^4, which is 5e4 in truth there (its centre a hair off the symmetric root). As an exact zero
    (`dropped` None) it rejects every degree below the interpolant's 17; weighed by the variance it would
    have had kept (`LocalFit.dropped`, 10x its value here), the quintic is accepted and exact."""
    lib = g.Library(5, 1)
    poly = np.polynomial.Polynomial.fromroots([-0.012, -0.006, 0.001, 0.007, 0.015]) * 1.3e10
    wells = [-0.01199, 0.001 + 8.3e-7, 0.01499]
    s_idx = lib.indices("stiffness")
    coefs = np.zeros((3, lib.n_terms))
    cov = np.zeros((3, lib.n_terms, lib.n_terms))
    dropped = np.zeros((3, lib.n_terms))
    for i, x in enumerate(wells):
        taylor = np.array([poly.deriv(k)(x) / math.factorial(k) if k else poly(x) for k in range(6)])
        se = 1e-8 * np.abs(taylor) + 1e-300
        if i == 1:
            assert 1e4 < abs(taylor[4]) < 1e5
            dropped[i, s_idx[4]] = (10 * taylor[4]) ** 2
            taylor[4], se[4] = 0.0, 0.0
        coefs[i, s_idx] = taylor
        cov[i, s_idx, s_idx] = se**2
    exact = eqx.tree_at(lambda f: f.covariance, _fits(wells, coefs, lib), jnp.asarray(cov))
    weighed = g.LocalFit(exact.equilibrium, exact.coef, exact.covariance, exact.threshold, exact.rss,
                         exact.n_samples, dropped=jnp.asarray(dropped))
    assert int(g.coordinate(exact, lib).stats["K_r"]) > 5
    sol = g.coordinate(weighed, lib)
    assert int(sol.stats["K_r"]) == 5
    np.testing.assert_allclose(np.asarray(sol.value.stiffness)[:6], poly.coef, rtol=1e-5)


def test_damping_polynomial_degree_starts_at_zero():
    """Three wells, damping (0.2 + 1400 x^2) v (audit D F8), each well's viscous value and slope within
    their standard errors (slopes 30 % noisy): the paper's exact interpolant (degree 5) passes the noise
    of the slopes on; the GLS's test starting at degree 0 takes the quadratic the values determine."""
    lib = g.Library(5, 1)
    wells = np.array([-0.012, 0.001, 0.015])
    v_idx, p_idx = lib.indices("velocity_damping"), lib.indices("position_damping")
    rng = np.random.default_rng(0)
    coefs = np.zeros((3, lib.n_terms))
    cov = np.zeros((3, lib.n_terms, lib.n_terms))
    s_idx = lib.indices("stiffness")
    for i, x in enumerate(wells):  # a restoring law so the fits are complete: x (x^2 - 1e-4)
        coefs[i, s_idx[:4]] = [x**3 - 1e-4 * x, 3 * x**2 - 1e-4, 3 * x, 1.0]
        cov[i, s_idx[:4], s_idx[:4]] = 1e-20
        value, slope = 0.2 + 1400 * x**2, 2800 * x
        se = np.array([0.01 * value, 0.3 * abs(slope) + 1.0])
        coefs[i, v_idx[1]] = value + se[0] * rng.normal()
        coefs[i, p_idx[0]] = slope + se[1] * rng.normal()
        both = [v_idx[1], p_idx[0]]
        cov[i, both, both] = se**2
    fits = eqx.tree_at(lambda f: f.covariance, _fits(wells, coefs, lib), jnp.asarray(cov))
    xs = np.linspace(-0.013, 0.016, 201)

    def err(sol):
        c = np.asarray(sol.value.position_damping).copy()
        c[0] = float(sol.value.velocity_damping[1])
        got = np.polynomial.Polynomial(c)(xs)
        truth = 0.2 + 1400 * xs**2
        return np.max(np.abs(got - truth) / truth)

    herm, gls = g.coordinate(fits, lib, method="hermite"), g.coordinate(fits, lib)
    assert int(herm.stats["K_d"]) == 5 and int(gls.stats["K_d"]) <= 2
    assert err(gls) < 0.015 and err(gls) < 0.5 * err(herm), (err(gls), err(herm))
