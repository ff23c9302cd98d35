"""`_reconstruct/_damping_slopes.py`: the slope of the damping a well does not resolve, in the band."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._reconstruct import _damping_slopes


def test_slope_vectors_are_the_hermite_slope_basis_times_estimate_and_noise():
    eq = np.array([-1.0, 0.2, 1.5])
    est, se = np.array([3.0, 0.0, -1.0]), np.array([4.0, 0.0, 2.0])  # the middle well kept its x v
    vectors = _damping_slopes.slope_vectors(eq, est, se)
    assert len(vectors) == 2
    for d, k, size in zip(vectors, (0, 2), (5.0, np.sqrt(5.0))):
        p = np.polynomial.Polynomial(d)
        assert d.size == 2 * eq.size
        np.testing.assert_allclose(p(eq), 0.0, atol=1e-12)  # the wells' values stay as the data fix them
        slopes = p.deriv()(eq)
        np.testing.assert_allclose(slopes, size * (np.arange(eq.size) == k), atol=1e-12)


def test_add_slope_vectors_places_the_damping_polynomial():
    ns, nv, npos = 4, 3, 5
    cov = np.eye(ns + nv + npos)
    d = np.array([1.0, 2.0, 3.0, 4.0])
    out = _damping_slopes.add_slope_vectors(cov, ns, nv, npos, [d])
    full = np.zeros(ns + nv + npos)
    full[ns + 1], full[ns + nv + 1 : ns + nv + 4] = 1.0, [2.0, 3.0, 4.0]  # C_0 = B_1, C_j of x^j v
    np.testing.assert_allclose(out - cov, np.outer(full, full))
    # a vector the position block cannot hold is left out
    np.testing.assert_allclose(_damping_slopes.add_slope_vectors(cov, ns, nv, 3, [d]), cov)


@pytest.mark.slow  # two reconstructions of a 5-cell chain (~2 x 60 s)
def test_the_tip_cell_band_holds_the_damping_it_does_not_resolve():
    """5-cell Kresling chain, 0.3 mm sweeps, 50 dB, seed 0 (`studies/coverage.py`): the tip cell keeps no x v at
    either well (C' = -15 and +15 there, refitted at 2-3 standard errors); its C is the wells' constant, which
    the truth halves between them. Its band was 0.17 % wide and held the truth on 4.9 % of span x v_range (470-690
    standard errors off mid-span); with the slopes' alternative and noise on >= 90 % (measured 100 %, 38 % wide)."""
    system = g.systems.kresling5()
    recs = g.systems.make_recordings(system, 3e-4, snr_db=50.0, seed=0)
    i = 4
    eq = system.equilibria[:, i]
    vs = np.linspace(*system.v_range[i], 41)
    xx, vv = (a.ravel() for a in np.meshgrid(np.linspace(eq.min(), eq.max(), 41), vs[vs != 0], indexing="ij"))
    x = jnp.zeros((xx.size, 5)).at[:, i].set(jnp.asarray(xx))
    v = jnp.zeros((xx.size, 5)).at[:, i].set(jnp.asarray(vv))
    truth = np.asarray(jax.vmap(system.truth.damping)(x, v))[:, i]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = g.reconstruct(recs, g.Library(*system.orders["gmr"]), throw=False).value
    band = jax.vmap(lambda p, q: g.force_band(model, p, q, part="damping", level=0.95))(x, v)
    low, up = np.asarray(band.lower)[:, i], np.asarray(band.upper)[:, i]
    cover = float(np.mean((truth >= low) & (truth <= up)))
    assert cover >= 0.9, cover
