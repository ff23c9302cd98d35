"""The Kresling chain benchmark: bistable truss cells, their chain, and its data."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax
from gmr_jax.systems._kresling import (
    KreslingCell,
    KreslingChain,
    cell_equilibria,
    kresling3,
    kresling5,
    kresling_chain,
)


def _cell(chain: KreslingChain, i: int) -> KreslingCell:
    return jax.tree_util.tree_map(lambda a: a[i], chain.cells)


@pytest.fixture(scope="module", params=["linear", "torque_free"])
def chain(request):
    return kresling_chain([20.0, 32.0, 60.0], [0.04, 0.04, 0.04], twist=request.param)


def test_cells_are_bistable_with_documented_equilibria(chain):
    eq = cell_equilibria(chain)
    L = np.asarray(chain.interwell)
    np.testing.assert_allclose(L, 0.03)
    np.testing.assert_allclose(eq["stable"], np.stack([np.zeros(3), L], axis=1))
    for i in range(3):
        cell = _cell(chain, i)
        xf, xd = eq["stable"][i]
        # both stable states are stress free: zero force, zero energy, positive stiffness
        for x in (xf, xd):
            assert abs(float(cell.force(x))) < 1e-12
            assert abs(float(cell.energy(x))) < 1e-15
        assert np.all(eq["stiffness"][i] > 0)
        # exactly one saddle between them, with negative stiffness and a positive barrier
        xu = eq["unstable"][i]
        assert xf < xu < xd
        assert abs(float(cell.force(xu))) < 1e-10 * float(eq["stiffness"][i, 0]) * L[i]
        assert float(cell.stiffness(xu)) < 0
        assert eq["barrier"][i] > 0
        np.testing.assert_allclose(eq["barrier"][i], float(cell.energy(xu)), rtol=1e-12)
        xs = jnp.linspace(-0.3 * L[i], 1.3 * L[i], 1999)  # no grid point on a root
        f = np.asarray(jax.vmap(cell.force)(xs))
        assert np.count_nonzero(np.sign(f[1:]) != np.sign(f[:-1])) == 3
    # graded: the folded-state stiffness is what was asked for
    np.testing.assert_allclose(eq["stiffness"][:, 0], [20.0, 32.0, 60.0], rtol=1e-10)


def test_restoring_force_is_the_energy_gradient(chain):
    cell = _cell(chain, 1)
    L = float(cell.interwell)
    h = 1e-7
    for x in np.linspace(-0.2 * L, 1.2 * L, 9):
        fd = (float(cell.energy(x + h)) - float(cell.energy(x - h))) / (2 * h)
        np.testing.assert_allclose(float(cell.force(x)), fd, rtol=1e-6, atol=1e-9)


def test_torque_free_twist_is_torque_free():
    cell = _cell(kresling_chain([20.0], [0.04], twist="torque_free"), 0)
    L = float(cell.interwell)
    dU = jax.grad(cell.truss_energy, argnums=1)
    for x in np.linspace(-0.2 * L, 1.2 * L, 7):
        phi = cell.twist_angle(x)
        assert abs(float(dU(cell.h_folded + x, phi))) < 1e-12
    # and is not the linear guide (that one needs a torque away from the wells)
    lin = eqx.tree_at(lambda c: c.twist, cell, "linear")
    assert abs(float(lin.twist_angle(0.5 * L) - cell.twist_angle(0.5 * L))) > 1e-3


def test_jit_vmap_grad(chain):
    x = jnp.array([0.001, 0.015, 0.029])
    v = jnp.array([0.01, -0.02, 0.03])
    f = eqx.filter_jit(lambda m, x, v: m.force(x, v))(chain, x, v)
    np.testing.assert_allclose(np.asarray(f), np.asarray(chain.force(x, v)), rtol=1e-12)
    # vmap over states
    xs = jnp.stack([x, 2 * x, 0.5 * x])
    fs = jax.vmap(chain.restoring)(xs)
    np.testing.assert_allclose(np.asarray(fs[1]), np.asarray(chain.restoring(2 * x)), rtol=1e-12)
    # grad with respect to the state: the tangent stiffness matrix is diagonal
    jac = jax.jacfwd(chain.restoring)(x)
    np.testing.assert_allclose(np.asarray(jac - jnp.diag(jnp.diag(jac))), 0.0, atol=1e-12)
    cell = _cell(chain, 2)
    h = 1e-7
    fd = (float(cell.force(x[2] + h)) - float(cell.force(x[2] - h))) / (2 * h)
    np.testing.assert_allclose(float(jac[2, 2]), fd, rtol=1e-5)
    # grad with respect to parameters (e.g. for design or model updating)
    def total(m):
        return jnp.sum(m.restoring(x) ** 2)

    g = eqx.filter_grad(total)(chain)
    eps = 1e-6
    bumped = eqx.tree_at(lambda m: m.cells.k_b, chain, chain.cells.k_b * jnp.array([1.0, 1.0, 1.0 + eps]))
    fd = (float(total(bumped)) - float(total(chain))) / (eps * float(chain.cells.k_b[2]))
    np.testing.assert_allclose(float(g.cells.k_b[2]), fd, rtol=1e-4)


def test_accelerations_follow_the_chain_equation(chain):
    x = jnp.array([0.001, 0.015, 0.029])
    v = jnp.array([0.01, -0.02, 0.03])
    xdd = chain.accelerations(x, v, jnp.asarray(0.3), jnp.zeros(3))
    a = chain.absolute_accelerations(xdd, jnp.asarray(0.3))
    m = np.asarray(chain.masses)
    ha = np.cumsum((m * np.asarray(a))[::-1])[::-1]
    np.testing.assert_allclose(ha + np.asarray(chain.force(x, v)), 0.0, atol=1e-12)


def test_systems():
    for make, d in ((kresling5, 5), (kresling3, 3)):
        s = make()
        assert s.equilibria.shape == (2, d)
        np.testing.assert_allclose(s.equilibria[0], 0.0)
        np.testing.assert_allclose(s.equilibria[1], np.asarray(s.truth.interwell))
        assert s.x_range.shape == (d, 2) and s.v_range.shape == (d, 2)
        assert np.all(s.x_range[:, 0] < 0) and np.all(s.x_range[:, 1] > s.equilibria[1])
        assert s.orders == {"gmr": (5, 5), "gmc": (5, 5)}
        assert s.truth.topology == "chain" and s.truth.n_dof == d
        # the equilibria are equilibria of the chain
        for e in s.equilibria:
            np.testing.assert_allclose(np.asarray(s.truth.restoring(jnp.asarray(e))), 0.0, atol=1e-12)
    # cells stiffen from the base: the base cell is the softest
    k = cell_equilibria(kresling5().truth)["stiffness"][:, 0]
    assert np.all(np.diff(k) > 0)


def test_recordings_are_finite_small_and_shrink_towards_the_tip():
    s = kresling5()
    recs = gmr_jax.make_recordings(s, 5e-4, snr_db=None, duration=12.0)
    L = np.asarray(s.truth.interwell)
    assert len(recs) == 2
    for r, e in zip(recs, s.equilibria):
        for sig in (r.x, r.v, r.a, r.base_acc):
            assert np.all(np.isfinite(sig))
        ratio = 0.5 * np.ptp(r.x, axis=0) / L
        assert np.all(ratio < 0.15) and np.all(ratio > 1e-3)  # stays in its well: small vibrations
        assert ratio[0] == ratio.max() and ratio[-1] == ratio.min()
        np.testing.assert_allclose(r.x.mean(axis=0), e, atol=0.05 * L.min())
    np.testing.assert_allclose(recs[0].masses, np.asarray(s.truth.masses))


def test_builder_rejects_impossible_geometry():
    with pytest.raises(ValueError):
        kresling_chain([20.0], [0.04], radius=0.02, h_folded=0.02, h_deployed=0.05)
    with pytest.raises(ValueError):
        kresling_chain([20.0], [0.04], h_folded=0.05, h_deployed=0.02)
    with pytest.raises(ValueError):
        KreslingCell(0.05, 0.02, 0.05, 1.0, 1.0, twist="helical")
