import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._simulate._frequency import resonance_frequencies, transmissibility


def test_resonance_of_linearised_chain():
    terms = []
    for i, (k1, k3) in enumerate([(-30.0, 1e5), (-60.0, 2e5)]):
        terms += [{"dof": i, "physics": "stiffness", "order": 1, "coefficient": k1},
                  {"dof": i, "physics": "stiffness", "order": 3, "coefficient": k3},
                  {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": 0.1}]
    m = g.from_terms([0.05, 0.05], terms, "chain")
    xe = -jnp.sqrt(jnp.array([30 / 1e5, 60 / 2e5]))
    fs = jnp.linspace(2.5, 5.0, 51)
    sol = transmissibility(m, fs, 1e-5, xe)
    td, amp = sol.value
    assert np.all(np.asarray(sol.stats["results"]) == 0)
    kc = np.array([[180.0, -120.0], [-120.0, 120.0]])
    f_lin = np.sort(np.sqrt(np.linalg.eigvals(kc / 0.05)) / (2 * np.pi))[0]
    (peak,) = resonance_frequencies(fs, td)
    assert abs(peak - f_lin) < 0.01 * f_lin
    # far below resonance the tip follows the base
    # (the same number of frequencies: the compiled sweep is reused)
    td_low, _ = transmissibility(m, fs.at[0].set(0.2), 1e-5, xe).value
    assert abs(float(td_low[0])) < 0.5


@pytest.mark.slow
def test_resonance_peaks_refine_to_the_exact_linear_peak():
    """Linear oscillator under base motion: |T(r)|² = (1 + (2ζr)²) / ((1 - r²)² + (2ζr)²).
    The refined peak of a coarse 25-point curve lands on the exact maximum."""
    k, c, mass = 400.0, 0.4, 0.1
    m = g.from_terms([mass], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": k},
                              {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": c}],
                     "independent")
    fn = np.sqrt(k / mass) / (2 * np.pi)
    zeta = c / (2 * np.sqrt(k * mass))
    r = np.linspace(0.5, 1.5, 200001)
    t2 = (1 + (2 * zeta * r) ** 2) / ((1 - r**2) ** 2 + (2 * zeta * r) ** 2)
    f_exact = fn * r[np.argmax(t2)]
    td, peaks, ok = g.resonance_peaks(m, np.linspace(0.5 * fn, 1.5 * fn, 25), 1e-5, jnp.zeros(1),
                                      zoom=0.03, n_zoom=41, min_settle_time=20.0)
    assert ok and len(peaks) == 1
    assert abs(peaks[0] - f_exact) < 1e-3 * f_exact
    np.testing.assert_allclose(np.max(td), 10 * np.log10(np.max(t2)), atol=1.5)  # coarse grid misses the top


def test_energy_barriers_of_a_double_well():
    """F = -k1 x + k3 x³: wells at ±sqrt(k1/k3), barrier k1² / (4 k3) on both sides."""
    k1, k3 = 30.0, 1e5
    m = g.from_terms([0.05], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -k1},
                              {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": k3}], "independent")
    out = g.metrics.energy_barriers(m, 0, (-0.03, 0.03))
    assert len(out) == 2
    for x, b in out:
        assert abs(abs(x) - np.sqrt(k1 / k3)) < 1e-5
        assert abs(b - k1**2 / (4 * k3)) < 1e-4 * k1**2 / (4 * k3)
