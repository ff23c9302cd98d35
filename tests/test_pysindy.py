"""pysindy interop (`to_pysindy`, `from_pysindy`) and the vectorised `predict`."""

import sys
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g

ps = pytest.importorskip("pysindy")


def _chain():
    terms = []
    for i, (k1, k3) in enumerate([(-30.0, 1e5), (-60.0, 2e5), (-10.0, 3e4)]):
        terms += [{"dof": i, "physics": "stiffness", "order": 0, "coefficient": 0.01 * (i + 1)},
                  {"dof": i, "physics": "stiffness", "order": 1, "coefficient": k1},
                  {"dof": i, "physics": "stiffness", "order": 3, "coefficient": k3},
                  {"dof": i, "physics": "velocity_damping", "order": 0, "coefficient": 0.1},
                  {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": 0.5},
                  {"dof": i, "physics": "velocity_damping", "order": 2, "coefficient": 0.2},
                  {"dof": i, "physics": "position_damping", "order": 2, "coefficient": 0.3}]
    return g.from_terms([0.05, 0.04, 0.03], terms, "chain")


MODELS = {
    "joint": lambda: g.systems.bistable_joint("position_dependent").truth,
    "nes": lambda: g.systems.tristable_nes().truth,
    "chain": _chain,
    "independent": lambda: g.from_terms([0.2, 0.3], [
        {"dof": 0, "physics": "stiffness", "order": 1, "coefficient": 5.0},
        {"dof": 1, "physics": "stiffness", "order": 2, "coefficient": -2.0},
        {"dof": 1, "physics": "stiffness", "order": 3, "coefficient": 7.0},
        {"dof": 1, "physics": "position_damping", "order": 0, "coefficient": 0.4},
        {"dof": 0, "physics": "velocity_damping", "order": 3, "coefficient": 1.5}], "independent"),
}


def _states(d, n=200, seed=0):
    r = np.random.default_rng(seed)
    return r.normal(size=(n, d)), r.normal(size=(n, d)), r.normal(size=n), r.normal(size=(n, d))


def _loop(model, x, v, b, f):
    """The reference: the model's own one-state accelerations, state by state (jitted once)."""
    one = jax.jit(lambda x, v, b, f: model.accelerations(x, v, b, f))
    return np.stack([np.asarray(one(x[k], v[k], b[k], f[k])) for k in range(x.shape[0])])


@pytest.mark.parametrize("name", list(MODELS))
def test_exported_pysindy_predicts_the_same_derivatives(name):
    model = MODELS[name]()
    d = model.n_dof
    x, v, b, f = _states(d)
    s = g.to_pysindy(model)
    zdot = s.predict(np.hstack([x, v]), np.column_stack([b, f]))
    want = _loop(model, x, v, b, f)
    np.testing.assert_array_equal(zdot[:, :d], v)
    np.testing.assert_allclose(zdot[:, d:], want, rtol=1e-10, atol=1e-10 * np.max(np.abs(want)))
    # the free system, no controls
    free = g.to_pysindy(model, inputs=False).predict(np.hstack([x, v]))
    np.testing.assert_allclose(free[:, d:], _loop(model, x, v, 0 * b, 0 * f), rtol=1e-10,
                               atol=1e-10 * np.max(np.abs(want)))


@pytest.mark.parametrize("name", list(MODELS))
def test_round_trip_gives_the_same_coefficients(name):
    model = MODELS[name]()
    back = g.from_pysindy(g.to_pysindy(model), model.masses, model.topology.name)
    for fam in ("stiffness", "velocity_damping", "position_damping"):
        a, b = np.asarray(getattr(model, fam)), np.asarray(getattr(back, fam))
        w = min(a.shape[1], b.shape[1])
        assert not np.any(a[:, w:]) and not np.any(b[:, w:])
        np.testing.assert_allclose(b[:, :w], a[:, :w], rtol=1e-12, atol=1e-12 * np.max(np.abs(a)))


def test_feature_names_are_the_model_file_names():
    s = g.to_pysindy(MODELS["joint"]())
    names = s.get_feature_names()
    assert {"x0^0", "x0", "x0^3", "sgn(v0)", "v0", "x0^2*v0", "base_acc", "f0"} <= set(names)


def test_local_fit_export_in_its_own_coordinate():
    lib = g.Library(3, 1)
    coef = jnp.array([0.0, 4.0, 0.0, 2.0, 0.0, 0.3, 0.1])  # 1, q, q^2, q^3, sgn(v), v, q v
    fit = g.LocalFit(equilibrium=jnp.asarray(1.5), coef=coef, covariance=jnp.eye(7), threshold=jnp.asarray(0.0),
                     rss=jnp.asarray(0.0), n_samples=jnp.asarray(100.0))
    s = g.to_pysindy(fit, library=lib, mass=2.0)
    assert "q0^3" in s.get_feature_names()
    q, v, b, f = _states(1, 50)
    zdot = s.predict(np.hstack([q, v]), np.column_stack([b, f]))
    F = 4 * q + 2 * q**3 + 0.3 * v + 0.1 * q * v
    np.testing.assert_allclose(zdot[:, 1:], (f - F) / 2.0 - b[:, None], rtol=1e-12, atol=1e-12)
    with pytest.raises(g.GMRInputError, match="Library it was fitted with"):
        g.to_pysindy(fit)


def test_import_a_plain_polynomial_pysindy_model():
    """A SINDy fitted by a pysindy user on (x, v) with a PolynomialLibrary imports where its terms map."""
    truth = g.from_terms([0.5], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -1.0},
                                 {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 4.0},
                                 {"dof": 0, "physics": "position_damping", "order": 2, "coefficient": 0.2},
                                 {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.05}])
    x, v, _, _ = _states(1, 400, seed=3)
    xdd = np.asarray(g.predict(truth, x, v))
    s = ps.SINDy(optimizer=ps.STLSQ(threshold=1e-3), feature_library=ps.PolynomialLibrary(degree=3))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s.fit(np.hstack([x, v]), t=1.0, x_dot=np.hstack([v, xdd]), feature_names=["x0", "v0"])
    m = g.from_pysindy(s, [0.5])
    np.testing.assert_allclose(np.asarray(m.stiffness)[0, [1, 3]], [-1.0, 4.0], rtol=1e-8)
    np.testing.assert_allclose(np.asarray(m.position_damping)[0, 2], 0.2, rtol=1e-8)
    # a term outside the model format is named
    s.optimizer.coef_[1, s.get_feature_names().index("v0^2")] = 0.7
    with pytest.raises(g.GMRInputError, match=r"'v0\^2' does not map"):
        g.from_pysindy(s, [0.5])
    # x' must be v
    s.optimizer.coef_[1, s.get_feature_names().index("v0^2")] = 0.0
    s.optimizer.coef_[0, s.get_feature_names().index("x0")] = 0.3
    with pytest.raises(g.GMRInputError, match="x_i' = v_i"):
        g.from_pysindy(s, [0.5])


def test_inputs_must_match_the_masses():
    s = g.to_pysindy(MODELS["joint"]())
    with pytest.raises(g.GMRInputError, match="do not match the masses"):
        g.from_pysindy(s, [2.0])


def test_missing_pysindy_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "pysindy", None)
    with pytest.raises(g.GMRInputError, match="pip install pysindy"):
        g.to_pysindy(MODELS["joint"]())


def test_predict_vectorised_matches_and_traces():
    model = _chain()
    x, v, b, f = _states(3, 37)
    want = _loop(model, x, v, b, f)
    np.testing.assert_allclose(np.asarray(g.predict(model, x, v, b, f)), want, rtol=1e-13, atol=1e-9)
    # inside the user's own jit (no padding on tracers), and a 1-DOF model with (n,) arrays
    got = jax.jit(lambda x, v: g.predict(model, x, v))(x, v)
    np.testing.assert_allclose(np.asarray(got), _loop(model, x, v, 0 * b, 0 * f), rtol=1e-13, atol=1e-9)
    joint = MODELS["joint"]()
    a = g.predict(joint, x[:, 0], v[:, 0])
    assert a.shape == (37, 1)
    with pytest.raises(g.GMRInputError, match=r"\(n, 3\)"):
        g.predict(model, x[:, :2], v[:, :2])


@pytest.mark.parametrize("sign_eps", [0.0, 0.05])
def test_numpy_forces_equal_the_models_own(sign_eps):
    """`reconstruct` and the figures evaluate a `GlobalModel` in NumPy (`numpy_forces`, no JAX
    program): the same F_r and F_d as its jitted `restoring` / `damping` (every term kind, a
    smoothed sign, v = 0 exactly), and `forces` takes that path."""
    from gmr_jax._model._predict import forces, numpy_forces

    model = _chain().with_sign_eps(sign_eps)
    x, v, _, _ = _states(3, 41)
    v = np.asarray(v).copy()
    v[:3] = 0.0
    fr, fd = numpy_forces(model, x, v)
    assert isinstance(fr, np.ndarray) and isinstance(fd, np.ndarray)
    np.testing.assert_allclose(fr, np.asarray(jax.vmap(model.restoring)(jnp.asarray(x))), rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(fd, np.asarray(jax.vmap(model.damping)(jnp.asarray(x), jnp.asarray(v))),
                               rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(forces(model, x, v), fr + fd, rtol=0, atol=0)
    # a model that is not a GlobalModel goes through the compiled path, with the same result shape
    truth = MODELS["joint"]()
    got = forces(truth, x[:, :1], v[:, :1])
    np.testing.assert_allclose(got, np.asarray(jax.vmap(truth.force)(jnp.asarray(x[:, :1]), jnp.asarray(v[:, :1]))),
                               rtol=1e-13, atol=1e-9)


def test_public_forces_on_a_grid_under_jit_vmap_and_grad():
    """`gmr.forces`: F = F_r + F_d (or the pair) on (n, dof) states; NumPy for a GlobalModel,
    the compiled path for another model, JAX under jit / vmap / grad (grad against central
    differences), a 1-DOF model on (n,) arrays, v None = 0, and a clear error on bad shapes."""
    model = _chain()
    x, v, _, _ = _states(3, 17)
    x, v = np.asarray(x), np.asarray(v)
    fr, fd = g.forces(model, x, v, parts=True)
    np.testing.assert_allclose(fr, np.asarray(jax.vmap(model.restoring)(jnp.asarray(x))), rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(fd, np.asarray(jax.vmap(model.damping)(jnp.asarray(x), jnp.asarray(v))),
                               rtol=1e-13, atol=1e-12)
    np.testing.assert_array_equal(g.forces(model, x, v), fr + fd)
    np.testing.assert_array_equal(g.forces(model, x), fr)  # v = 0: the restoring force alone
    # under jit: the same numbers, as JAX arrays
    got = jax.jit(lambda x, v: g.forces(model, x, v))(x, v)
    assert isinstance(got, jax.Array)
    np.testing.assert_allclose(np.asarray(got), fr + fd, rtol=1e-13, atol=1e-12)
    # vmap over models (a traced model): each model's own forces
    scales = jnp.array([0.5, 1.0, 2.0])
    batched = jax.vmap(lambda s: g.forces(eqx.tree_at(lambda m: m.stiffness, model, s * model.stiffness), x))(scales)
    np.testing.assert_allclose(np.asarray(batched), np.asarray(scales)[:, None, None] * fr, rtol=1e-12, atol=1e-12)
    # grad of the energy-like sum of F_r over x against central differences
    fn = lambda x: jnp.sum(g.forces(model, x) ** 2)  # noqa: E731
    gx = np.asarray(jax.grad(fn)(jnp.asarray(x)))
    h, i = 1e-6, (4, 1)
    e = np.zeros_like(x)
    e[i] = h
    fd_i = (float(fn(jnp.asarray(x + e))) - float(fn(jnp.asarray(x - e)))) / (2 * h)
    assert gx[i] == pytest.approx(fd_i, rel=1e-6)
    # another model (a system's truth) goes through the compiled path; a 1-DOF model takes (n,)
    truth = MODELS["joint"]()
    xs = np.linspace(-1.5, 1.5, 7)
    np.testing.assert_allclose(g.forces(truth, xs)[:, 0], np.asarray(jax.vmap(truth.restoring)(jnp.asarray(xs)[:, None]))[:, 0],
                               rtol=1e-13, atol=1e-9)
    with pytest.raises(g.GMRInputError, match=r"\(n, 3\)"):
        g.forces(model, x[:, :2], v[:, :2])
    with pytest.raises(g.GMRInputError, match="mechanical model"):
        g.forces("model.json", x)
