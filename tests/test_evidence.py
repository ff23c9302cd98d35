"""The reconstruction as one probabilistic model (`coordination="evidence"`, `reconstruct_arrays`):
what it recovers, whether its uncertainty is honest, and the transforms it promises."""

import dataclasses
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as gmr


def _fit(recs, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gmr.GMRDataWarning)
        return gmr.reconstruct(recs, coordination="evidence", **kw)


@pytest.fixture(scope="module")
def joint():
    return gmr.systems.bistable_joint("position_dependent")


def test_cubic_law_recovered_within_its_standard_errors(joint):
    # the truth is inside the model family: its coefficients sit within the printed standard errors
    outside = 0
    for seed in (0, 1):
        recs = gmr.systems.make_recordings(joint, np.deg2rad(1.0), snr_db=40.0, seed=seed, duration=4.0)
        model = _fit(recs).value
        k = np.asarray(model.stiffness[0])
        se = np.asarray(model.stderr["stiffness"][0])
        for order, true in ((1, -2244.0), (3, 1755.0)):
            assert abs(k[order] - true) < 0.02 * abs(true)
            outside += abs(k[order] - true) > 2.0 * se[order]
        assert gmr.metrics.restoring_error(model, joint.truth, 0, joint.x_range[0]) < 0.01
    assert outside <= 1


def test_standard_errors_and_band_are_one_covariance(joint):
    recs = gmr.systems.make_recordings(joint, np.deg2rad(1.0), snr_db=40.0, seed=2, duration=4.0)
    sol = _fit(recs)
    model = sol.value
    se = np.sqrt(np.diagonal(np.asarray(model.covariance[0])))
    k = model.stiffness.shape[1]
    np.testing.assert_allclose(np.asarray(model.stderr["stiffness"][0]), se[:k], rtol=1e-12)
    assert isinstance(sol.stats["settings"], gmr.ReconstructSettings)
    report = sol.stats["dofs"][0].stats
    assert report["coordination"] == "evidence"
    assert 1 <= report["degree"] <= sol.stats["settings"].degree
    assert abs(sum(report["degree_weight"]) - 1.0) < 1e-9


def test_band_covers_the_truth_between_three_wells():
    nes = gmr.systems.tristable_nes()
    recs = gmr.systems.make_recordings(nes, 5e-4, snr_db=40.0, seed=1)
    model = _fit(recs).value
    eq = nes.equilibria[:, 0]
    band = gmr.metrics.band_coverage(model, nes.truth, 0, (eq.min(), eq.max()), n=201, level=0.95)
    assert band.share >= 0.9
    assert band.width < 0.05  # and sharp enough to use


def test_displacement_only_records_need_no_differentiated_target(joint):
    # v and a removed: the inertia enters the weak form through the test function's phi''
    recs = gmr.systems.make_recordings(joint, np.deg2rad(1.0), snr_db=50.0, seed=0, duration=4.0)
    x_only = [dataclasses.replace(r, v=None, a=None) for r in recs]
    model = _fit(x_only).value
    assert gmr.metrics.restoring_error(model, joint.truth, 0, joint.x_range[0]) < 0.01


def _arrays(joint, seed=0):
    recs = gmr.systems.make_recordings(joint, np.deg2rad(1.0), snr_db=50.0, seed=seed, duration=2.0)
    x = np.stack([r.x[:, 0] for r in recs])
    v = np.stack([r.v[:, 0] for r in recs])
    p = np.stack([-r.a[:, 0] for r in recs])  # unit inertia, absolute acceleration measured
    return (jnp.asarray(x), jnp.asarray(v), jnp.asarray(p), jnp.zeros_like(jnp.asarray(x)),
            jnp.ones(x.shape, bool), jnp.arange(2), recs[0].dt)


SETTINGS = gmr.ReconstructSettings(degree=5, damping_order=2)


def _k1_plus_k3(joint_arrays, scale):
    x, v, p, s, mask, well, dt = joint_arrays
    coef, _, _ = gmr.reconstruct_arrays(x, v, p * scale, s, mask, well, n_wells=2, width=31, dt=dt,
                                        settings=SETTINGS, throw=False)
    return coef[1] + coef[3]


def test_reconstruct_arrays_jit_vmap_and_gradients(joint):
    arrays = _arrays(joint)
    f = jax.jit(lambda c: _k1_plus_k3(arrays, c))
    value = float(f(1.0))
    assert abs(value - (-2244.0 + 1755.0)) < 5.0
    rev = float(jax.jit(jax.grad(lambda c: _k1_plus_k3(arrays, c)))(1.0))
    fwd = float(jax.jit(lambda c: jax.jvp(lambda c_: _k1_plus_k3(arrays, c_), (c,), (1.0,))[1])(1.0))
    h = 1e-4
    central = (float(f(1.0 + h)) - float(f(1.0 - h))) / (2 * h)
    # the target scales the whole law: d(k1 + k3)/dc = k1 + k3
    np.testing.assert_allclose(rev, fwd, rtol=1e-6)
    np.testing.assert_allclose(rev, central, rtol=1e-4)
    np.testing.assert_allclose(rev, value, rtol=1e-4)

    x, v, p, s, mask, well, dt = arrays
    batch = jnp.stack([p, 2.0 * p])
    coefs = jax.vmap(lambda pp: gmr.reconstruct_arrays(x, v, pp, s, mask, well, n_wells=2, width=31, dt=dt,
                                                       settings=SETTINGS, throw=False)[0])(batch)
    np.testing.assert_allclose(np.asarray(coefs[1]), 2.0 * np.asarray(coefs[0]), rtol=1e-4, atol=1e-6)


def _cubic_chain(saddles, stiffness=(20.0, 40.0), wells=(0.03, 0.025), masses=(0.04, 0.04)):
    """A chain of bistable cubic cells F_i = c_i x (x - s_i)(x - L_i), trained around 0-0 and 1-1."""
    terms = []
    for i, (k, L, s, m) in enumerate(zip(stiffness, wells, saddles, masses)):
        c = k / (s * L)
        terms += [{"dof": i, "physics": "stiffness", "order": 1, "coefficient": c * s * L},
                  {"dof": i, "physics": "stiffness", "order": 2, "coefficient": -c * (s + L)},
                  {"dof": i, "physics": "stiffness", "order": 3, "coefficient": c},
                  {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": 0.04 * np.sqrt(k * m)}]
    L = np.asarray(wells)
    return gmr.systems.System(
        name="cubic2", truth=gmr.from_terms(list(masses), terms, "chain"), equilibria=np.stack([np.zeros(2), L]),
        sweep=(0.5, 10.0), duration=8.0, fs=1000.0, x_range=np.stack([-0.1 * L, 1.1 * L], axis=1),
        v_range=np.tile([[-0.1, 0.1]], (2, 1)), orders={"gmr": (5, 1), "gmc": (5, 1)}, description="2-cell cubic chain",
        units=("x [m]", "x' [m/s]", "F [N]"))


@pytest.mark.parametrize("saddles, one_design", [((0.012, 0.01), True), ((0.006, 0.0125), False)])
def test_cells_share_a_law_only_where_they_are_one_design(saddles, one_design):
    # same saddle ratio s/L: one design, scaled; otherwise each cell keeps its own law
    chain = _cubic_chain(saddles)
    recs = gmr.systems.make_recordings(chain, 3e-4, snr_db=40.0, seed=0)
    sol = _fit(recs, settings=gmr.ReconstructSettings(damping_order=1), designs=[0, 0])
    spread = max(d.stats["design_spread"] for d in sol.stats["dofs"])
    assert spread < 0.1 if one_design else spread > 1.0
    for i in range(2):
        st = sol.stats["dofs"][i].stats
        assert st["design"] == [0, 1]
        eq = chain.equilibria[:, i]
        band = gmr.metrics.band_coverage(sol.value, chain.truth, i, (eq.min(), eq.max()), n=101, level=0.95)
        assert band.share >= 0.9
        assert gmr.metrics.restoring_error(sol.value, chain.truth, i, chain.x_range[i]) < 0.01


def test_cells_share_a_law_only_when_labelled_one_design():
    chain = _cubic_chain((0.012, 0.01))
    recs = gmr.systems.make_recordings(chain, 3e-4, snr_db=40.0, seed=0)
    sol = _fit(recs, settings=gmr.ReconstructSettings(damping_order=1))
    assert all("design" not in d.stats for d in sol.stats["dofs"])
    with pytest.raises(gmr.GMRInputError, match="one integer label per DOF"):
        _fit(recs, designs=[0, 0, 0])
    with pytest.raises(gmr.GMRInputError, match="evidence"):
        gmr.reconstruct(recs, coordination="gls", designs=[0, 0])
    with pytest.raises(gmr.GMRInputError, match="damping_order"):  # two settings of one option
        gmr.reconstruct(recs, gmr.Library(5, 2), settings=gmr.ReconstructSettings(tests=4))


def test_test_functions_of_one_window_are_uncorrelated():
    from gmr_jax._coordination._bayes import test_functions

    tf = test_functions(60, 4)
    for k in (0, 2):  # white noise in the force (psi) and in x (psi'')
        gram = tf[:, k] @ tf[:, k].T
        sd = np.sqrt(np.diag(gram))
        np.testing.assert_allclose(gram / np.outer(sd, sd), np.eye(4), atol=1e-3)  # correlations
    n = np.arange(60) - 29.5
    for psi, d1, d2 in tf:  # summation by parts exact on a constant offset and a trend
        np.testing.assert_allclose([d1 @ n**0, d2 @ n**0, d2 @ n], 0.0, atol=1e-12)
        np.testing.assert_allclose(d1 @ n, -psi.sum(), atol=1e-12)


def _steady_tones(system, snr_db, seed=0, fs=100.0, settle=60.0, duration=60.0, amplitude=0.03):
    """The steady response to one base sine per well at 0.8 x the well's natural frequency."""
    ts = jnp.arange(int((settle + duration) * fs) + 1) / fs
    keep = np.asarray(ts) >= settle
    rng = np.random.default_rng(seed)
    recs = []
    for i, e in enumerate(system.equilibria[:, 0]):
        k = float(jax.grad(lambda x: system.truth.restoring(jnp.atleast_1d(x))[0])(e))
        exc = gmr.BaseSine(jnp.asarray(amplitude), 0.8 * np.sqrt(k) / (2 * np.pi))
        xs, vs = gmr.simulate(system.truth, exc, ts, system.equilibria[i]).value
        base = jax.vmap(lambda t: exc(t)[0])(ts)
        xdd = jax.vmap(lambda x, v, b: system.truth.accelerations(x, v, b, jnp.zeros(1)))(xs, vs, base)
        a = system.truth.absolute_accelerations(xdd, base)
        sig = [gmr.add_noise(np.asarray(z)[keep], snr_db, rng) for z in (xs, vs, a, base)]
        recs.append(gmr.Recording(t=np.asarray(ts)[keep] - settle, x=sig[0], v=sig[1], a=sig[2], base_acc=sig[3],
                                  masses=np.ones(1), name=f"tone{i}"))
    return recs


def test_a_steady_tone_per_well_fixes_the_curvature_between_the_wells():
    # one bump per window averages a steady tone's harmonics away (about 20 % off here)
    arch = gmr.systems.shallow_arch()
    sol = _fit(_steady_tones(arch, 50.0), settings=gmr.ReconstructSettings(tests=4))
    assert gmr.metrics.restoring_error(sol.value, arch.truth, 0, arch.x_range[0]) < 0.05
    eq = arch.equilibria[:, 0]
    band = gmr.metrics.band_coverage(sol.value, arch.truth, 0, (eq.min(), eq.max()), n=101, level=0.95)
    assert band.share >= 0.9
