import jax.numpy as jnp
import numpy as np

import gmr_jax as g
from gmr_jax.simulate._frequency import resonance_frequencies, transmissibility


def test_resonance_of_linearised_chain():
    terms = []
    for i, (k1, k3) in enumerate([(-30.0, 1e5), (-60.0, 2e5)]):
        terms += [{"dof": i, "physics": "stiffness", "order": 1, "coefficient": k1},
                  {"dof": i, "physics": "stiffness", "order": 3, "coefficient": k3},
                  {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": 0.1}]
    m = g.from_terms([0.05, 0.05], terms, "chain")
    xe = -jnp.sqrt(jnp.array([30 / 1e5, 60 / 2e5]))
    fs = jnp.linspace(2.5, 5.0, 51)
    td, amp, code = transmissibility(m, fs, 1e-5, xe)
    assert np.all(np.asarray(code) == 0)
    kc = np.array([[180.0, -120.0], [-120.0, 120.0]])
    f_lin = np.sort(np.sqrt(np.linalg.eigvals(kc / 0.05)) / (2 * np.pi))[0]
    (peak,) = resonance_frequencies(fs, td)
    assert abs(peak - f_lin) < 0.01 * f_lin
    # far below resonance the tip follows the base
    td_low, _, _ = transmissibility(m, jnp.array([0.2]), 1e-5, xe)
    assert abs(float(td_low[0])) < 0.5
