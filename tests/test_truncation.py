"""The local Taylor truncation in the coordination's degree choice (`_reconstruct/_truncation.py`)."""

import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._reconstruct._truncation import sensitivity
from _truth import restoring_l2  # tests/_truth.py


def _well(n=2000, seed=0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, n)
    q = 0.01 * (np.sin(2 * np.pi * 7 * t) + 0.6 * np.sin(2 * np.pi * 17.3 * t + 1.0))
    v = np.gradient(q, t) + 1e-4 * rng.standard_normal(n)
    return q, v


def test_the_sensitivity_is_the_change_the_next_term_makes():
    """Noise-free force with a q^4 term, fitted with a cubic: the truncated fit plus delta is the truth
    (with the term the fit is exact); without a q^4 term delta vanishes; a well that does not move has
    none (rank-deficient)."""
    lib = g.Library(3, 1, position_damping=False)
    q, v = _well()
    true = {1: 150.0, 2: -2.0e4, 3: 4.0e5}
    y0 = sum(c * q**k for k, c in true.items()) + 0.3 * v
    support = np.array([True, True, True, True, False, True])  # 1, q, q^2, q^3, sgn(v), v
    w = np.ones_like(q)
    theta = np.asarray(lib(jnp.asarray(q), jnp.asarray(v)))[:, support]
    for a4, expect_zero in ((3.0e7, False), (0.0, True)):
        y = y0 + a4 * q**4
        coef = np.zeros(lib.n_terms)
        coef[support] = np.linalg.lstsq(theta, y, rcond=None)[0]
        d, t2 = sensitivity(coef, q, v, y, w, lib)
        assert np.all(d[~support] == 0)
        if expect_zero:
            np.testing.assert_allclose(d, 0, atol=1e-6 * np.abs(coef).max())
        else:
            fixed = coef + d
            np.testing.assert_allclose(fixed[2], true[2], rtol=1e-6)  # the curvature the q^4 had biased
            assert abs(coef[2] - true[2]) > 1e-3 * abs(true[2])
            assert t2 > 1e6  # noise-free: resolved
    # with noise and no q^4 term, t^2 is chi-squared with one degree of freedom (mean 1) and delta is the
    # new coefficient's noise carried onto the kept ones: its spread is delta delta' / t^2's
    rng = np.random.default_rng(1)
    t2s, d2, var = [], [], []
    for _ in range(40):
        y = y0 + 1e-3 * rng.standard_normal(q.size)
        coef = np.zeros(lib.n_terms)
        coef[support] = np.linalg.lstsq(theta, y, rcond=None)[0]
        d, t2 = sensitivity(coef, q, v, y, w, lib)
        t2s.append(t2), d2.append(d[2] ** 2), var.append(d[2] ** 2 / t2)
    assert 0.5 < np.mean(t2s) < 1.6, np.mean(t2s)
    assert 0.5 < np.mean(d2) / np.mean(var) < 1.6
    still = np.zeros_like(q)
    d, t2 = sensitivity(coef, still, still, y0, w, lib)
    assert np.all(d == 0) and t2 == np.inf


@pytest.mark.slow  # one NES reconstruction (~20 s cold); the default tier keeps the unit test above
def test_the_truncation_chooses_the_degree_of_the_tristable_nes():
    """Tri-stable NES (paper orders 3, 3), 60 dB, seed 0: the local F'' at two wells was 3-4 standard
    errors off for want of q^4, the chi-squared test rejected degree 7 and the law of degree 8, then 9,
    was 0.24-0.29 % off the truth; with the truncation in the degree choice, degree 7, 0.031 %."""
    s = g.systems.tristable_nes()
    recs = g.systems.make_recordings(s, 5e-4, snr_db=60.0, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = g.reconstruct(recs, g.Library(*s.orders["gmr"]))
    st = res.stats["dofs"][0].stats
    k = np.trim_zeros(np.asarray(res.value.stiffness[0]), "b")
    assert k.size - 1 == 7
    assert any("truncation of their Taylor series" in n for n in st.get("degree_notes", [])), st.get("degree_notes")
    # independent: relative L2 over the box by NumPy against the truth
    assert restoring_l2(s, k, 801)[0] < 1e-3
