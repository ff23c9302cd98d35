import equinox as eqx
import jax.numpy as jnp
import numpy as np

import gmr_jax as g
from gmr_jax.basins._sweep import SweepSettings, basin_map
from gmr_jax.basins._wells import stable_wells
from gmr_jax.simulate._inputs import HalfSineTip


def chain():
    terms = []
    for i, (k1, k3) in enumerate([(-30.0, 1e5), (-60.0, 2e5)]):
        terms += [{"dof": i, "physics": "stiffness", "order": 1, "coefficient": k1},
                  {"dof": i, "physics": "stiffness", "order": 3, "coefficient": k3},
                  {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": 0.5}]
    return g.from_terms([0.05, 0.05], terms, "chain")


def test_wells_and_classification_match_plain_simulation():
    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    np.testing.assert_allclose(wells, np.sqrt([[30 / 1e5] * 2, [60 / 2e5] * 2]) * [-1, 1], rtol=1e-4)
    f = jnp.array([0.5, 2.0, 4.0])
    A = jnp.array([0.3, 1.5, 2.5])
    bm = basin_map(m, f, A, wells, chunk=4)
    assert bm.config.shape == (3, 3) and bm.wells.shape == (3, 3, 2)
    for i in range(3):
        for j in range(3):
            t1 = 0.5 / float(f[j]) + 10.0
            sol = g.simulate(m, HalfSineTip(f[j], A[i], n_dof=2), jnp.array([0.0, t1]), jnp.asarray(wells[:, 0]))
            x1 = np.asarray(sol.value[0])[-1]
            want = [int(np.argmin(np.abs(x1[k] - wells[k]))) for k in range(2)]
            assert list(np.asarray(bm.wells[i, j])) == want
            assert int(bm.config[i, j]) == want[0] + 2 * want[1]


def test_unsettled_and_diverged_are_flagged():
    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    bm = basin_map(m, jnp.array([1.0]), jnp.array([2.0]), wells, settings=SweepSettings(settle_time=0.05))
    assert int(bm.config[0, 0]) == -1 and int(bm.result[0, 0]) == g.RESULTS.not_settled._value
    soft = g.from_terms([0.05, 0.05], [{"dof": i, "physics": "stiffness", "order": 3, "coefficient": -1e3}
                                       for i in range(2)], "chain")
    bm = basin_map(soft, jnp.array([1.0]), jnp.array([50.0]), wells)
    assert int(bm.config[0, 0]) == -1 and int(bm.result[0, 0]) == g.RESULTS.diverged._value


def test_no_recompile_for_new_grid_values_or_coefficients():
    from gmr_jax.basins import _sweep

    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    basin_map(m, jnp.array([1.0, 2.0]), jnp.array([1.0]), wells)
    before = _sweep._sweep_points._cached._cache_size()
    m2 = eqx.tree_at(lambda q: q.stiffness, m, m.stiffness * 1.01)
    basin_map(m2, jnp.array([1.5, 3.0]), jnp.array([0.7]), wells)
    assert _sweep._sweep_points._cached._cache_size() == before


def test_sharded_over_two_host_devices_matches_and_does_not_recompile():
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent("""
        import os
        os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=2"
        import jax, jax.numpy as jnp, numpy as np
        import gmr_jax as g
        from gmr_jax.basins import _sweep
        from gmr_jax.basins._sweep import basin_map
        from gmr_jax.basins._wells import stable_wells
        assert len(jax.devices()) == 2
        terms = []
        for i, (k1, k3) in enumerate([(-30.0, 1e5), (-60.0, 2e5)]):
            terms += [{"dof": i, "physics": "stiffness", "order": 1, "coefficient": k1},
                      {"dof": i, "physics": "stiffness", "order": 3, "coefficient": k3},
                      {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": 0.5}]
        m = g.from_terms([0.05, 0.05], terms, "chain")
        w = stable_wells(m, [[-0.05, 0.05]] * 2)
        f, A = jnp.linspace(0.5, 4, 5), jnp.linspace(0.3, 2.5, 3)
        two = basin_map(m, f, A, w, chunk=4)
        one = basin_map(m, f, A, w, chunk=4, devices=jax.devices()[:1])
        assert np.array_equal(np.asarray(two.config), np.asarray(one.config))
        run = _sweep._sharded(tuple(jax.devices()), 4)
        n = run._cached._cache_size()
        basin_map(m, f + 0.1, A + 0.1, w, chunk=4)
        assert run._cached._cache_size() == n
        print("OK")
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0 and "OK" in r.stdout, r.stderr[-2000:]
