"""The native basin kernel (`_basins/_native.py`): a C kernel generated from the model, checked
against the model's own equations, the XLA lanes path, scipy, and for its fallbacks."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import gmr_jax as g
from gmr_jax._basins import _native
from gmr_jax._basins._sweep import SweepSettings, basin_map
from gmr_jax._basins._wells import stable_wells
from gmr_jax._simulate._inputs import HalfSineBase, HalfSineTip

pytestmark = pytest.mark.skipif(_native.compiler() is None, reason="no C compiler: the native kernel cannot be built")


def chain(damping=0.5, topology="chain"):
    terms = []
    for i, (k1, k3) in enumerate([(-30.0, 1e5), (-60.0, 2e5), (-45.0, 1.5e5)]):
        terms += [{"dof": i, "physics": "stiffness", "order": 1, "coefficient": k1},
                  {"dof": i, "physics": "stiffness", "order": 3, "coefficient": k3},
                  {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": damping}]
    return g.from_terms([0.05, 0.05, 0.04], terms, topology)


def rich(topology, sign_eps=0.0):
    """Every family of the library: even and odd stiffness, sgn(v), v, sgn(v) v^2, x^2 v."""
    terms = [{"dof": i, "physics": p, "order": o, "coefficient": c}
             for i in range(3) for p, o, c in (("stiffness", 1, -20.0 - i), ("stiffness", 3, 3e4), ("stiffness", 2, 7.0),
                                               ("stiffness", 0, 0.01), ("velocity_damping", 1, 0.4),
                                               ("velocity_damping", 0, 0.05), ("velocity_damping", 2, 0.3),
                                               ("velocity_damping", 3, 0.2), ("position_damping", 2, 11.0))]
    m = g.from_terms([0.05, 0.04, 0.03], terms, topology)
    return m.with_sign_eps(sign_eps) if sign_eps else m


@pytest.mark.parametrize("sign_eps", [0.0, 0.01])
@pytest.mark.parametrize("topology", ["chain", "independent"])
@pytest.mark.parametrize("load", ["tip", "base"])
def test_kernel_field_is_the_model_equations(topology, load, sign_eps):
    """The generated right-hand side equals `GlobalModel.accelerations` under the half-sine,
    also after the switch-off (load 0) and with the sgn smoothed to tanh."""
    import ctypes

    m = rich(topology, sign_eps)
    lib = _native.kernel(m, SweepSettings(load=load))
    rng = np.random.default_rng(0)
    n = 64
    x, v = rng.normal(0, 0.03, (n, 3)), rng.normal(0, 0.5, (n, 3))
    v[:4] = 0.0  # sgn(0) = 0
    f, a = rng.uniform(0.5, 3, n), rng.uniform(0.1, 2, n)
    t = rng.uniform(0.0, 1.5, n) / f  # before and after t_off = 1/(2f)
    y = np.ascontiguousarray(np.concatenate([x, v], axis=1))
    out = np.zeros_like(y)
    dp = lambda z: np.ascontiguousarray(z, float).ctypes.data_as(ctypes.POINTER(ctypes.c_double))  # noqa: E731
    keep = [np.ascontiguousarray(np.asarray(z), float) for z in (m.stiffness, m.velocity_damping,
                                                                  m.position_damping, m.masses)]
    toff = 0.5 / f
    lib.gmr_field(n, dp(t), dp(y), dp(f), dp(a), dp(toff), *(dp(k) for k in keep), dp(out))
    src = HalfSineTip if load == "tip" else HalfSineBase
    want = np.stack([np.asarray(m.accelerations(x[k], v[k], *src(f[k], a[k], n_dof=3)(t[k]))) for k in range(n)])
    np.testing.assert_array_equal(out[:, :3], v)
    np.testing.assert_allclose(out[:, 3:], want, rtol=1e-12, atol=1e-10)


def _grid():
    return np.linspace(0.3, 4.5, 9), np.linspace(0.2, 2.8, 7)


@pytest.mark.parametrize("topology", ["chain", "independent"])
@pytest.mark.parametrize("load", ["tip", "base"])
def test_native_equals_the_lanes_path_point_by_point(topology, load):
    """The same pair and tolerances; the kernel's integral controller may shrink an accepted step
    where diffrax's PIDController keeps it, so step counts differ by a few per cent and final
    states to well inside the tolerance: the same maps and codes."""
    m = chain(topology=topology)
    wells = stable_wells(m, [[-0.05, 0.05]] * 3)
    f, A = _grid()
    if load == "base":
        A = A * 40.0  # m/s^2
    nat = basin_map(m, f, A, wells, settings=SweepSettings(batching="native", load=load))
    lan = basin_map(m, f, A, wells, settings=SweepSettings(batching="lanes", load=load))
    assert nat.stats["batching"] == "native" and lan.stats["batching"] == "lanes"
    nv, lv = nat.value, lan.value
    assert len(set(np.asarray(nv.config).ravel().tolist())) >= 2  # the grid reaches several configurations
    np.testing.assert_array_equal(np.asarray(nv.config), np.asarray(lv.config))
    np.testing.assert_array_equal(np.asarray(nv.result), np.asarray(lv.result))
    np.testing.assert_allclose(np.asarray(nv.x_final), np.asarray(lv.x_final), atol=1e-6)
    ns, ls = np.asarray(nv.steps), np.asarray(lv.steps)
    assert np.all(np.abs(ns - ls) <= 0.15 * ls + 3) and abs(ns.mean() / ls.mean() - 1) < 0.08


def test_native_final_states_agree_with_scipy():
    """An independent integrator: scipy's DOP853 at rtol 1e-11 on the chain's equations written
    out in NumPy (not the model's code), for a few points of the grid."""
    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 3)
    f, A = np.array([0.4, 1.3, 3.1]), np.array([0.3, 1.1, 2.4])
    bm = basin_map(m, f, A, wells, settings=SweepSettings(batching="native")).value
    k1, k3 = np.array([-30.0, -60.0, -45.0]), np.array([1e5, 2e5, 1.5e5])
    mass = np.array([0.05, 0.05, 0.04])

    def rhs(t, y, fq, aq):
        x, v = y[:3], y[3:]
        force = k1 * x + k3 * x**3 + 0.5 * v
        p = aq * np.sin(2 * np.pi * fq * t) if t <= 0.5 / fq else 0.0
        load = np.array([0.0, 0.0, p])
        acc = (load - force + np.append(force[1:], 0.0)) / mass  # absolute accelerations of the masses
        return np.concatenate([v, acc - np.concatenate([[0.0], acc[:-1]])])

    for i, aq in enumerate(A):
        for j, fq in enumerate(f):
            y0 = np.concatenate([np.asarray(wells)[:, 0], np.zeros(3)])
            t_off = 0.5 / fq
            s1 = solve_ivp(rhs, (0, t_off), y0, method="DOP853", rtol=1e-11, atol=1e-13, args=(fq, aq))
            s2 = solve_ivp(rhs, (t_off, t_off + 10.0), s1.y[:, -1], method="DOP853", rtol=1e-11, atol=1e-13,
                           args=(fq, aq))
            np.testing.assert_allclose(np.asarray(bm.x_final[i, j]), s2.y[:3, -1], atol=2e-5)


def test_one_thread_and_many_give_identical_answers_and_coefficients_reuse_the_kernel():
    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 3)
    f, A = _grid()
    ff, aa = (z.ravel() for z in np.meshgrid(f, A))
    span = np.nanmax(wells, 1) - np.nanmin(wells, 1)
    centre = 0.5 * (np.nanmax(wells, 1) + np.nanmin(wells, 1))
    st = SweepSettings()
    one = _native.native_final_states(m, st, wells[:, 0], ff, aa, centre, span, n_threads=1)
    many = _native.native_final_states(m, st, wells[:, 0], ff, aa, centre, span, n_threads=3)
    for a, b in zip(one, many):
        np.testing.assert_array_equal(a, b)
    built = len(_native._loaded)
    import equinox as eqx

    m2 = eqx.tree_at(lambda q: q.stiffness, m, m.stiffness * 1.02)
    other = _native.native_final_states(m2, SweepSettings(settle_time=4.0), wells[:, 0], ff, aa, centre, span)
    assert len(_native._loaded) == built  # new coefficients and settings: the same kernel
    assert not np.array_equal(other[0], one[0])


def test_diverged_and_step_budget_are_flagged_like_lanes():
    soft = g.from_terms([0.05] * 3, [{"dof": i, "physics": "stiffness", "order": 3, "coefficient": -1e3}
                                     for i in range(3)], "chain")
    wells = stable_wells(chain(), [[-0.05, 0.05]] * 3)
    bm = basin_map(soft, [1.0], [50.0], wells, settings=SweepSettings(batching="native")).value
    assert int(bm.result[0, 0]) == g.RESULTS.diverged._value and int(bm.config[0, 0]) == -1


def test_native_is_opt_in_and_says_why_it_cannot_run(monkeypatch):
    import diffrax as dfx
    import jax

    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 3)
    assert basin_map(m, [1.0], [1.0], wells).stats["batching"] == "lanes"  # the default on every device
    native = SweepSettings(batching="native")
    sol = basin_map(m, [1.0], [1.0], wells, settings=native)
    assert sol.stats["batching"] == "native" and sol.stats["threads"] == _native.threads()
    assert basin_map(m, [1.0], [1.0], wells, settings=native, devices=jax.devices()[:1]).stats["threads"] == 1
    with pytest.raises(g.GMRInputError, match="native.*float64"):
        basin_map(m, [1.0], [1.0], wells, settings=SweepSettings(batching="native", precision="float32"))
    with pytest.raises(g.GMRInputError, match="Kvaerno5"):
        basin_map(m, [1.0], [1.0], wells, settings=SweepSettings(batching="native", solver=dfx.Kvaerno5()))
    monkeypatch.setenv("GMR_NATIVE", "0")
    with pytest.raises(g.GMRInputError, match="GMR_NATIVE"):
        basin_map(m, [1.0], [1.0], wells, settings=native)


def test_a_compiler_that_fails_is_named_and_the_default_does_not_need_one(monkeypatch, tmp_path):
    monkeypatch.setenv("CC", "false")
    monkeypatch.setenv("GMR_CACHE_DIR", str(tmp_path))  # no kernel already on disk
    monkeypatch.setattr(_native, "_loaded", {})
    monkeypatch.setattr(_native, "_by_structure", {})
    m = chain(damping=0.37)
    wells = stable_wells(m, [[-0.05, 0.05]] * 3)
    sol = basin_map(m, [1.0], [1.0], wells, settings=SweepSettings(solver="dopri5"))
    assert sol.stats["batching"] == "lanes"
    with pytest.raises(g.GMRInputError, match="did not build"):
        basin_map(m, [1.0], [1.0], wells, settings=SweepSettings(solver="dopri5", batching="native"))


def test_a_compiler_without_the_tuned_flags_builds_the_portable_kernel(monkeypatch, tmp_path):
    """A compiler that refuses the tuned flags (-march=native on some compilers) still gives a
    kernel, built with the portable ones, and the same answers."""
    monkeypatch.setenv("GMR_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(_native, "FLAGS", _native.FLAGS + ("-fno-such-flag-for-any-compiler",))
    monkeypatch.setattr(_native, "_loaded", {})  # nothing built in this process either
    monkeypatch.setattr(_native, "_by_structure", {})
    m = chain(damping=0.41)
    wells = stable_wells(m, [[-0.05, 0.05]] * 3)
    f, A = _grid()
    nat = basin_map(m, f, A, wells, settings=SweepSettings(batching="native")).value
    assert len(list((tmp_path / "gmr_native").glob("*.so"))) == 1
    lan = basin_map(m, f, A, wells, settings=SweepSettings(batching="lanes")).value
    np.testing.assert_array_equal(np.asarray(nat.config), np.asarray(lan.config))
    np.testing.assert_allclose(np.asarray(nat.x_final), np.asarray(lan.x_final), atol=1e-6)
