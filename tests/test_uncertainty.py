"""Uncertainty of the global model (issue 15): the covariance on the model and in its file, the
force band (exact linear propagation) against Monte Carlo, sampled models under jit/vmap/grad,
the calibrated covariance of a reconstruction, and basin maps drawn from the distribution."""

import json
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._model._model import coefficient_index, coefficients


def _model(topology="independent"):
    """Two DOFs: bistable cubic springs with mixed damping and a full, correlated covariance."""
    terms = []
    for i, (k1, k3) in enumerate([(-1.0, 1.0), (-2.0, 1.5)]):
        terms += [{"dof": i, "physics": "stiffness", "order": 1, "coefficient": k1},
                  {"dof": i, "physics": "stiffness", "order": 3, "coefficient": k3},
                  {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": 0.1},
                  {"dof": i, "physics": "velocity_damping", "order": 3, "coefficient": 0.02},
                  {"dof": i, "physics": "position_damping", "order": 2, "coefficient": 0.3}]
    rng = np.random.default_rng(0)
    cov = []
    keys = [["stiffness", 0], ["stiffness", 1], ["stiffness", 3], ["velocity_damping", 1],
            ["velocity_damping", 3], ["position_damping", 2]]
    for i in range(2):
        a = rng.normal(size=(6, 6)) * np.array([0.02, 0.05, 0.03, 0.01, 0.004, 0.02])[:, None]
        cov.append({"dof": i, "terms": keys, "matrix": (a @ a.T).tolist()})
    return g.from_terms([1.0, 2.0], terms, topology, covariance=cov)


def test_band_is_exact_linear_propagation_and_matches_samples():
    m = _model()
    x, v = jnp.array([0.7, -1.2]), jnp.array([0.5, -0.8])
    samples = g.sample_models(m, jax.random.key(1), 40_000)
    for part in ("restoring", "damping", "total"):
        band = g.force_band(m, x, v, part=part, level=0.9)
        if part == "restoring":
            f = jax.vmap(lambda s: s.restoring(x))(samples)
            want = m.restoring(x)
        elif part == "damping":
            f = jax.vmap(lambda s: s.damping(x, v))(samples)
            want = m.damping(x, v)
        else:
            f = jax.vmap(lambda s: s.force(x, v))(samples)
            want = m.force(x, v)
        np.testing.assert_allclose(band.mean, want, rtol=1e-12)
        sd = np.asarray(f).std(axis=0)
        np.testing.assert_allclose(band.stderr, sd, rtol=0.03)
        lo, hi = np.quantile(np.asarray(f), [0.05, 0.95], axis=0)
        np.testing.assert_allclose(band.lower, lo, atol=0.05 * float(np.max(sd)))
        np.testing.assert_allclose(band.upper, hi, atol=0.05 * float(np.max(sd)))
    # the analytic variance is phi' Sigma phi
    phi = np.array([1.0, 0.7, 0.49, 0.343])
    cov = np.asarray(m.covariance)[0][:4, :4]
    np.testing.assert_allclose(g.force_band(m, x).stderr[0], np.sqrt(phi @ cov @ phi), rtol=1e-12)


def test_band_under_jit_vmap_and_grad():
    m = _model()
    xs = jnp.stack([jnp.linspace(-1.5, 1.5, 9), jnp.linspace(-1.0, 1.0, 9)], axis=1)
    vs = jnp.ones_like(xs) * 0.3
    eager = jax.vmap(lambda x, v: g.force_band(m, x, v, part="total"))(xs, vs)
    jitted = eqx.filter_jit(jax.vmap(lambda mm, x, v: g.force_band(mm, x, v, part="total"), (None, 0, 0)))(m, xs, vs)
    np.testing.assert_allclose(eager.upper, jitted.upper, rtol=1e-12)
    assert eager.upper.shape == (9, 2)
    # a new level does not recompile (traced)
    f = eqx.filter_jit(eqx.debug.assert_max_traces(lambda mm, lev: g.force_band(mm, xs[0], level=lev).upper,
                                                   max_traces=1))
    assert np.all(f(m, jnp.asarray(0.99)) > f(m, jnp.asarray(0.9)))
    # gradient of the upper bound in x against central differences (also at x = 0)
    for x0 in (jnp.array([0.4, -0.3]), jnp.array([0.0, 0.0])):
        grad = jax.grad(lambda x: jnp.sum(g.force_band(m, x, vs[0], part="total").upper))(x0)
        eps = 1e-6
        fd = [(jnp.sum(g.force_band(m, x0.at[k].add(eps), vs[0], part="total").upper)
               - jnp.sum(g.force_band(m, x0.at[k].add(-eps), vs[0], part="total").upper)) / (2 * eps) for k in range(2)]
        np.testing.assert_allclose(grad, fd, rtol=1e-5, atol=1e-7)
    # samples map under vmap and jit alike
    samples = g.sample_models(m, jax.random.key(0), 8)
    out = eqx.filter_jit(jax.vmap(lambda s: s.force(xs[1], vs[1])))(samples)
    assert out.shape == (8, 2) and np.all(np.isfinite(out))
    one = jax.tree.map(lambda a: a[3] if eqx.is_array(a) else a, samples)
    np.testing.assert_allclose(out[3], one.force(xs[1], vs[1]), rtol=1e-12)
    assert samples.covariance is None and samples.stderr is None


def test_coefficients_without_variance_are_not_sampled():
    m = _model()
    samples = g.sample_models(m, jax.random.key(2), 50)
    # stiffness order 2 has zero variance: every sample keeps it exactly
    np.testing.assert_array_equal(np.asarray(samples.stiffness)[:, :, 2], 0.0)
    assert np.std(np.asarray(samples.stiffness)[:, 0, 3]) > 0


def test_model_file_round_trip_and_old_files(tmp_path):
    m = _model("chain")
    path = tmp_path / "m.json"
    g.save_model(m, path)
    d = json.loads(path.read_text())
    assert d["format"] == "gmr-model/1" and len(d["covariance"]) == 2
    back = g.load_model(path)
    assert back.covariance is not None
    idx_m, idx_b = coefficient_index(m), coefficient_index(back)
    for i in range(2):
        for a, ka in enumerate(idx_m):
            for b, kb in enumerate(idx_m):
                want = float(np.asarray(m.covariance)[i, a, b])
                got = (float(np.asarray(back.covariance)[i, idx_b.index(ka), idx_b.index(kb)])
                       if ka in idx_b and kb in idx_b else 0.0)
                assert got == want
    x = jnp.array([0.3, 1.1])
    np.testing.assert_allclose(g.force_band(back, x).upper, g.force_band(m, x).upper, rtol=1e-14)
    # an old file (no covariance key) still loads, with covariance None; a reader that knows
    # nothing of the key gets the same terms
    del d["covariance"]
    old = g.load_model(d)
    assert old.covariance is None
    np.testing.assert_array_equal(coefficients(old), coefficients(back)[..., : coefficients(old).shape[-1]]
                                  if coefficients(old).shape == coefficients(back).shape else coefficients(old))
    with pytest.raises(g.GMRInputError, match="no covariance"):
        g.force_band(old, x)
    with pytest.raises(g.GMRInputError, match="no covariance"):
        g.sample_models(old, jax.random.key(0), 3)


@pytest.mark.parametrize("bad,match", [
    ("nope", "must be a list"),
    ([{"dof": 0, "terms": [["stiffness", 1]]}], "exactly the keys"),
    ([{"dof": 5, "terms": [["stiffness", 1]], "matrix": [[1.0]]}], "outside"),
    ([{"dof": 0, "terms": [["spring", 1]], "matrix": [[1.0]]}], "physics one of"),
    ([{"dof": 0, "terms": [["stiffness", 1]], "matrix": [[1.0, 0.0]]}], "shape"),
    ([{"dof": 0, "terms": [["stiffness", 1]], "matrix": [[-1.0]]}], "negative variance"),
    ([{"dof": 0, "terms": [["stiffness", 1], ["stiffness", 3]], "matrix": [[1.0, 0.5], [0.2, 1.0]]}], "symmetric"),
    ([{"dof": 0, "terms": [["stiffness", 1], ["stiffness", 1]], "matrix": [[1.0, 0.0], [0.0, 1.0]]}], "twice"),
])
def test_bad_covariance_in_a_file_is_named(tmp_path, bad, match):
    d = {"format": "gmr-model/1", "topology": "independent", "masses": [1.0],
         "terms": [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": 1.0}], "covariance": bad}
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(d))
    with pytest.raises(g.GMRInputError, match=match):
        g.load_model(path)


def test_bad_band_arguments():
    m = _model()
    with pytest.raises(g.GMRInputError, match="part must be"):
        g.force_band(m, jnp.zeros(2), part="inertia")
    with pytest.raises(g.GMRInputError, match="needs the velocities"):
        g.force_band(m, jnp.zeros(2), part="damping")
    # a grid (or a scalar) where one point is taken: named, with the vmap that does it
    with pytest.raises(g.GMRInputError, match=r"x must have shape \(2,\).*got shape \(7, 2\).*jax.vmap"):
        g.force_band(m, jnp.zeros((7, 2)))
    with pytest.raises(g.GMRInputError, match=r"v must have shape \(2,\).*got shape \(\)"):
        g.force_band(m, jnp.zeros(2), 0.0, part="damping")
    with pytest.raises(g.GMRInputError, match="n must be"):
        g.sample_models(m, jax.random.key(0), 0)


def _bistable(var_k1, var_c=1e-4, position=None):
    terms = [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -30.0},
             {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1e5},
             {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.5}]
    if position is not None:  # x^k v terms
        terms += [{"dof": 0, "physics": "position_damping", "order": k, "coefficient": c} for k, c in position.items()]
    cov = [{"dof": 0, "terms": [["stiffness", 1], ["velocity_damping", 1]], "matrix": [[var_k1, 0.0], [0.0, var_c]]}]
    return g.from_terms([0.05], terms, covariance=cov)


def test_feeds_energy_reads_the_damping_over_the_span_of_use():
    from gmr_jax._basins._probability import feeds_energy

    x_range = [[-0.05, 0.05]]
    m = _bistable(1e-6)
    wells = g.stable_wells(m, x_range)
    assert feeds_energy(m, wells, x_range) == []
    # wells at +-0.0173: 0.5 - 20 x^2 v stays positive on the span widened by half (|x| <= 0.035)
    assert feeds_energy(_bistable(1e-6, position={2: -20.0}), wells, x_range) == []
    # ... 0.5 - 1000 x^2 turns negative at |x| > 0.022, inside it
    why = feeds_energy(_bistable(1e-6, position={2: -1000.0}), wells, x_range)
    assert len(why) == 1 and why[0].startswith("DOF 0: its damping feeds energy in")
    # the speed: a fall from the edge of x_range to a well, sqrt(2 (V(0.05) - V(well)) / m) = 2.2; a cubic
    # damping 0.5 v + b3 v^3 turns at |v| = sqrt(0.5 / -b3): inside at b3 = -0.12, beyond at -0.09
    cubic = [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -30.0},
             {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1e5},
             {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.5}]
    for b3, feeds in ((-0.09, False), (-0.12, True)):
        m3 = g.from_terms([0.05], cubic + [{"dof": 0, "physics": "velocity_damping", "order": 3, "coefficient": b3}])
        assert bool(feeds_energy(m3, wells, x_range)) is feeds
    neg = g.from_terms([0.05], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -30.0},
                                {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1e5},
                                {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": -0.1}])
    assert feeds_energy(neg, wells, x_range) != []


def test_basin_probability_on_a_tiny_grid():
    f, A = jnp.array([0.5, 2.0, 4.0]), jnp.array([0.3, 1.5, 2.5])
    settings = g.SweepSettings(settle_time=5.0)
    x_range = [[-0.05, 0.05]]
    # a tight distribution: every sample ends where the model does
    m = _bistable(1e-6)
    sol = g.basin_probability(m, f, A, jax.random.key(0), 3, x_range=x_range, settings=settings)
    bp = sol.value
    want = g.basin_map(m, f, A, g.stable_wells(m, x_range), settings=settings).value.config
    np.testing.assert_array_equal(bp.mean_config, want)
    np.testing.assert_array_equal(bp.most_likely, want)
    np.testing.assert_allclose(bp.confidence, 1.0)
    np.testing.assert_allclose(np.sum(np.asarray(bp.probability), axis=-1), 1.0)
    assert sol.stats["samples_used"] == 3 and sol.stats["samples_other_wells"] == 0
    # a wide one: samples whose k1 turns positive have one well and are counted apart (more are
    # drawn in their place); the rest give probabilities that sum to 1 per point
    wide = _bistable(30.0**2)
    sol = g.basin_probability(wide, f, A, jax.random.key(1), 6, x_range=x_range, settings=settings)
    assert sol.stats["samples_used"] + sol.stats["samples_other_wells"] == sol.stats["samples_drawn"]
    assert sol.stats["samples_other_wells"] >= 1 and sol.stats["samples_non_dissipative"] == 0
    if sol.stats["samples_used"]:
        np.testing.assert_allclose(np.sum(np.asarray(sol.value.probability), axis=-1), 1.0)
    # a damping whose distribution reaches below 0 (c = 0.5 +- 1): those samples feed energy in and
    # are left out, counted apart, and more are drawn until n are used; every sample used dissipates.
    # The key: the first whose 6 draws hold a negative c (the test's teeth, whatever the random stream)
    leaky = _bistable(1e-6, var_c=1.0)

    def draws(key, batches):
        return np.concatenate([np.asarray(g.sample_models(leaky, key if b == 0 else jax.random.fold_in(key, b), 6)
                                          .velocity_damping)[:, 0, 1] for b in range(batches)])

    key = next(k for k in (jax.random.key(i) for i in range(50)) if np.any(draws(k, 1) < 0))
    c = draws(key, 8)
    seen = []
    sol = g.basin_probability(leaky, f, A, key, 6, x_range=x_range, settings=settings,
                              progress=lambda used, n: seen.append(used))
    st = sol.stats
    assert st["samples_used"] == 6 and st["samples_other_wells"] == 0 and st["mean_non_dissipative"] == []
    drawn = st["samples_drawn"]
    assert drawn > 6 and st["samples_non_dissipative"] == int(np.sum(c[:drawn] < 0)) == drawn - 6
    assert len(seen) == drawn and seen[-1] == 6  # progress after every draw, the used count
    # ... and no more than `max_draws`
    sol = g.basin_probability(leaky, f, A, key, 6, x_range=x_range, settings=settings, max_draws=6)
    assert sol.stats["samples_drawn"] == 6 and sol.stats["samples_used"] == 6 - int(np.sum(c[:6] < 0)) < 6
    with pytest.raises(g.GMRInputError, match="max_draws must be >= 1"):
        g.basin_probability(leaky, f, A, key, 6, x_range=x_range, max_draws=0)
    with pytest.raises(g.GMRInputError, match="no covariance"):
        g.basin_probability(g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": 1.0}]),
                            f, A, jax.random.key(0), 2, x_range=x_range)


@pytest.mark.slow  # end to end: data -> reconstruct -> band vs truth -> file -> figure (~20 s cold); the
# band's algebra, transforms and file round trip are tested in the default tier above
def test_reconstructed_model_carries_a_calibrated_covariance(tmp_path):
    s = g.systems.bistable_joint("position_dependent")
    recs = g.systems.make_recordings(s, np.deg2rad(1.0), snr_db=40.0, seed=1, duration=20.0)
    m = g.reconstruct(recs, g.Library(5, 5)).value
    cov = np.asarray(m.covariance)
    p = coefficients(m).shape[-1]
    assert cov.shape == (1, p, p)
    np.testing.assert_allclose(cov, np.swapaxes(cov, 1, 2), rtol=1e-8, atol=1e-12 * np.max(np.abs(cov)))
    assert np.min(np.linalg.eigvalsh(cov[0])) > -1e-9 * np.max(np.diag(cov[0]))
    # the 95 % band holds the true restoring force over the interwell span
    xs = np.linspace(-1.1308, 1.1308, 101)[:, None]
    band = jax.vmap(lambda x: g.force_band(m, x))(jnp.asarray(xs))
    truth = np.asarray(jax.vmap(s.truth.restoring)(jnp.asarray(xs)))
    assert np.mean((truth >= np.asarray(band.lower)) & (truth <= np.asarray(band.upper))) >= 0.9
    assert float(np.median(np.asarray(band.upper - band.lower))) < 0.1 * float(np.max(np.abs(truth)))  # not vacuous
    # and survives the model file
    g.save_model(m, tmp_path / "m.json")
    back = g.load_model(tmp_path / "m.json")
    # (the same numbers, summed in another layout: round-off of the cancelling monomials only)
    np.testing.assert_allclose(jax.vmap(lambda x: g.force_band(back, x).upper)(jnp.asarray(xs)), band.upper,
                               rtol=1e-9, atol=1e-9 * float(np.max(np.abs(np.asarray(band.upper)))))
    # the figure draws it
    fig = g.plots.band_figure(m, 0, truth=s.truth, recordings=recs, path=tmp_path / "band.png")
    assert (tmp_path / "band.png").stat().st_size > 0 and len(fig.axes) == 2


@pytest.mark.slow
@pytest.mark.parametrize("index", [1, 7, 15])  # joint 40 dB, NES 30 dB, shallow arch 40 dB
def test_coverage_study_cases_meet_the_target(index):
    """A reduced `studies/coverage.py`: the 95 % band covers the true restoring force on >= 90 %
    of the interwell span, with a band narrower than half the force scale (not vacuous)."""
    from studies.coverage import CASES, TARGET, run_case

    rows, _, _ = run_case(*CASES[index])
    for r in rows:
        assert r["cover_span"] >= TARGET, r
        assert r["width"] < 0.5, r


@pytest.mark.slow
def test_the_band_holds_an_odd_error_between_three_wells():
    """A non-polynomial tri-stable law (audit: F = k x + s sin(w x) + e x^2, wells -9.3 / 0 / 9.1 mm, x, v, a at
    40 dB): the degree-9 polynomial's error between the wells is odd (its next even degree does not hold it), and
    the band built from the next degree alone held the truth on 42 % of the span (saddles outside it); with the
    next fit of each parity, on all of it, the band RMS under 4 x the error (numpy truth)."""
    from scipy.integrate import solve_ivp
    from scipy.optimize import brentq

    m, w, s, e = 0.1, 600.0, 1000.0 / 600.0, 600.0
    k = s * w / 8

    def force(x):
        return k * x + s * np.sin(w * x) + e * x**2

    def damping(x, v):
        return (0.2 + 1400 * x**2) * v + 2 * v**3

    grid = np.linspace(-0.03, 0.03, 60001)
    f = force(grid)
    roots = np.unique(np.round([brentq(force, grid[i], grid[i + 1])
                                for i in np.nonzero(np.sign(f[:-1]) != np.sign(f[1:]))[0]], 9))
    wells = roots[k + s * w * np.cos(w * roots) + 2 * e * roots > 0]
    assert wells.size == 3
    t = np.arange(10_000) / 1000.0
    recs = []
    for i, x0 in enumerate(wells):
        rng = np.random.default_rng(20 + i)
        fs, ph = np.linspace(1.0, 30.0, 40), rng.uniform(0, 2 * np.pi, 40)

        def base(tt, fs=fs, ph=ph):
            return 0.3 * np.sum(np.sin(2 * np.pi * fs[:, None] * np.atleast_1d(tt)[None, :] + ph[:, None]), 0) / np.sqrt(20)

        sol = solve_ivp(lambda tt, z, base=base: [z[1], -(force(z[0]) + damping(z[0], z[1])) / m - base(tt)[0]],
                        (0, t[-1]), [x0, 0.0], t_eval=t, method="DOP853", rtol=1e-10, atol=1e-12)
        x, v = sol.y
        a = -(force(x) + damping(x, v)) / m
        noisy = [c + np.std(c) * 10 ** (-2.0) * rng.standard_normal(c.size) for c in (x, v, a)]
        recs.append(g.Recording(t=t, x=noisy[0], v=noisy[1], a=noisy[2], base_acc=base(t), masses=np.array([m]),
                                name=f"well{i}"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", g.GMRDataWarning)
        model = g.reconstruct(recs).value
    xs = np.linspace(wells[0], wells[-1], 301)
    band = jax.vmap(lambda x: g.force_band(model, x))(jnp.asarray(xs[:, None]))
    lo, hi, mean = (np.asarray(getattr(band, n))[:, 0] for n in ("lower", "upper", "mean"))
    truth = force(xs)
    assert np.mean((truth >= lo) & (truth <= hi)) >= 0.9
    err = np.sqrt(np.mean((mean - truth) ** 2))
    assert 0.5 * np.sqrt(np.mean((hi - lo) ** 2)) < 4 * 1.96 * err
