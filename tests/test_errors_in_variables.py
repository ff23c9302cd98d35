"""Errors in variables (`_fit/_errors_in_variables.py`): the corrected score of a local fit whose
displacement is measured with noise. Checked against the Hermite polynomials written out, the
corrected normal equations solved directly in NumPy, a Monte Carlo of the bias, jit/vmap/grad,
and `reconstruct` on a chain (slow tier)."""

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._fit._errors_in_variables import corrected_qr, hermite_excess, powers_and_factors
from gmr_jax._fit._stls import compress

LIB = g.Library(3, 1)  # 1, q, q^2, q^3, sgn(v), v, q v
N = 4000


def _excess_closed_form(n, q, s2):
    """q^n - He_n(q; s2) from He_n(q; s2) = sum_k (-1)^k n! / (k! (n - 2k)! 2^k) s2^k q^(n - 2k)."""
    he = sum((-1) ** k * math.factorial(n) / (math.factorial(k) * math.factorial(n - 2 * k) * 2**k)
             * s2**k * q ** (n - 2 * k) for k in range(n // 2 + 1))
    return q**n - he


def test_hermite_excess_matches_the_closed_form_and_unbiases_the_powers():
    q = np.linspace(-2.0, 3.0, 11)
    d = np.asarray(hermite_excess(jnp.asarray(q), 0.3, 8))
    for n in range(9):
        np.testing.assert_allclose(d[:, n], _excess_closed_form(n, q, 0.3), rtol=1e-12, atol=1e-12)
    # E[(q + e)^n - D_n(q + e)] = q^n, by Monte Carlo (antithetic draws, 2e5 of them)
    rng = np.random.default_rng(0)
    e = rng.standard_normal(100_000) * np.sqrt(0.3)
    e = np.concatenate([e, -e])
    for q0 in (-1.0, 0.4, 1.5):
        z = q0 + e
        dz = np.asarray(hermite_excess(jnp.asarray(z), 0.3, 6))
        for n in range(7):
            draws = z**n - dz[:, n]
            se = np.std(draws) / np.sqrt(draws.size / 2)  # antithetic pairs: at most half as many independent
            assert abs(np.mean(draws) - q0**n) < 5 * se + 1e-12, (q0, n)


def _problem(seed, sd_x=0.02, sd_y=0.02):
    """A cubic well, q from a decaying sweep, v its derivative; y = F(q) + c v + noise; x noisy."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 40.0, N)
    amp = 0.3 * (1.0 + 0.5 * np.sin(0.13 * t))
    q = amp * np.sin(2 * np.pi * (0.5 + 0.05 * t) * t)
    v = np.gradient(q, t)
    y = 2.0 * q - 3.0 * q**2 + 5.0 * q**3 + 0.2 * v + sd_y * rng.standard_normal(N)
    q_obs = q + sd_x * rng.standard_normal(N)
    return q_obs, v, y


def _normal_equation_solution(q, v, y, s2):
    """The corrected score solved from its normal equations, in NumPy (the module's formula
    written out: each q^n in Θ'Θ and Θ'y replaced by He_n)."""
    cols = [(0, 1.0), (1, 1.0), (2, 1.0), (3, 1.0), (0, np.sign(v)), (0, v), (1, v)]
    m = np.array([c[0] for c in cols])
    gfac = np.stack([np.broadcast_to(c[1], q.shape) for c in cols], 1)
    he = lambda n: q**n - _excess_closed_form(n, q, s2)  # noqa: E731
    mm = np.array([[np.sum(he(m[a] + m[b]) * gfac[:, a] * gfac[:, b]) for b in range(7)] for a in range(7)])
    bb = np.array([np.sum(he(m[a]) * gfac[:, a] * y) for a in range(7)])
    return np.linalg.solve(mm, bb)


def _solve(qr):
    return np.linalg.solve(np.asarray(qr.r), np.asarray(qr.z))


def test_corrected_problem_is_the_corrected_normal_equations():
    q, v, y = _problem(1)
    w = jnp.ones(N)
    qr = compress(LIB(jnp.asarray(q), jnp.asarray(v)), jnp.asarray(y), w)
    fixed, ok = corrected_qr(qr, jnp.asarray(q), jnp.asarray(v), jnp.asarray(y), w, LIB, jnp.asarray(0.02**2))
    assert bool(ok)
    np.testing.assert_allclose(_solve(fixed), _normal_equation_solution(q, v, y, 0.02**2), rtol=1e-8, atol=1e-10)
    # the objective changes by a constant only: R_c'R_c = M - Δ (checked via the normal matrix)
    m_c = np.asarray(fixed.r).T @ np.asarray(fixed.r)
    th = np.asarray(LIB(jnp.asarray(q), jnp.asarray(v)))
    assert np.all(np.linalg.eigvalsh(m_c) > 0) and not np.allclose(m_c, th.T @ th, rtol=1e-6)
    # no noise: the problem itself
    same, ok0 = corrected_qr(qr, jnp.asarray(q), jnp.asarray(v), jnp.asarray(y), w, LIB, jnp.asarray(0.0))
    assert bool(ok0)
    np.testing.assert_allclose(_solve(same), _solve(qr), rtol=1e-10)


def test_corrected_score_removes_the_attenuation():
    """20 draws with noise of 5 % of the amplitude on q: least squares biases the slope (+1.3 %)
    and the cubic (-7 %) by several times their scatter; the corrected fit is unbiased within it."""
    ols, fixed = [], []
    for seed in range(20):
        q, v, y = _problem(seed, sd_x=0.015)
        w = jnp.ones(N)
        qr = compress(LIB(jnp.asarray(q), jnp.asarray(v)), jnp.asarray(y), w)
        c, _ = corrected_qr(qr, jnp.asarray(q), jnp.asarray(v), jnp.asarray(y), w, LIB, jnp.asarray(0.015**2))
        ols.append(_solve(qr)), fixed.append(_solve(c))
    ols, fixed = np.array(ols), np.array(fixed)
    for k, true in ((1, 2.0), (3, 5.0)):
        se = np.std(fixed[:, k]) / np.sqrt(len(fixed))  # of the mean of 20 draws
        assert abs(np.mean(ols[:, k]) - true) > 3 * np.std(fixed[:, k])  # biased by several scatters of one fit
        assert abs(np.mean(fixed[:, k]) - true) < 3 * se


def test_too_much_noise_falls_back_to_the_recorded_problem():
    q, v, y = _problem(2)
    w = jnp.ones(N)
    qr = compress(LIB(jnp.asarray(q), jnp.asarray(v)), jnp.asarray(y), w)
    out, ok = corrected_qr(qr, jnp.asarray(q), jnp.asarray(v), jnp.asarray(y), w, LIB, jnp.asarray(1e3))
    assert not bool(ok)
    np.testing.assert_array_equal(np.asarray(out.r), np.asarray(qr.r))
    out, ok = corrected_qr(qr, jnp.asarray(q), jnp.asarray(v), jnp.asarray(y), w, LIB, jnp.asarray(jnp.nan))
    assert not bool(ok)


def test_corrected_qr_under_jit_vmap_and_grad():
    qs, vs, ys = (np.stack(a) for a in zip(*[_problem(s) for s in range(3)]))
    w = jnp.ones(N)

    def slope(q, v, y, s2):
        qr = compress(LIB(q, v), y, w)
        c, _ = corrected_qr(qr, q, v, y, w, LIB, s2)
        return jnp.linalg.solve(c.r, c.z)[1]

    one = [float(slope(jnp.asarray(qs[k]), jnp.asarray(vs[k]), jnp.asarray(ys[k]), 4e-4)) for k in range(3)]
    batched = jax.jit(jax.vmap(slope, in_axes=(0, 0, 0, None)))(jnp.asarray(qs), jnp.asarray(vs), jnp.asarray(ys),
                                                                 jnp.asarray(4e-4))
    np.testing.assert_allclose(np.asarray(batched), one, rtol=1e-10)
    f = lambda s2: slope(jnp.asarray(qs[0]), jnp.asarray(vs[0]), jnp.asarray(ys[0]), s2)  # noqa: E731
    grad = float(jax.grad(f)(jnp.asarray(4e-4)))
    h = 1e-6
    fd = (float(f(jnp.asarray(4e-4 + h))) - float(f(jnp.asarray(4e-4 - h)))) / (2 * h)
    np.testing.assert_allclose(grad, fd, rtol=1e-5)


def test_fit_local_with_x_noise_keeps_the_recorded_covariance():
    q, v, y = _problem(3, sd_x=0.015)
    x = jnp.asarray(q + 1.0)
    plain = g.fit_local(x, jnp.asarray(v), jnp.asarray(y), LIB, select=None)
    fixed = g.fit_local(x, jnp.asarray(v), jnp.asarray(y), LIB, select=None, x_noise=jnp.asarray(0.015**2))
    assert bool(fixed.stats["eiv_applied"])
    k1, k3 = LIB.names().index("x"), LIB.names().index("x^3")
    assert abs(float(fixed.value.coef[k3]) - 5.0) < 0.5 * abs(float(plain.value.coef[k3]) - 5.0)  # bias undone
    # standard errors of the recorded samples (to first order the corrected estimator's), the rss theirs
    np.testing.assert_allclose(np.sqrt(np.diag(np.asarray(fixed.value.covariance)))[k1],
                               np.sqrt(np.diag(np.asarray(plain.value.covariance)))[k1], rtol=0.05)
    assert float(fixed.value.rss) >= float(plain.value.rss)


@pytest.mark.slow
def test_noisy_chain_band_holds_the_truth():
    """2-cell cubic chain, 30 dB on every channel: noise on x inside the regressors biases a plain
    regression's slopes; the default route's error stays small and its band holds the truth on
    the interwell span of every cell."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "studies"))
    from coverage import poly2

    system = poly2()
    for seed in (0, 1, 4):
        recs = g.systems.make_recordings(system, 3e-4, snr_db=30.0, seed=seed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sol = g.reconstruct(recs, throw=False)
        for i in range(2):
            assert g.metrics.restoring_error(sol.value, system.truth, i, system.x_range[i]) < 0.01
            eq = sol.stats["dofs"][i].equilibria
            xs = np.linspace(eq.min(), eq.max(), 101)
            X = np.zeros((xs.size, 2))
            X[:, i] = xs
            band = jax.vmap(lambda xx: g.force_band(sol.value, xx))(jnp.asarray(X))
            true = np.asarray(jax.vmap(system.truth.restoring)(jnp.asarray(X)))[:, i]
            inside = (np.asarray(band.lower)[:, i] <= true) & (true <= np.asarray(band.upper)[:, i])
            assert inside.mean() > 0.9



def test_a_floor_that_is_not_flat_is_not_taken_for_white_noise():
    from scipy.signal import butter, sosfiltfilt

    from gmr_jax._recordings._noise import white_floor

    rng = np.random.default_rng(1)
    dt = 1e-3
    t = np.arange(20000) * dt
    x = 1e-3 * np.sin(2 * np.pi * 3 * t) + 1e-5 * rng.standard_normal(t.size)
    assert white_floor(x, dt) == pytest.approx(1e-10, rel=0.1)
    # anti-aliasing roll-off: the top of the band falls away
    sos = butter(8, 300.0, fs=1 / dt, output="sos")
    assert white_floor(sosfiltfilt(sos, x), dt) is None
    # a response whose spectrum still falls at the top of the band (red noise, not white)
    assert white_floor(np.cumsum(rng.standard_normal(t.size)) * 1e-6, dt) is None


def test_noise_variances_do_not_recompile_the_local_fit():
    """The noise variance of x is a traced array: a new variance reuses the compiled fit (a Python
    float would be static to `filter_jit`: one compile per value)."""
    rng = np.random.default_rng(0)
    x = 0.01 * rng.standard_normal(2000)
    v = rng.standard_normal(2000)
    y = 200.0 * x + 0.5 * v + 1e-3 * rng.standard_normal(2000)
    jitted = g.fit_local.__wrapped_jit__
    sizes = []
    for var in (1e-8, 2e-8):
        g.fit_local(x, v, y, g.Library(3, 1), x_noise=jnp.asarray(var), throw=False)
        sizes.append(jitted._cached._cache_size())
    assert sizes[1] == sizes[0]


