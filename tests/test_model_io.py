import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g


def chain_model():
    terms = [
        {"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -30.0},
        {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1e5},
        {"dof": 1, "physics": "stiffness", "order": 1, "coefficient": 50.0},
        {"dof": 1, "physics": "velocity_damping", "order": 0, "coefficient": 0.031},
        {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.2},
        {"dof": 1, "physics": "position_damping", "order": 2, "coefficient": 50.0},
    ]
    return g.from_terms([0.1, 0.2], terms, "chain"), terms


def test_json_round_trip_exact(tmp_path):
    m, terms = chain_model()
    m = g.GlobalModel(m.masses, m.stiffness * (1 + 1e-13 * np.pi), m.velocity_damping,
                      m.position_damping, m.topology)
    p = tmp_path / "m.json"
    g.save_model(m, p)
    d = json.loads(p.read_text())
    assert d["format"] == "gmr-model/1" and d["topology"] == "chain" and d["masses"] == [0.1, 0.2]
    m2 = g.load_model(p)
    for a, b in [(m.stiffness, m2.stiffness), (m.velocity_damping, m2.velocity_damping),
                 (m.position_damping, m2.position_damping), (m.masses, m2.masses)]:
        assert np.array_equal(np.asarray(a), np.asarray(b))
    assert m2.terms() == m.terms()


@pytest.mark.parametrize("content,msg", [
    ("{", "not valid JSON"),
    ('{"format": "other"}', "not a gmr-model/1"),
    ('{"format": "gmr-model/1", "masses": [-1], "terms": []}', "positive"),
    ('{"format": "gmr-model/1", "masses": [1], "terms": [{"dof": 0, "physics": "magic", "order": 1, "coefficient": 1}]}', "unknown physics"),
    ('{"format": "gmr-model/1", "masses": [1], "terms": [{"dof": 3, "physics": "stiffness", "order": 1, "coefficient": 1}]}', "dof"),
])
def test_bad_model_files(tmp_path, content, msg):
    p = tmp_path / "bad.json"
    p.write_text(content)
    with pytest.raises(g.GMRInputError, match=msg):
        g.load_model(p)


def test_chain_equation_of_motion_matches_contract():
    m, _ = chain_model()
    x = jnp.array([0.01, -0.02])
    v = jnp.array([0.3, -0.1])
    base = 0.7
    force = jnp.array([0.05, 0.4])
    xdd = m.accelerations(x, v, base, force)
    a = m.absolute_accelerations(xdd, jnp.asarray(base))
    # (H a)_i + F_i = sum_{k>=i} force_k
    ha = jnp.array([m.masses[0] * a[0] + m.masses[1] * a[1], m.masses[1] * a[1]])
    rhs = jnp.array([force[0] + force[1], force[1]])
    np.testing.assert_allclose(ha + m.force(x, v), rhs, rtol=1e-12)


def test_independent_equation_and_transforms():
    m, terms = chain_model()
    mi = g.from_terms([0.1, 0.2], terms, "independent")
    x, v = jnp.array([0.01, -0.02]), jnp.array([0.3, -0.1])
    xdd = mi.accelerations(x, v, 0.5, jnp.zeros(2))
    np.testing.assert_allclose(mi.masses * (xdd + 0.5) + mi.force(x, v), 0.0, atol=1e-12)
    f = jax.jit(lambda x, v: mi.force(x, v))
    np.testing.assert_allclose(f(x, v), mi.force(x, v))
    batch = jax.vmap(mi.force)(jnp.stack([x, 2 * x]), jnp.stack([v, v]))
    np.testing.assert_allclose(batch[0], mi.force(x, v))
    # grad wrt the coefficients vs finite differences (smooth sign)
    ms = mi.with_sign_eps(1e-2)

    def loss(k):
        return jnp.sum(g.GlobalModel(ms.masses, k, ms.velocity_damping, ms.position_damping,
                                     ms.topology, ms.sign_eps).force(x, v) ** 2)

    gk = jax.grad(loss)(ms.stiffness)
    e = jnp.zeros_like(ms.stiffness).at[0, 3].set(1e-3)
    fd = (loss(ms.stiffness + e) - loss(ms.stiffness - e)) / 2e-3
    np.testing.assert_allclose(gk[0, 3], fd, rtol=1e-6)


def test_equations_readable():
    m, _ = chain_model()
    eq = m.equations()
    assert eq[0] == "F_0(x, v) = -30 x + 1e+05 x^3 + 0.2 v"
    assert "0.031 sgn(v)" in eq[1] and "50 x^2*v" in eq[1]


def test_save_model_from_a_solution_keeps_metadata(tmp_path):
    model = g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": 2.0}])
    sol = g.Solution(value=model, result=g.RESULTS.successful,
                     stats={"method": "GMR", "library": g.Library(3, 2), "warnings": ("a warning",),
                            "training": {"S1": {"r2": [0.99], "nrmse": [0.1]}}})
    g.save_model(sol, tmp_path / "m.json", data_range=[[-1.0, 1.0]])
    d = json.loads((tmp_path / "m.json").read_text())
    assert d["method"] == "GMR" and d["library"] == {"r": 3, "d": 2} and d["warnings"] == ["a warning"]
    assert d["training"]["S1"]["r2"] == [0.99] and d["data_range"] == [[-1.0, 1.0]]
    assert g.load_model(tmp_path / "m.json").stiffness.tolist() == model.stiffness.tolist()
    with pytest.raises(g.GMRInputError, match="save_model writes a GlobalModel"):
        g.save_model({"not": "a model"}, tmp_path / "x.json")
