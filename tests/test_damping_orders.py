"""Velocity terms no well kept, in the damping band at crossing speeds, and rule 14b (`_damping_orders`)."""

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._reconstruct import _sanity
from gmr_jax.systems import System, make_recordings

M, K1, K3, C1, C3 = 0.1, 10.0, 1e5, 0.05, 5.0
WELL = np.sqrt(K1 / K3)


def _truth():
    terms = [("stiffness", 1, -K1), ("stiffness", 3, K3), ("velocity_damping", 1, C1), ("velocity_damping", 3, C3)]
    return g.from_terms([M], [{"dof": 0, "physics": p, "order": o, "coefficient": c} for p, o, c in terms])


def test_crossing_speed_is_the_fall_from_the_barrier():
    """sqrt(2 barrier / m) for the double well -k1 x + k3 x^3 (barrier k1^2 / (4 k3)); 0 with one well."""
    want = np.sqrt(2 * K1**2 / (4 * K3) / M)
    assert _sanity.crossing_speed([0.0, -K1, 0.0, K3], [-WELL, WELL], M) == pytest.approx(want, rel=1e-5)
    assert _sanity.crossing_speed([0.0, -K1, 0.0, K3], [WELL], M) == 0.0


def test_rule_14b_speaks_where_the_alternative_parts_below_the_crossing_speed():
    """Silent where the records reach the crossing speeds (within 2x) or the alternative law stays within 25 % of the
    model's damping up to them; otherwise one message, from the first speed where it parts."""
    b, c = np.array([0.0, C1, 0.0, 0.0]), np.zeros(2)
    found = {3: (C3, 0.4, 2, np.array([0.0, 0.0, 0.0, C3]), ())}
    args = (0, b, c, found)
    assert _sanity.check_unresolved_damping(*args, 0.05, 0.07, -WELL, WELL) == []  # records reach 0.05
    assert _sanity.check_unresolved_damping(*args[:3], {3: (0.1, 0.01, 2, np.array([0, 0, 0, 0.1]), ())}, 0.011,
                                            0.07, -WELL, WELL) == []  # 0.1 v^3: 1 % of 0.05 v at 0.07
    msg = _sanity.check_unresolved_damping(*args, 0.011, 0.07, -WELL, WELL)
    assert len(msg) == 1 and "v^3 added (5 +- 0.4 refitted at 2 wells, 12.5 standard errors from 0" in msg[0]
    # |delta . phi| + 2 s v^3 = (5 + 0.8) v^3 > 0.25 * 0.05 v  <=>  v > 0.0464
    v_part = float(msg[0].split("above |v| = ")[1].split(" ")[0])
    assert v_part == pytest.approx(np.sqrt(0.25 * C1 / 5.8), abs=0.07 / 400)


@pytest.mark.parametrize("snr_db", [40.0])
def test_a_dropped_cubic_damping_is_in_the_band_at_crossing_speeds(snr_db):
    """A double well with 0.05 v + 5 v^3, swept at 4 % of the interwell distance (|v| <= 0.011, a crossing 0.071):
    the threshold drops v^3 at both wells and the model damps 33 % too little at |v| = 0.07. With the alternative in
    the band (the default), the 95 % band holds the truth's damping (0.05 v + 5 v^3, evaluated here) at every x
    between the wells, and a warning says so."""
    s = System(name="dw", truth=_truth(), equilibria=np.array([[-WELL], [WELL]]), sweep=(0.5, 6.0), duration=40.0,
               fs=200.0, x_range=np.array([[-1.5 * WELL, 1.5 * WELL]]), v_range=np.array([[-0.1, 0.1]]))
    recs = make_recordings(s, 5e-5, snr_db=snr_db, seed=0)
    xs, vc = jnp.linspace(-WELL, WELL, 21)[:, None], 0.07
    truth = C1 * vc + C3 * vc**3
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", g.GMRDataWarning)
        sol = g.reconstruct(recs)
    band = jax.vmap(lambda x: g.force_band(sol.value, x, jnp.array([vc]), part="damping"))(xs)
    lo, hi, mean = (np.asarray(a).ravel() for a in (band.lower, band.upper, band.mean))
    said = [w for w in sol.stats["warnings"] if "do not decide the damping at the speeds of a crossing" in w]
    assert np.all(mean < 0.75 * truth)  # the model's mean: too little damping at a crossing
    assert np.all((lo <= truth) & (truth <= hi)) and len(said) == 1 and "v^3 added" in said[0]
