import jax
import jax.numpy as jnp
import numpy as np
from scipy.integrate import solve_ivp

import gmr_jax as g


def test_matches_scipy_and_jit_vmap():
    s = g.systems.bistable_joint("position_dependent")
    m = s.truth
    exc = g.BaseSine(0.05, 8.0)
    ts = jnp.linspace(0, 1.0, 201)
    sol = g.simulate(m, exc, ts, jnp.array([1.0]))

    @jax.jit
    def acc(t, y):
        b, f = exc(t)
        return m.accelerations(y[:1], y[1:], b, f)[0]

    def rhs(t, y):
        return [y[1], float(acc(t, jnp.asarray(y)))]

    ref = solve_ivp(rhs, (0, 1), [1.0, 0.0], t_eval=np.asarray(ts), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(np.asarray(sol.value[0])[:, 0], ref.y[0], atol=1e-6)
    batch = jax.vmap(lambda a: g.simulate(m, g.BaseSine(a, 8.0), ts, jnp.array([1.0]), throw=False))(
        jnp.array([0.05, 0.01]))
    np.testing.assert_allclose(batch.value[0][0], sol.value[0], atol=1e-8)


def test_divergence_is_flagged_not_returned():
    m = g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 3, "coefficient": -1.0}])
    sol = g.simulate(m, g.NoInput(), jnp.linspace(0, 10, 11), jnp.array([2.0]),
                     box=100.0, throw=False)
    assert sol.result == g.RESULTS.diverged
    assert np.all(np.isnan(np.asarray(sol.value[0])))


def test_grad_through_solve_vs_finite_differences():
    s = g.systems.bistable_joint("position_dependent")
    ts = jnp.linspace(0, 0.5, 51)

    def loss(k3):
        m = g.GlobalModel(s.truth.masses, s.truth.stiffness.at[0, 3].set(k3), s.truth.velocity_damping,
                          s.truth.position_damping)
        x = g.simulate(m, g.HalfSineTip(2.0, 500.0), ts, jnp.array([-1.13]), throw=False).value[0]
        return jnp.sum(x**2)

    gk = jax.grad(loss)(1755.0)
    fd = (loss(1755.0 + 0.5) - loss(1755.0 - 0.5)) / 1.0
    np.testing.assert_allclose(gk, fd, rtol=1e-4)
