import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._basins._sweep import SweepSettings, basin_map
from gmr_jax._basins._wells import stable_wells
from gmr_jax._simulate._inputs import HalfSineBase, HalfSineTip


def _needs_compiler():
    from gmr_jax._basins import _native

    if _native.compiler() is None:
        pytest.skip("no C compiler: the native kernel cannot be built here")


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
    bm = basin_map(m, f, A, wells, chunk=4).value
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
    bm = basin_map(m, jnp.array([1.0]), jnp.array([2.0]), wells, settings=SweepSettings(settle_time=0.05)).value
    assert int(bm.config[0, 0]) == -1 and int(bm.result[0, 0]) == g.RESULTS.not_settled._value
    soft = g.from_terms([0.05, 0.05], [{"dof": i, "physics": "stiffness", "order": 3, "coefficient": -1e3}
                                       for i in range(2)], "chain")
    bm = basin_map(soft, jnp.array([1.0]), jnp.array([50.0]), wells).value
    assert int(bm.config[0, 0]) == -1 and int(bm.result[0, 0]) == g.RESULTS.diverged._value


def test_no_recompile_for_new_grid_values_or_coefficients():
    from gmr_jax._basins import _sweep

    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    basin_map(m, jnp.array([1.0, 2.0]), jnp.array([1.0]), wells, settings=SweepSettings(batching="lanes"))
    before = _sweep._sweep_points._cached._cache_size()
    m2 = eqx.tree_at(lambda q: q.stiffness, m, m.stiffness * 1.01)
    basin_map(m2, jnp.array([1.5, 3.0]), jnp.array([0.7]), wells, settings=SweepSettings(batching="lanes"))
    assert _sweep._sweep_points._cached._cache_size() == before


@pytest.mark.slow
def test_sharded_over_two_host_devices_matches_and_does_not_recompile():
    import subprocess
    import sys
    import textwrap

    code = textwrap.dedent("""
        import os
        os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=2"
        import jax, jax.numpy as jnp, numpy as np
        import gmr_jax as g
        from gmr_jax._basins import _sweep
        from gmr_jax._basins._sweep import basin_map
        from gmr_jax._basins._wells import stable_wells
        assert len(jax.devices()) == 2
        terms = []
        for i, (k1, k3) in enumerate([(-30.0, 1e5), (-60.0, 2e5)]):
            terms += [{"dof": i, "physics": "stiffness", "order": 1, "coefficient": k1},
                      {"dof": i, "physics": "stiffness", "order": 3, "coefficient": k3},
                      {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": 0.5}]
        m = g.from_terms([0.05, 0.05], terms, "chain")
        w = stable_wells(m, [[-0.05, 0.05]] * 2)
        f, A = jnp.linspace(0.5, 4, 5), jnp.linspace(0.3, 2.5, 3)
        s = _sweep.SweepSettings(batching="lanes")  # the XLA path is what shards over devices
        two = basin_map(m, f, A, w, chunk=4, settings=s).value
        one = basin_map(m, f, A, w, chunk=4, devices=jax.devices()[:1], settings=s).value
        assert np.array_equal(np.asarray(two.config), np.asarray(one.config))
        run = _sweep._sharded(tuple(jax.devices()), 4)
        n = run._cached._cache_size()
        assert n >= 1
        basin_map(m, f + 0.1, A + 0.1, w, chunk=4, settings=s)
        assert run._cached._cache_size() == n
        print("OK")
    """)
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.returncode == 0 and "OK" in r.stdout, r.stderr[-2000:]


@pytest.fixture(scope="module")
def batched_maps():
    """One grid swept with both batchings (chunks of 8; shared by the two tests below, whose
    compiled sweeps are then compiled once)."""
    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    f, A = jnp.linspace(0.3, 4.5, 7), jnp.linspace(0.2, 2.8, 6)
    joint = basin_map(m, f, A, wells, chunk=8, settings=SweepSettings(batching="joint")).value
    member = basin_map(m, f, A, wells, chunk=8, settings=SweepSettings(batching="member")).value
    return m, wells, f, A, joint, member


def test_joint_and_member_batching_agree_and_meet_the_tolerance(batched_maps):
    # joint: one ODE per chunk, shared step, max-over-members error norm; member: vmap of solves
    m, wells, f, A, joint, member = batched_maps
    assert np.array_equal(np.asarray(joint.config), np.asarray(member.config))
    assert np.all(np.asarray(joint.config) >= 0)
    # both are within tolerance-level distance of a much tighter reference on a few points
    tight = SweepSettings(integrator=g.Integrator(rtol=1e-10, atol=1e-12, max_steps=100_000), batching="member")
    ref = basin_map(m, f[::3], A[::2], wells, settings=tight).value
    for bm in (joint, member):
        np.testing.assert_allclose(np.asarray(bm.x_final)[::2, ::3], np.asarray(ref.x_final), atol=2e-4)
    # the shared step is set by the hardest member (max-norm, not a mean over the chunk): every
    # joint chunk takes about as many steps as each of its members took alone, or more
    assert np.all(np.asarray(joint.steps) >= 0.9 * np.asarray(member.steps))


def test_base_load_matches_plain_simulation():
    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    f, A = jnp.array([0.7, 3.0]), jnp.array([8.0, 30.0])
    bm = basin_map(m, f, A, wells, settings=SweepSettings(load="base")).value
    for i in range(2):
        for j in range(2):
            t1 = 0.5 / float(f[j]) + 10.0
            sol = g.simulate(m, HalfSineBase(f[j], A[i], n_dof=2), jnp.array([0.0, t1]), jnp.asarray(wells[:, 0]))
            x1 = np.asarray(sol.value[0])[-1]
            want = [int(np.argmin(np.abs(x1[k] - wells[k]))) for k in range(2)]
            assert list(np.asarray(bm.wells[i, j])) == want
    assert len(set(np.asarray(bm.config).ravel().tolist())) > 1  # the grid is not trivial


def test_failed_joint_chunk_is_rerun_point_by_point(batched_maps):
    m, wells, f, A, joint, member = batched_maps
    need_member, need_joint = int(np.max(member.steps)), int(np.max(joint.steps))
    assert need_joint > need_member  # the shared step costs steps
    budget = SweepSettings(integrator=g.Integrator(rtol=1e-6, atol=1e-8, max_steps=need_member + 5),
                           batching="joint")
    bm = basin_map(m, f, A, wells, chunk=8, settings=budget).value  # the joint solve runs out, members do not
    failed = np.asarray(joint.steps) > need_member + 5  # the chunks whose shared solve ran out
    assert failed.any() and not failed.all()
    assert np.array_equal(np.asarray(bm.config), np.asarray(member.config))
    # a failed chunk's points are rerun one by one (each member's own steps); the others keep
    # their joint solve
    want = np.where(failed, np.asarray(member.steps), np.asarray(joint.steps))
    assert np.array_equal(np.asarray(bm.steps), want)
    assert np.all(np.asarray(bm.result) == g.RESULTS.successful._value)


def test_progress_blocks_give_the_same_map():
    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    f, A = jnp.linspace(0.3, 4.5, 9), jnp.linspace(0.2, 2.8, 5)
    calls = []
    a = basin_map(m, f, A, wells, chunk=4, progress=lambda done, total: calls.append((done, total))).value
    b = basin_map(m, f, A, wells, chunk=4).value
    assert np.array_equal(np.asarray(a.config), np.asarray(b.config))
    assert len(calls) > 1 and calls[-1] == (45, 45) and all(d <= t for d, t in calls)


def test_new_settle_time_or_tolerance_does_not_recompile():
    from gmr_jax._basins import _sweep

    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    basin_map(m, jnp.array([1.0, 2.0]), jnp.array([1.0]), wells, settings=SweepSettings(settle_time=3.0, batching="lanes"))
    before = _sweep.n_chunk_compiles()
    basin_map(m, jnp.array([1.0, 2.0]), jnp.array([0.5]), wells, settings=SweepSettings(settle_time=4.0, integrator=g.Integrator(rtol=1e-7, atol=1e-8, max_steps=100_000), batching="lanes"))
    assert _sweep.n_chunk_compiles() == before


@pytest.mark.parametrize("kwargs, match", [
    ({"f": [0.0, 1.0]}, "f must be > 0"),
    ({"A": [np.nan]}, "A contains NaN"),
    ({"f": [[1.0]]}, "1-D"),
    ({"wells": np.zeros((3, 2))}, "wells must be"),
    ({"wells": np.full((2, 2), np.nan)}, "no stable well"),
    ({"x0": [0.0]}, "x0 must be"),
])
def test_bad_inputs_name_the_problem(kwargs, match):
    m = chain()
    args = {"f": [1.0], "A": [1.0], "wells": stable_wells(m, [[-0.05, 0.05]] * 2)}
    args.update({k: v for k, v in kwargs.items() if k in args})
    extra = {k: v for k, v in kwargs.items() if k not in args}
    with pytest.raises(g.GMRInputError, match=match):
        basin_map(m, args["f"], args["A"], args["wells"], **extra)
    with pytest.raises(g.GMRInputError, match="load must be"):
        SweepSettings(load="top")


@pytest.mark.slow
def test_two_processes_with_jax_distributed_each_get_the_whole_map(tmp_path):
    # multi-host scale-out through JAX's own runtime, run here as two CPU processes (gloo)
    import socket
    import subprocess
    import sys
    import textwrap

    with socket.socket() as s:
        s.bind(("localhost", 0))
        port = s.getsockname()[1]
    code = textwrap.dedent(f"""
        import sys
        import jax
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
        jax.distributed.initialize(coordinator_address="localhost:{port}", num_processes=2,
                                   process_id=int(sys.argv[1]))
        import numpy as np
        import gmr_jax as g
        terms = []
        for i, (k1, k3) in enumerate([(-30.0, 1e5), (-60.0, 2e5)]):
            terms += [{{"dof": i, "physics": "stiffness", "order": 1, "coefficient": k1}},
                      {{"dof": i, "physics": "stiffness", "order": 3, "coefficient": k3}},
                      {{"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": 0.5}}]
        m = g.from_terms([0.05, 0.05], terms, "chain")
        w = g.stable_wells(m, [[-0.05, 0.05]] * 2)
        assert jax.process_count() == 2 and len(jax.devices()) == 2
        bm = g.basin_map(m, np.linspace(0.5, 4, 7), np.linspace(0.3, 2.5, 5), w, chunk=4).value
        np.save(sys.argv[2], np.asarray(bm.config))
    """)
    outs = [tmp_path / f"p{k}.npy" for k in range(2)]
    procs = [subprocess.Popen([sys.executable, "-c", code, str(k), str(outs[k])], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for k in range(2)]
    for p in procs:
        _, err = p.communicate(timeout=300)
        assert p.returncode == 0, err[-2000:]
    m = chain()
    one = basin_map(m, np.linspace(0.5, 4, 7), np.linspace(0.3, 2.5, 5), stable_wells(m, [[-0.05, 0.05]] * 2),
                    chunk=4).value
    for o in outs:
        assert np.array_equal(np.load(o), np.asarray(one.config))


@pytest.mark.skipif("device_count" in __import__("os").environ.get("XLA_FLAGS", ""),
                    reason="XLA_FLAGS already fixes the CPU device count")
def test_use_cpu_cores_after_jax_started_is_a_clear_error():
    jnp.zeros(1).block_until_ready()  # JAX has started in this process
    with pytest.raises(g.GMRInputError, match="before the first JAX computation"):
        g.use_cpu_cores(2)
    assert g.use_cpu_cores(2, strict=False) == len(jax.devices("cpu"))


def test_default_chunk_scales_with_the_number_of_cells():
    from gmr_jax._basins._sweep import default_chunk

    assert [default_chunk(d) for d in (1, 3, 5, 10, 40)] == [512, 512, 256, 128, 64]
    assert default_chunk(5, "lanes") == 256 and default_chunk(5, "lanes", accelerator=True) == 32_768


# -- lanes batching: per-point step control in one vectorised loop ---------------------------
def _grid():
    return jnp.linspace(0.3, 4.5, 7), jnp.linspace(0.2, 2.8, 6)


def test_lanes_match_member_and_a_tight_reference_with_per_point_steps():
    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    f, A = _grid()
    lanes = basin_map(m, f, A, wells, chunk=8, settings=SweepSettings(batching="lanes")).value  # 8 lanes: the queue refills them
    member = basin_map(m, f, A, wells, chunk=8, settings=SweepSettings(batching="member")).value
    joint = basin_map(m, f, A, wells, chunk=8, settings=SweepSettings(batching="joint")).value
    assert np.array_equal(np.asarray(lanes.config), np.asarray(member.config))
    tight = SweepSettings(integrator=g.Integrator(rtol=1e-10, atol=1e-12, max_steps=100_000), batching="member")
    ref = basin_map(m, f[::3], A[::2], wells, settings=tight).value
    np.testing.assert_allclose(np.asarray(lanes.x_final)[::2, ::3], np.asarray(ref.x_final), atol=2e-4)
    # each point's own step count: close to diffrax's per-member solve (same pair, an I-controller
    # like the PID default), and on average below the shared step of a joint chunk
    ls, ms = np.asarray(lanes.steps, float), np.asarray(member.steps, float)
    assert np.all(ls <= 1.25 * ms + 5) and np.all(ls >= 0.75 * ms - 5)
    assert ls.mean() < np.asarray(joint.steps, float).mean()
    assert len(set(np.unique(ls).tolist())) > 5  # steps are per point, not per chunk


@pytest.mark.parametrize("topology", ["chain", "independent"])
@pytest.mark.parametrize("load", ["tip", "base"])
def test_lane_field_matches_the_model_equations(topology, load):
    """The lanes' field (lanes on the last axis, one model or each lane its own) is the model's
    equations of motion lane by lane."""
    from gmr_jax._basins._lanes import lanes_field

    terms = [{"dof": i, "physics": p, "order": o, "coefficient": c}
             for i in range(3) for p, o, c in (("stiffness", 1, -20.0 - i), ("stiffness", 3, 3e4), ("stiffness", 2, 7.0),
                                               ("velocity_damping", 1, 0.4), ("velocity_damping", 0, 0.05),
                                               ("velocity_damping", 2, 0.3), ("position_damping", 2, 11.0))]
    m = g.from_terms([0.05, 0.04, 0.03], terms, topology)
    rng = np.random.default_rng(0)
    x, v = jnp.asarray(rng.normal(0, 0.03, (3, 16))), jnp.asarray(rng.normal(0, 0.5, (3, 16)))
    t, f, a = (jnp.asarray(rng.uniform(0.01, 0.3, 16)), jnp.asarray(rng.uniform(0.5, 3, 16)),
               jnp.asarray(rng.uniform(0.1, 2, 16)))
    src = HalfSineTip if load == "tip" else HalfSineBase

    def want(model):
        return jax.vmap(lambda xi, vi, ti, fi, ai: model.accelerations(xi, vi, *src(fi, ai, n_dof=3)(ti)),
                        in_axes=(1, 1, 0, 0, 0), out_axes=1)(x, v, t, f, a)

    with jax.numpy_rank_promotion("allow"):
        got = lanes_field(m, load, 3, per_lane=False)(t, (x, v), (m, f, a, 0.5 / f))
    np.testing.assert_allclose(np.asarray(got[1]), np.asarray(want(m)), rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(np.asarray(got[0]), np.asarray(v))
    # each lane its own coefficients (a drawn ensemble): lane k follows model k
    scale = jnp.asarray(rng.uniform(0.8, 1.2, 16))
    models = jax.vmap(lambda s: eqx.tree_at(lambda q: (q.stiffness, q.masses), m, (m.stiffness * s, m.masses * s)))(scale)
    lanes = jax.tree.map(lambda q: jnp.moveaxis(q, 0, -1), models)
    with jax.numpy_rank_promotion("allow"):
        got = lanes_field(m, load, 3, per_lane=True)(t, (x, v), (lanes, f, a, 0.5 / f))
    for k in (0, 7, 15):
        mk = jax.tree.map(lambda q: q[k], models)
        np.testing.assert_allclose(np.asarray(got[1][:, k]), np.asarray(want(mk))[:, k], rtol=1e-12, atol=1e-9)


def test_lane_half_period_sin_is_sin_on_the_load_phase():
    """The lanes' polynomial sine equals sin on [0, pi] to 4e-16 (the phase of the half-sine
    while the load is on), in float32 to float32 resolution, and clips outside it."""
    from gmr_jax._basins._lanes import _half_period_sin

    theta = np.linspace(0.0, np.pi, 200_001)
    got = np.asarray(jax.jit(_half_period_sin)(jnp.asarray(theta)))
    np.testing.assert_allclose(got, np.sin(theta), rtol=0, atol=4e-16)
    got32 = np.asarray(_half_period_sin(jnp.asarray(theta, jnp.float32)))
    assert got32.dtype == np.float32
    np.testing.assert_allclose(got32, np.sin(theta), rtol=0, atol=5e-7)
    np.testing.assert_allclose(np.asarray(_half_period_sin(jnp.asarray([-0.5, 4.0]))), [0.0, 0.0], atol=1e-15)


@pytest.mark.parametrize("batching", ["lanes", "native"])
def test_lanes_step_budget_is_per_point(batching):
    if batching == "native":
        _needs_compiler()
    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    f, A = jnp.array([0.3, 4.5]), jnp.array([0.5, 2.5])
    free = basin_map(m, f, A, wells, settings=SweepSettings(batching=batching)).value
    steps = np.asarray(free.steps)
    budget = int((steps.min() + steps.max()) // 2)
    st = SweepSettings(integrator=g.Integrator(rtol=1e-6, atol=1e-8, max_steps=budget), batching=batching)
    sol = basin_map(m, f, A, wells, settings=st, throw=False)
    res = np.asarray(sol.value.result)
    over = steps > budget
    assert np.all(res[over] == g.RESULTS.max_steps_reached._value)
    assert np.all(res[~over] == g.RESULTS.successful._value)
    assert np.array_equal(np.asarray(sol.value.config)[~over], np.asarray(free.config)[~over])
    assert np.all(np.asarray(sol.value.config)[over] == -1)
    with pytest.raises(g.GMRComputationError, match="max_steps"):
        basin_map(m, f, A, wells, settings=st)


@pytest.mark.parametrize("batching", ["lanes", "native"])
@pytest.mark.parametrize("solver", [dfx.Dopri5(), dfx.Dopri8(), "dopri8"])
def test_lanes_other_pairs_give_the_same_map(solver, batching):
    if batching == "native":
        _needs_compiler()
    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    f, A = _grid()
    ref = basin_map(m, f, A, wells, settings=SweepSettings(batching=batching)).value
    other = basin_map(m, f, A, wells, settings=SweepSettings(solver=solver, batching=batching)).value
    assert np.array_equal(np.asarray(other.config), np.asarray(ref.config))
    np.testing.assert_allclose(np.asarray(other.x_final), np.asarray(ref.x_final), atol=2e-4)


def test_default_sweep_runs_the_diffrax_solver_it_is_given():
    """The default path integrates with the diffrax solver object of `SweepSettings.solver`:
    Dopri8 instead of Tsit5 takes fewer steps per point (an 8th-order pair) and gives the same
    map; an implicit solver (Kvaerno5, vmapped lane by lane) gives it too."""
    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    f, A = _grid()
    tsit = basin_map(m, f, A, wells)
    assert tsit.stats["batching"] == "lanes" and tsit.stats["solver"] == "Tsit5"
    dop8 = basin_map(m, f, A, wells, settings=SweepSettings(solver=dfx.Dopri8()))
    assert dop8.stats["solver"] == "Dopri8"
    np.testing.assert_array_equal(np.asarray(dop8.value.config), np.asarray(tsit.value.config))
    s_t, s_8 = np.asarray(tsit.value.steps, float), np.asarray(dop8.value.steps, float)
    assert s_8.mean() < 0.8 * s_t.mean()
    assert np.mean(s_8 < s_t) > 0.9  # point by point, not only on average
    kv = basin_map(m, f[::2], A[::2], wells, settings=SweepSettings(solver=dfx.Kvaerno5()))
    np.testing.assert_array_equal(np.asarray(kv.value.config), np.asarray(tsit.value.config)[::2, ::2])
    with pytest.raises(g.GMRInputError, match="adaptive diffrax solver"):
        SweepSettings(solver=dfx.Euler())


def test_float32_sweep_agrees_with_float64():
    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    f, A = _grid()
    ref = basin_map(m, f, A, wells).value
    lo_sol = basin_map(m, f, A, wells, settings=SweepSettings(precision="float32"))
    assert lo_sol.stats["batching"] == "lanes"
    lo = lo_sol.value
    assert lo.x_final.dtype == jnp.float32
    assert np.array_equal(np.asarray(lo.config), np.asarray(ref.config))
    with pytest.raises(g.GMRInputError, match="precision"):
        SweepSettings(precision="float16")


# -- Coulomb friction: sgn(v) in a sweep ---------------------------------------------------------
def _with_friction(level=0.01):
    terms = []
    for i, (k1, k3) in enumerate([(-30.0, 1e5), (-60.0, 2e5)]):
        terms += [{"dof": i, "physics": "stiffness", "order": 1, "coefficient": k1},
                  {"dof": i, "physics": "stiffness", "order": 3, "coefficient": k3},
                  {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": 0.5},
                  {"dof": i, "physics": "velocity_damping", "order": 0, "coefficient": level}]
    return g.from_terms([0.05, 0.05], terms, "chain")


@pytest.mark.parametrize("batching", ["auto", "lanes"])
def test_coulomb_friction_is_smoothed_below_the_settled_speed_and_said(batching):
    """With the exact sgn(v) every point chatters to its step budget (and the error says why);
    by default sgn(v) -> tanh(v / eps), eps a tenth of the settled-speed test, reported in stats,
    and the map does not depend on eps (ten times smaller: the same map)."""
    m = _with_friction()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    f, A = jnp.linspace(0.3, 4.5, 5), jnp.linspace(0.2, 2.8, 4)
    small = g.Integrator(rtol=1e-6, atol=1e-8, max_steps=20_000)
    exact = basin_map(m, f, A, wells, settings=SweepSettings(sign_eps=0.0, integrator=small, batching=batching),
                      throw=False)
    assert exact.stats["sign_eps"] == 0.0
    assert exact.stats["counts"].get("max_steps_reached", 0) >= 10
    with pytest.raises(g.GMRComputationError, match="sign_eps at None"):
        basin_map(m, f, A, wells, settings=SweepSettings(sign_eps=0.0, integrator=small, batching=batching))
    auto = basin_map(m, f, A, wells, settings=SweepSettings(batching=batching))
    span = float(np.min(np.nanmax(wells, 1) - np.nanmin(wells, 1)))
    assert auto.stats["sign_eps"] == pytest.approx(0.1 * 0.05 * span)
    assert auto.stats["counts"] == {"successful": 20}
    # ten times smaller eps: ten times stiffer near v = 0, about 1e5 steps a point (budget raised)
    finer = basin_map(m, f, A, wells, settings=SweepSettings(
        batching=batching, sign_eps=auto.stats["sign_eps"] / 10,
        integrator=g.Integrator(rtol=1e-6, atol=1e-8, max_steps=400_000)))
    np.testing.assert_array_equal(np.asarray(auto.value.config), np.asarray(finer.value.config))
    assert len(set(np.asarray(auto.value.config).ravel().tolist())) >= 2
    # a model without sgn(v) is not touched
    assert basin_map(chain(), f[:2], A[:1], wells).stats["sign_eps"] is None


def test_cli_basins_notes_the_amplitudes_that_push_beyond_the_fitted_range(tmp_path):
    """The tip half-sine's static force against the largest restoring force over the model file's data_range
    (Duffing -x + x^3 on [-1.1, 1.1]: max 2 / (3 sqrt 3) = 0.385 at the hump): amplitudes above it are named, with
    the static deflection at the largest (x^3 - x = 1: x = 1.3247, NumPy's root); none above: silent; base
    load on a chain: per the masses each cell carries."""
    import json

    from gmr_jax._cli._basins import _beyond_data

    duffing = g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -1.0},
                                   {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1.0}],
                           topology="independent")
    path = tmp_path / "m.json"
    g.save_model(duffing, path)
    doc = json.loads(path.read_text())
    doc["data_range"] = [[-1.1, 1.1]]
    path.write_text(json.dumps(doc))
    said = _beyond_data(duffing, path, np.array([0.1, 0.5, 1.0]), "tip")[0]
    a_star = 2 / (3 * np.sqrt(3))
    root = max(r.real for r in np.roots([1, 0, -1, -1]) if abs(r.imag) < 1e-12)
    assert f"A > {a_star:.4g} (2 of 3 amplitudes)" in said and f"x = {root:.4g}" in said
    assert _beyond_data(duffing, path, np.array([0.1, 0.3]), "tip") is None
    doc.pop("data_range")
    path.write_text(json.dumps(doc))
    assert _beyond_data(duffing, path, np.array([1.0]), "tip") is None  # no range recorded: nothing to say
    chain = g.from_terms([1.0, 0.5], [{"dof": i, "physics": "stiffness", "order": k, "coefficient": c}
                                      for i in (0, 1) for k, c in ((1, -1.0), (3, 1.0))], topology="chain")
    g.save_model(chain, path)
    doc = json.loads(path.read_text())
    doc["data_range"] = [[-1.1, 1.1], [-1.1, 1.1]]
    path.write_text(json.dumps(doc))
    base = _beyond_data(chain, path, np.array([0.3, 0.5]), "base")[0]  # cell 0 carries 1.5: A* = 0.385 / 1.5
    assert f"A > {a_star / 1.5:.4g} (2 of 2 amplitudes)" in base and "cell 0" in base


def test_cli_basins_draws_maps_the_probability_over_the_covariance(tmp_path, capsys):
    """`gmr basins --draws N`: N models drawn from the file's covariance swept like the model (basin_probability);
    a tight covariance agrees with the model's own map, the probability file and figure are written; a model file
    without a covariance is refused with the fix."""
    import json

    from gmr_jax._cli._main import main

    terms = [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -1.0},
             {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1.0},
             {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.3}]
    doc = {"format": "gmr-model/1", "topology": "independent", "masses": [1.0], "terms": terms}
    plain = tmp_path / "plain.json"
    plain.write_text(json.dumps(doc))
    doc["covariance"] = [{"dof": 0, "terms": [["stiffness", 1], ["stiffness", 3], ["velocity_damping", 1]],
                          "matrix": (np.diag([1e-8, 1e-8, 1e-8])).tolist()}]
    tight = tmp_path / "tight.json"
    tight.write_text(json.dumps(doc))
    args = ["--f", "0.05:0.5:3", "--A", "0.1:1.5:3", "--settle-time", "40", "--draws", "3"]
    assert main(["basins", str(tight), *args, "--out", str(tmp_path / "b")]) == 0
    printed = capsys.readouterr().out
    assert "drawn models: 3 used of 3 drawn" in printed and "the model's own map is the most likely at 100 %" in printed
    prob = np.load(tmp_path / "b" / "basins_probability.npz")
    own = np.load(tmp_path / "b" / "basins.npz")
    np.testing.assert_array_equal(prob["most_likely"], own["config"])
    assert prob["probability"].shape[:2] == (3, 3) and np.allclose(prob["probability"].sum(-1), 1.0)
    assert (tmp_path / "b" / "basins_confidence.png").stat().st_size > 1000
    assert main(["basins", str(plain), *args, "--out", str(tmp_path / "c")]) == 2
    assert "has no covariance" in capsys.readouterr().err


def test_a_third_well_is_its_own_configuration(tmp_path):
    """A tri-stable DOF (F = x^5 - 5x^3 + 4x: wells -2, 0, 2): a point that ends in the third well has
    configuration 2, not the first well's 0 (audit: `config` was a bit field, and the +2 well's points
    were drawn and labelled as the -2 well's); codes are base-K digits (K wells per cell), a bit field
    for bistable cells, and the figure reads them in the base its wells give."""
    from gmr_jax._basins._sweep import classify
    from gmr_jax.plots import basin_figure, config_label

    settings = SweepSettings()
    wells = jnp.array([[-2.0, 0.0, 2.0]])
    ok = g.RESULTS.successful._value
    for x, idx in ((-2.0, 0), (0.0, 1), (2.0, 2)):
        i, config, _ = classify(jnp.array([x]), jnp.zeros(1), ok, wells, jnp.array([4.0]), settings)
        assert int(i[0]) == idx and int(config) == idx
    two = jnp.array([[-2.0, 0.0, 2.0], [-1.0, 1.0, jnp.nan]])
    _, config, _ = classify(jnp.array([2.0, 1.0]), jnp.zeros(2), ok, two, jnp.array([4.0, 2.0]), settings)
    assert int(config) == 2 + 1 * 3 and config_label(int(config), 2, 3) == "2-1"
    _, bits, _ = classify(jnp.array([1.0, 1.0]), jnp.zeros(2), ok, jnp.array([[-1.0, 1.0], [-1.0, 1.0]]),
                          jnp.array([2.0, 2.0]), settings)
    assert int(bits) == 3 and config_label(3, 2) == "1-1"  # bistable cells: the bit field, as before
    model = g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": k, "coefficient": c}
                                 for k, c in ((1, 4.0), (3, -5.0), (5, 1.0))]
                         + [{"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.5}])
    found = stable_wells(model, [(-3.0, 3.0)])
    np.testing.assert_allclose(np.asarray(found)[0][np.isfinite(np.asarray(found)[0])], [-2.0, 0.0, 2.0], atol=1e-9)
    config = np.array([[0, 1], [2, -1]])
    fig = basin_figure(np.array([1.0, 2.0]), np.array([1.0, 2.0]), config, 1, wells=found)
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert "2 (x = 2)" in labels and "0 (x = -2)" in labels
    with pytest.raises(g.GMRInputError, match="more than two wells"):
        basin_figure(np.array([1.0, 2.0]), np.array([1.0, 2.0]), config, 1)


def test_cli_basins_notes_crossings_faster_than_the_recorded_speeds(tmp_path):
    """A crossing of the double well F = -x + x^3 (barrier 1/4, mass 1) needs |v| >= sqrt(1/2): a model fitted
    at speeds up to 0.05 (the file's speed_range) is noted (its damping along the crossings is extrapolated), one
    fitted up to 1 is not, nor a file without speed_range."""
    import json

    from gmr_jax._cli._basins import _beyond_speed

    model = g.from_terms([1.0], [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -1.0},
                                 {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1.0},
                                 {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.1}])
    wells = np.array([[-1.0, 1.0]])
    for vmax, noted in ((0.05, True), (1.0, False), (None, False)):
        path = tmp_path / f"m{vmax}.json"
        g.save_model(model, path, **({} if vmax is None else {"speed_range": [[-vmax, vmax]]}))
        note = _beyond_speed(model, path, wells, None)
        assert (note is not None) == noted, note
        if noted:
            assert "at least 0.707" in note and "14.1 x the fastest recorded (0.05" in note
    assert json.loads(path.read_text()).get("speed_range") is None


def test_basin_probability_sweeps_the_drawn_models_as_one_batch_with_the_loops_answer():
    """The drawn models are data in one lanes sweep: each (model, point) pair ends as that model's
    own `basin_map` does point by point, so the probabilities are those of the per-draw loop."""
    terms = []
    for i, (k1, k3) in enumerate([(-30.0, 1e5), (-60.0, 2e5)]):
        terms += [{"dof": i, "physics": "stiffness", "order": 1, "coefficient": k1},
                  {"dof": i, "physics": "stiffness", "order": 3, "coefficient": k3},
                  {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": 0.5}]
    cov = [{"dof": i, "terms": [["stiffness", 1], ["stiffness", 3]], "matrix": np.diag([4.0, 1e8]).tolist()}
           for i in range(2)]
    m = g.from_terms([0.05, 0.05], terms, "chain", covariance=cov)
    f, A = _grid()
    x_range = [[-0.05, 0.05]] * 2
    key = jax.random.key(3)
    sol = g.basin_probability(m, f, A, key, 5, x_range=x_range)
    bp = sol.value
    assert sol.stats["samples_used"] == 5 and sol.stats["samples_drawn"] == 5
    samples = g.sample_models(m, key, 5)
    configs = []
    for k in range(5):
        mk = jax.tree.map(lambda a: a[k] if eqx.is_array(a) else a, samples)
        configs.append(np.asarray(basin_map(mk, f, A, stable_wells(mk, x_range)).value.config))
    stack = np.stack(configs)
    assert len(np.unique(stack)) >= 2 and np.any(np.ptp(stack, axis=0) > 0)  # the draws disagree somewhere
    want = np.stack([np.mean(stack == c, axis=0) for c in np.asarray(bp.configs)], axis=-1)
    np.testing.assert_array_equal(np.asarray(bp.probability), want)
    np.testing.assert_array_equal(np.asarray(bp.mean_config),
                                  np.asarray(basin_map(m, f, A, stable_wells(m, x_range)).value.config))


# -- traceable: jit, vmap over models, gradients with respect to the load ----------------------
def test_basin_map_is_a_pure_function_under_jit_and_vmap():
    """With the wells and settings fixed, `basin_map` jits (new grid values reuse the program) and
    vmaps over stacked models, with the eager map's answer."""
    import functools

    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    f, A = _grid()
    eager = basin_map(m, f, A, wells).value
    run = jax.jit(functools.partial(basin_map, wells=wells, settings=SweepSettings()))
    sol = run(m, f, A)
    np.testing.assert_array_equal(np.asarray(sol.value.config), np.asarray(eager.config))
    np.testing.assert_array_equal(np.asarray(sol.value.result), np.asarray(eager.result))
    np.testing.assert_allclose(np.asarray(sol.value.x_final), np.asarray(eager.x_final), atol=1e-5)
    # (the points in another order among the lanes: rounding may flip an accept near err = 1)
    assert int(sol.stats["num_steps"]) == pytest.approx(int(np.sum(np.asarray(eager.steps))), rel=0.01)
    run(m, f * 1.01, A * 0.99)
    assert run._cache_size() == 1  # new grid values: the same program
    # vmap over models (coefficients as data): each one's own map
    scales = jnp.asarray([0.9, 1.0, 1.15])
    models = jax.vmap(lambda s: eqx.tree_at(lambda q: q.stiffness, m, m.stiffness * s))(scales)
    configs = jax.vmap(lambda mk: basin_map(mk, f, A, wells).value.config)(models)
    for k, s in enumerate(scales):
        mk = eqx.tree_at(lambda q: q.stiffness, m, m.stiffness * s)
        np.testing.assert_array_equal(np.asarray(configs[k]), np.asarray(basin_map(mk, f, A, wells).value.config))
    with pytest.raises(g.GMRInputError, match="wells and the settings fixed"):
        jax.jit(lambda w: basin_map(m, f, A, w).value.config)(jnp.asarray(wells))


def test_gradient_of_the_final_miss_matches_central_differences():
    """`BasinMap.miss` (how far each point ended from a target configuration, smooth in the final
    state) differentiated with respect to the load's frequencies and amplitudes through the sweep
    agrees with central differences of the eager map, point by point (a short settle time: the
    state still moves at t1, so the derivatives are O(1))."""
    m = chain()
    wells = stable_wells(m, [[-0.05, 0.05]] * 2)
    st = SweepSettings(settle_time=0.5, integrator=g.Integrator(rtol=1e-11, atol=1e-13, max_steps=100_000))

    def miss(f, A):
        return basin_map(m, f, A, wells, settings=st).value.miss(wells, [1, 1])

    f0, a0 = jnp.asarray([0.7, 1.3, 2.0]), jnp.asarray([0.9, 1.6])
    gf, ga = jax.grad(lambda f, A: jnp.sum(miss(f, A)), argnums=(0, 1))(f0, a0)
    h = 1e-5
    cf = np.array([np.sum(miss(f0.at[i].add(h), a0) - miss(f0.at[i].add(-h), a0)) / (2 * h) for i in range(3)])
    ca = np.array([np.sum(miss(f0, a0.at[i].add(h)) - miss(f0, a0.at[i].add(-h))) / (2 * h) for i in range(2)])
    assert np.all(np.abs(cf) > 1e-3) and np.all(np.abs(ca) > 1e-3)  # not a trivially flat quantity
    np.testing.assert_allclose(np.asarray(gf), cf, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(ga), ca, rtol=1e-5)
    # forward mode too, and the eager value is the traced one
    val, tan = jax.jvp(miss, (f0, a0), (jnp.zeros(3), jnp.ones(2)))
    np.testing.assert_allclose(np.asarray(val), np.asarray(miss(f0, a0)), rtol=1e-9)
    np.testing.assert_allclose(np.asarray(tan).sum(), ca.sum(), rtol=1e-5)


def test_cli_basins_settles_by_the_models_own_time_by_default(tmp_path, capsys):
    """Without --settle-time, `gmr basins` judges final states after the model's own settle time
    (7 / its slowest linearised decay rate, here 47 s), said in its output: a lightly damped
    model that 10 s leaves moving is classified everywhere."""
    from gmr_jax._cli._main import main

    terms = [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -2.0},
             {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 2.0},
             {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.3}]
    g.save_model(g.from_terms([1.0], terms, topology="chain"), tmp_path / "m.json")
    grid = ["--f", "0.05:0.5:3", "--A", "0.5:2:3"]
    assert main(["basins", str(tmp_path / "m.json"), *grid, "--settle-time", "10", "--out", str(tmp_path / "a")]) == 0
    assert np.any(np.load(tmp_path / "a" / "basins.npz")["result"] == g.RESULTS.not_settled._value)
    capsys.readouterr()
    assert main(["basins", str(tmp_path / "m.json"), *grid, "--out", str(tmp_path / "b")]) == 0
    assert "settle time 47 s after the load" in capsys.readouterr().out
    assert np.all(np.load(tmp_path / "b" / "basins.npz")["config"] >= 0)
