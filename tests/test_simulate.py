import jax
import jax.numpy as jnp
import numpy as np
import pytest
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


def test_reversed_times_under_jit_are_a_result_code():
    """Outside jit a reversed ts is refused by name; under jit (the times traced) the solve says
    `unordered_times` with NaN values (audit: it returned `successful` and a wrong trajectory)."""
    m = g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": 1.0}])
    ts = jnp.linspace(1.0, 0.0, 11)
    with pytest.raises(g.GMRInputError, match="strictly increasing"):
        g.simulate(m, g.NoInput(), ts, jnp.array([0.1]))
    sol = jax.jit(lambda t: g.simulate(m, g.NoInput(), t, jnp.array([0.1]), throw=False))(ts)
    assert sol.status == "unordered_times" and np.all(np.isnan(np.asarray(sol.value[0])))
    ok = jax.jit(lambda t: g.simulate(m, g.NoInput(), t, jnp.array([0.1]), throw=False))(ts[::-1])
    assert ok.status == "successful"


def test_divergence_is_flagged_not_returned():
    m = g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 3, "coefficient": -1.0}])
    sol = g.simulate(m, g.NoInput(), jnp.linspace(0, 10, 11), jnp.array([2.0]),
                     box=100.0, throw=False)
    assert sol.result == g.RESULTS.diverged
    assert np.all(np.isnan(np.asarray(sol.value[0])))
    # named, not only coded: status and ok outside jit, for one result and for a batch (as a
    # vmapped solve returns them); inside jit a clear error
    assert sol.status == "diverged" and not sol.ok
    from gmr_jax._solution import as_result

    codes = as_result(jnp.array([g.RESULTS.successful._value, g.RESULTS.diverged._value]))
    batch = g.Solution(value=None, result=codes, stats={})
    assert batch.status.tolist() == ["successful", "diverged"] and not batch.ok
    assert g.Solution(value=None, result=g.RESULTS.successful, stats={}).ok
    with pytest.raises(g.GMRInputError, match="outside jit"):
        jax.jit(lambda r: g.Solution(value=None, result=r, stats={}).ok)(g.RESULTS.successful)


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


def test_declared_sample_times_cut_rejected_steps_on_a_rough_input(rng):
    """A long record with a rough (noisy) input, linearly interpolated: each kink rejects steps
    unless the sample times are declared to the controller (issue 14: ~17 steps per sample)."""
    n = 3000
    t = np.arange(n) * 0.01
    f = np.sin(2 * np.pi * 0.8 * t) + 0.3 * rng.normal(size=n)
    m = g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": 30.0},
                                   {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.5}])
    ts = jnp.asarray(t)
    runs = {}
    for declare in (False, True):
        inp = g.Sampled(ts, jnp.zeros(n), jnp.asarray(f[:, None]), n_dof=1, declare_samples=declare)
        runs[declare] = g.simulate(m, inp, ts, jnp.zeros(1), integrator=g.Integrator(
            rtol=1e-8, atol=1e-10, max_steps=400_000))
    a, b = runs[False], runs[True]
    np.testing.assert_allclose(np.asarray(b.value[0]), np.asarray(a.value[0]), atol=1e-4 * float(jnp.max(jnp.abs(a.value[0]))))
    assert int(b.stats["num_rejected_steps"]) < 0.2 * int(a.stats["num_rejected_steps"])


def test_a_failed_solve_outside_jit_is_a_named_error_and_coulomb_friction_says_the_fix():
    """With concrete arguments and throw=True a failure is a GMRComputationError naming the code
    (not equinox's runtime error with a JAX trace); a model with the exact sgn(v) chatters to
    its step budget, and the error says how to integrate it; inside jit the old raise stays."""
    terms = [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -10.0},
             {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 11111.0},
             {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.8},
             {"dof": 0, "physics": "velocity_damping", "order": 0, "coefficient": 0.01}]
    m = g.from_terms([0.05], terms, "chain")
    ts = jnp.linspace(0.0, 12.0, 121)
    small = g.Integrator(max_steps=4000)
    with pytest.raises(g.GMRComputationError, match="max_steps_reached") as err:
        g.simulate(m, g.HalfSineTip(1.0, 0.2, n_dof=1), ts, jnp.array([-0.03]), integrator=small)
    assert "with_sign_eps" in str(err.value) and err.value.name == "max_steps_reached"
    smooth = g.simulate(m.with_sign_eps(1e-4), g.HalfSineTip(1.0, 0.2, n_dof=1), ts, jnp.array([-0.03]),
                        integrator=g.Integrator(max_steps=100_000))
    assert smooth.ok and np.min(np.abs(float(smooth.value[0][-1, 0]) - np.array([-0.03, 0.03]))) < 0.003
    # a model without sgn(v) that diverges: the named code, no friction hint
    bad = g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 3, "coefficient": -1e3}], "chain")
    with pytest.raises(g.GMRComputationError, match="diverged") as err:
        g.simulate(bad, g.NoInput(), ts, jnp.array([0.5]), box=10.0)
    assert "with_sign_eps" not in str(err.value)
    import equinox as eqx

    with pytest.raises((eqx.EquinoxRuntimeError, jax.errors.JaxRuntimeError)):
        jax.jit(lambda x0: g.simulate(bad, g.NoInput(), ts, x0, box=10.0).value[0])(jnp.array([0.5]))
