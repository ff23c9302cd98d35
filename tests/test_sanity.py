"""Physical sanity checks of `reconstruct` / `gmr fit` (issue 13): each bad-data case gives its
own plain-words warning or refusal, and clean built-in data give none.

Recordings are 5 s long (one shape) and fitted with the default library, so the local fit is
compiled once; recordings are shared per module."""

import dataclasses
import json
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._cli._main import main
from gmr_jax._reconstruct import _sanity
from gmr_jax._reconstruct._sanity import GMRDataWarning
from gmr_jax.metrics._metrics import equilibria, restoring_error

DURATION = 5.0


def _fit(recs, **kw):
    """reconstruct, returning (solution, the GMRDataWarning messages emitted)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", GMRDataWarning)
        sol = g.reconstruct(recs, **kw)
    emitted = [str(w.message) for w in caught if issubclass(w.category, GMRDataWarning)]
    assert emitted == sol.stats["warnings"]
    return sol, emitted


def _has(msgs, *parts):
    return any(all(p in m for p in parts) for m in msgs)


@pytest.fixture(scope="module")
def nes():
    s = g.systems.tristable_nes()
    return s, g.systems.make_recordings(s, 5e-4, seed=0, duration=DURATION)


@pytest.fixture(scope="module")
def nes_swinging():
    """The tri-stable NES driven at 4 mm: the outer records leave their wells. The paper's
    coordination (the checks of the model are about its failures)."""
    s = g.systems.tristable_nes()
    return _fit(g.systems.make_recordings(s, 4e-3, seed=0, duration=DURATION), coordination="gls")


@pytest.mark.slow  # a third NES reconstruction (~15 s cold); the default tier checks the replacement on
# sinusoidal joint records (test_10 below)
def test_records_that_leave_their_wells_are_said_and_the_default_still_fits():
    """On the NES driven across its wells the records leave their wells: the data warnings say
    so, and the default route (records that cross are rows of the global law like any other)
    still explains its training data."""
    s = g.systems.tristable_nes()
    sol, msgs = _fit(g.systems.make_recordings(s, 4e-3, seed=0, duration=DURATION))
    assert _has(msgs, "does not stay in one well")
    assert not _has(msgs, "explains its own training data poorly")


@pytest.fixture(scope="module")
def joint():
    return g.systems.bistable_joint()


def test_clean_builtin_data_give_no_warning(nes):
    """The paper's nominal cases are silent (a false warning is as bad as a missed one)."""
    s, recs = nes
    said = []
    with warnings.catch_warnings():
        warnings.simplefilter("error", GMRDataWarning)
        sol = g.reconstruct(recs, progress=said.append)
    assert sol.stats["warnings"] == []
    # and right (the paper's three-well case; test_reconstruct has it at Library(3, 3) in the
    # slow tier): measured 0.02 % restoring error, every equilibrium within 1e-5
    assert said[0] == "posterior of the global law" and "checks" in said[-1]
    assert restoring_error(sol.value, s.truth, 0, s.x_range[0]) < 0.005
    got, want = equilibria(sol.value, 0, s.x_range[0]), equilibria(s.truth, 0, s.x_range[0])
    assert [st for _, st in got] == [st for _, st in want] == [True, False, True, False, True]
    np.testing.assert_allclose([x for x, _ in got], [x for x, _ in want], atol=1e-4)


@pytest.mark.slow
def test_clean_joint_data_give_no_warning(joint):
    """As above, on the bistable joint (a second full reconstruction: slow tier)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", GMRDataWarning)
        jrecs = g.systems.make_recordings(joint, np.deg2rad(1.0), seed=1, duration=DURATION)
        assert g.reconstruct(jrecs).stats["warnings"] == []


def test_1_two_recordings_of_one_well_are_refused(joint):
    a = g.systems.make_recordings(joint, np.deg2rad(1.0), seed=0, duration=DURATION)[0]
    b = dataclasses.replace(g.systems.make_recordings(joint, np.deg2rad(0.5), seed=1, duration=DURATION)[0],
                            name="joint_S1_again")
    assert abs(a.x.mean() - b.x.mean()) < 1e-3  # different runs, means 0.0002 apart
    with pytest.raises(g.GMRInputError, match=r"joint_S1_again and joint_pi_S1 do not give two distinct"):
        g.reconstruct([a, b])


def test_2_record_swinging_between_wells(nes_swinging):
    _, msgs = nes_swinging
    assert _has(msgs, "nes_S1 (DOF 0) does not stay in one well", "across the equilibrium of another well")
    assert _has(msgs, "nes_S3 (DOF 0) does not stay in one well", "middle of its range is almost empty")


def test_3_clipped_channel(nes):
    _, recs = nes
    x = recs[0].x
    clipped = dataclasses.replace(recs[0], x=np.minimum(x, np.percentile(x, 97)))
    _, msgs = _fit([clipped, *recs[1:]])
    # the clipped well also spoils the model (blown-up interpolant, low R²): warned about too
    assert msgs[0].startswith("nes_S1: column x0 looks clipped: 151 samples (3.0 %)") and "maximum" in msgs[0]
    assert not _has(msgs, "column x0 looks clipped", "nes_S2")


def test_3_brief_saturations_are_found_by_their_rail():
    """A noisy response clipped at its 99.9 % quantile sits at the rail for 1-2 samples per peak (no flat tops of
    3): flagged; a noise-free sine that repeats its samples every period, a quantised (encoder-like) record and a
    clean noisy one are not."""
    rng = np.random.default_rng(0)
    t = np.arange(60_000) / 200.0
    y = np.sin(2 * np.pi * 10.3 * t) * (1 + 0.3 * np.sin(0.2 * t)) + 0.01 * rng.standard_normal(t.size)
    rail = np.quantile(y, 0.999)
    clipped = np.minimum(y, rail)
    assert _sanity._flat_samples(clipped >= rail, 3) < 5  # the old rule's flat tops: none
    msgs = _sanity.check_clipping("rec", {"a0": clipped})
    assert len(msgs) == 1 and "column a0 looks clipped: 60 samples" in msgs[0] and "maximum" in msgs[0]
    sine = np.sin(2 * np.pi * 10.0 * np.arange(60_000) / 200.0)  # 20 samples a period: its top repeats
    quantised = np.round(y * 200) / 200
    for col in (y, sine, quantised):
        assert _sanity.check_clipping("rec", {"a0": col}) == []


def test_4_driven_record_without_input(nes):
    _, recs = nes
    _, msgs = _fit([dataclasses.replace(recs[0], base_acc=None), *recs[1:]])
    assert len(msgs) == 1 and _has(msgs, "nes_S1: no input column", "not a free decay")


def test_4_free_decay_without_input_is_fine(joint):
    """A released joint, and one tapped after a quiet second: free decays, no warning."""
    ts = jnp.arange(4001) / 1000.0
    xe = joint.equilibria[1]
    x = np.asarray(g.simulate(joint.truth, g.NoInput(), ts, xe + 0.05).value[0])
    noise = 1e-4 * np.random.default_rng(0).standard_normal((5001, 1))
    tapped = np.concatenate([np.full((1000, 1), xe[0]), x[:4001]])
    for rec in (x + noise[:4001], tapped + noise):
        assert _sanity.check_missing_input("decay", rec, has_input=False) == []


@pytest.mark.parametrize("name", ["joint", "arch", "magnet", "kresling3"])
def test_13_consistent_units_are_silent(name):
    """Rule 13 stays silent on the built-in systems' own columns at 30 dB (every column of x, v, a
    measured; the NES end to end in `test_clean_builtin_data_give_no_warning`)."""
    s = {"joint": g.systems.bistable_joint, "arch": g.systems.shallow_arch, "magnet": g.systems.magnetic_bistable,
         "kresling3": g.systems.kresling3}[name]()
    amp = {"joint": np.deg2rad(1.0), "kresling3": 3e-4}.get(name, 0.05)
    topo = g.Chain() if s.truth.n_dof > 1 else g.Independent()
    for r in g.systems.make_recordings(s, amp, snr_db=30.0, seed=0, duration=DURATION):
        assert _sanity.check_units(r.name, r, topo) == []
        assert _sanity.check_acceleration_offset(r.name, r, topo) == []  # rule 13d
        # x only: rule 13b (the base input's factor) is all that compares the units, and stays silent
        assert _sanity.check_units(r.name, dataclasses.replace(r, v=None, a=None), topo) == []


def test_13b_x_only_records_in_other_units_are_reported(nes):
    """x and base_acc only (audit: t in ms gave a 97.6 % wrong model, and no warning named the time column): the
    base input's factor in x'' is -1 whatever the mass; a time column in ms (1e-6), x in mm (1e3), base_acc in g
    (9.81) and a reversed base accelerometer (+1) are reported with their factor, and `reconstruct` emits it."""
    _, recs = nes
    r = dataclasses.replace(recs[0], v=None, a=None)
    topo = g.Independent()
    cases = {"ms": (dataclasses.replace(r, t=r.t * 1e3), -1e-6, "time column in 1/1000 of a second"),
             "mm": (dataclasses.replace(r, x=r.x * 1e3), -1e3, "as with t in ms or x in mm"),
             "g": (dataclasses.replace(r, base_acc=r.base_acc / 9.80665), -9.80665, "a power of g"),
             "reversed": (dataclasses.replace(r, base_acc=-r.base_acc), 1.0, "opposite sign")}
    for label, (rec, factor, words) in cases.items():
        msgs = _sanity.check_units("nes_S1", rec, topo)
        assert len(msgs) == 1 and words in msgs[0], (label, msgs)
        got = float(msgs[0].split("with the factor ")[1].split(" ")[0])
        assert got == pytest.approx(factor, rel=0.05), (label, got)
    # one base tone: the input is x and x' over again, so its factor is not identified: no verdict
    t = np.arange(20_000) / 200.0
    w = 2 * np.pi * 3.0
    x = 1e-3 * np.sin(w * t + 0.3) + 1e-6 * np.random.default_rng(0).standard_normal(t.size)
    tone = g.Recording(t=t, x=x, base_acc=np.sin(w * t), name="tone")
    assert _sanity.check_units("tone", tone, topo) == []
    _, msgs = _fit([cases["ms"][0], *[dataclasses.replace(q, t=q.t * 1e3, v=None, a=None) for q in recs[1:]]])
    assert _has(msgs, "nes_S1: the base acceleration enters", "time column in 1/1000 of a second")


def test_13_columns_in_other_units_are_reported(nes):
    """A time column in ms, accelerations in g, x in mm, a velocity of the opposite sign: each is
    reported with its factor (checked against the scale applied), and reconstruct emits it. A time column in ms
    (v 1000 x and a 1e6 x the derivatives of x) is one message that names t and the fix."""
    _, recs = nes
    r = recs[0]
    topo = g.Independent()
    ms = _sanity.check_units("nes_S1", dataclasses.replace(r, t=r.t * 1e3), topo)
    assert len(ms) == 1 and "the time column is in 1/1000 of a second" in ms[0] and "'t=t/1000'" in ms[0], ms
    assert [float(v) for v in (ms[0].split(" is ")[1].split(" times")[0],
                               ms[0].split("acceleration ")[1].split(" times")[0])] == pytest.approx([1e3, 1e6],
                                                                                                   rel=0.03)
    cases = {
        "a in g": (dataclasses.replace(r, a=r.a / 9.80665, base_acc=r.base_acc / 9.80665), {"a": 1 / 9.80665}),
        "x in mm": (dataclasses.replace(r, x=r.x * 1e3), {"v": 1e-3, "a": 1e-3}),
        "v reversed": (dataclasses.replace(r, v=-r.v), {"v": -1.0}),
    }
    for label, (rec, want) in cases.items():
        msgs = _sanity.check_units("nes_S1", rec, topo)
        got = {("v" if "velocity" in m else "a"): float(m.split(" is ")[1].split(" times")[0]) for m in msgs}
        assert set(got) == set(want), (label, msgs)
        for key, factor in want.items():
            assert got[key] == pytest.approx(factor, rel=0.03), (label, key, got[key])
    assert "as with t in ms or x in mm" in _sanity.check_units("nes_S1", cases["x in mm"][0], topo)[0]
    assert "accelerations in g" in _sanity.check_units("nes_S1", cases["a in g"][0], topo)[0]
    assert "opposite sign" in _sanity.check_units("nes_S1", cases["v reversed"][0], topo)[0]
    _, msgs = _fit([cases["a in g"][0], *recs[1:]])
    assert _has(msgs, "nes_S1: the measured relative acceleration", "accelerations in g")
    # an accelerometer mounted reversed (a = -(x'' + b)): a - b is not x'' where b is large, but -a - b is
    # (audit: reported only as records leaving their wells)
    flipped = dataclasses.replace(r, a=-r.a)
    msgs = _sanity.check_units("nes_S1", flipped, topo)
    assert abs(np.corrcoef(-r.a[:, 0] - r.base_acc, r.a[:, 0] - r.base_acc)[0, 1]) < 0.9  # plain check: no verdict
    assert len(msgs) == 1 and "acceleration of DOF 0 has the opposite sign" in msgs[0], msgs
    # rule 13c: a file holding the relative acceleration x'' (a simulation's state) where a = x'' + b is meant;
    # the correct file is silent (above), this one is named with the fix, and reconstruct emits it
    relative = [dataclasses.replace(q, a=q.a - q.base_acc[:, None]) for q in recs]
    msgs = _sanity.check_units("nes_S1", relative[0], topo)
    assert len(msgs) == 1 and "acceleration of DOF 0 is the relative one, not the absolute one" in msgs[0], msgs
    assert "add the base acceleration to the a column" in msgs[0]
    _, msgs = _fit(relative)
    assert _has(msgs, "nes_S1: the measured acceleration of DOF 0 is the relative one")
    # at 40 dB the unexplained shares differ by less than RELATIVE_A_RATIO, and a - b read as 1.3-1.9 x'': rule 13
    # gave a factor as the fix; a itself matches x'', so it is rule 13c's message, not a scale
    joint = g.systems.bistable_joint("position_independent")
    for q in g.systems.make_recordings(joint, np.deg2rad(1.0), snr_db=40.0, seed=0):
        assert _sanity.check_units(q.name, q, topo) == []
        msgs = _sanity.check_units(q.name, dataclasses.replace(q, a=q.a - q.base_acc[:, None]), topo)
        assert len(msgs) == 1 and "is the relative one" in msgs[0] and "times the second" not in msgs[0], msgs


def test_13d_an_accelerometer_offset_is_reported(nes):
    """Rule 13d (audit 8: +0.1 m/s^2 on one well's a, 8 % of its RMS: restoring error 2.3 % against a band of
    +-0.78 %, no warning): the mean of a - base_acc departs from the change of speed over the record; named with
    the offset and the fix, silent on the clean records (and on the built-in systems at 30 dB, above)."""
    _, recs = nes
    topo = g.Independent()
    r = recs[0]
    rel = r.a[:, 0] - r.base_acc
    assert all(_sanity.check_acceleration_offset(q.name, q, topo) == [] for q in recs)
    bias = 0.05 * np.std(rel)
    biased = dataclasses.replace(r, a=r.a + bias)
    msgs = _sanity.check_acceleration_offset(r.name, biased, topo)
    assert len(msgs) == 1 and "holds an offset of" in msgs[0] and "--columns a=<a's column>" in msgs[0], msgs
    got = float(msgs[0].split("holds an offset of ")[1].split(" ")[0])
    assert got == pytest.approx(bias, rel=0.05)
    # half the threshold: silent; an x-derived a (no a column): nothing to check
    assert _sanity.check_acceleration_offset(r.name, dataclasses.replace(r, a=r.a + 0.004 * np.std(rel)), topo) == []
    assert _sanity.check_acceleration_offset(r.name, dataclasses.replace(r, a=None), topo) == []
    _, msgs = _fit([biased, *recs[1:]])
    assert _has(msgs, f"{r.name}: the measured acceleration of DOF 0 holds an offset")


def test_5_different_masses_are_refused(nes):
    _, recs = nes
    heavier = dataclasses.replace(recs[1], masses=recs[1].masses * 1.5)
    with pytest.raises(g.GMRInputError, match=r"nes_S1 and nes_S2 carry different masses \(\[0.035\] and"):
        g.reconstruct([recs[0], heavier, recs[2]])
    # explicit masses settle it
    g.reconstruct([recs[0], heavier, recs[2]], masses=[0.035])


def test_6_large_vibration(joint):
    s = g.systems.bistable_joint("position_dependent")
    _, msgs = _fit(g.systems.make_recordings(s, np.deg2rad(30.0), seed=0, duration=DURATION))
    assert _has(msgs, "joint_pd_S1 (DOF 0): vibration amplitude", "% of the distance", "GMR assumes small")
    assert not _has(msgs, "does not stay in one well")


def test_7_low_training_r2(nes_swinging):
    _, msgs = nes_swinging
    assert _has(msgs, "nes_S1 (DOF 0): the model explains its own training data poorly (R² -")


def test_9_global_shape_outside_and_between_the_data(nes_swinging):
    """Rule 9 on the NES driven across its wells (a 16th-degree law), and on hand-made
    restoring laws around recorded wells at +-1 (amplitude 0.05)."""
    _, msgs = nes_swinging
    assert _has(msgs, "DOF 0: the restoring force turns outward beyond x = ", "F -> -inf as x -> +inf", "runs away")
    eq, amp, k = np.array([-1.0, 1.0]), np.array([0.05, 0.05]), np.array([2.0, 2.0])
    # -x + x^3: clean
    assert _sanity.check_global_shape(0, [0, -1, 0, 1], eq, amp, k) == []
    # (x^2 - 1) x (x^2 - 2.25) (x^2 - 4): extra wells at +-2 (F' > 0 there), within one span
    spurious = np.polynomial.polynomial.polyfromroots([-2, -1.5, -1, 0, 1, 1.5, 2])
    msgs = _sanity.check_global_shape(3, spurious, eq, amp, k)
    assert _has(msgs, "DOF 3: the model has a well", "x = -2, 2", "spurious outer well")
    # x (x^2 - 1) (1.69 - x^2): turns outward at |x| = 1.3, barrier 0.027 < interwell energy 0.34
    msgs = _sanity.check_global_shape(0, [0, -1.69, 0, 2.69, 0, -1], eq, amp, k)
    assert _has(msgs, "turns outward beyond x = 1.3 ", "x -> +inf") and _has(msgs, "beyond x = -1.3 ", "x -> -inf")
    # the NES truth turns outward too, but far enough: no warning
    nes = g.systems.tristable_nes()
    assert _sanity.check_global_shape(0, g.systems.NES_ALPHA, nes.equilibria[:, 0], np.full(3, 1.5e-3),
                                      np.array([190.0, 157.0, 155.0])) == []


@pytest.mark.slow  # 9-12 s: the default tier's 5 min; CI runs the slow tier too
def test_10_default_orders_on_sinusoidal_records(joint):
    """Displacement-only records of a steady 10 Hz sine, two noise seeds. On the raw library columns the default
    (5, 5) library gave an 11th-degree global law that blew up between the wells. With the columns through the
    differentiation filter's gain (`_filter_gain.filter_gain`), the local fits are right and the law is within
    1 % of the truth, with no fault warned."""
    ts = jnp.arange(int(DURATION * 1000) + 1) / 1000.0
    inp = g.BaseSine(np.deg2rad(1.0), 10.0)
    base = np.asarray(jax.vmap(lambda t: inp(t)[0])(ts))
    clean = [np.asarray(g.simulate(joint.truth, inp, ts, xe).value[0]) for xe in joint.equilibria]
    x = np.linspace(-1.5, 1.5, 301) * joint.equilibria.max()
    truth = np.polynomial.polynomial.polyval(x, [0.0, *g.systems.JOINT_STIFFNESS[:1], 0.0, g.systems.JOINT_STIFFNESS[1]])

    def error(sol):
        model = np.polynomial.polynomial.polyval(x, np.asarray(sol.value.stiffness[0]))
        return np.linalg.norm(model - truth) / np.linalg.norm(truth)

    for seed in (2, 0):
        rng = np.random.default_rng(seed)
        recs = [g.Recording(t=np.asarray(ts), x=g.add_noise(x0, 60.0, rng), base_acc=base, masses=np.ones(1),
                            name=f"sine_S{i + 1}") for i, x0 in enumerate(clean)]
        sol, msgs = _fit(recs)
        assert error(sol) < 0.01, (seed, error(sol))  # measured 0.29 % and 0.018 %
        assert not _has(msgs, "poorly") and not _has(msgs, "blew up") and not _has(msgs, "spurious")


def test_cli_prints_warnings_records_them_and_strict_exits_3(nes, tmp_path, capsys):
    _, recs = nes
    paths = []
    for r in recs:
        if r.name == "nes_S1":
            r = dataclasses.replace(r, x=np.minimum(r.x, np.percentile(r.x, 97)))
        paths.append(str(tmp_path / f"{r.name}.npz"))
        g.save_recording(r, paths[-1])
    out = tmp_path / "m.json"
    capsys.readouterr()
    assert main(["fit", *paths, "--out", str(out), "--no-figure"]) == 0  # the figure: test_cli
    err = capsys.readouterr().err
    assert err.startswith("warning: nes_S1: column x0 looks clipped")
    saved = json.loads(out.read_text())
    assert saved["format"] == "gmr-model/1" and "clipped" in saved["warnings"][0]
    # one line per warning, each the start of the stored sentence and its fix (the full text: the model file)
    from gmr_jax._cli._args import short_warning

    assert err.splitlines() == [f"warning: {short_warning(w).replace('gmr show MODEL', f'gmr show {out}')}"
                                for w in saved["warnings"]]
    assert main(["fit", *paths, "--out", str(out), "--strict", "--no-figure"]) == 3
    assert "--strict" in capsys.readouterr().err and out.exists()
    # a refusal is an input error: exit 2, one line naming both files
    heavy = tmp_path / "heavy.npz"
    g.save_recording(dataclasses.replace(recs[1], masses=recs[1].masses * 2, name="heavy"), heavy)
    assert main(["fit", paths[0], str(heavy), paths[2], "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "nes_S1 and heavy carry different masses" in err and len(err.splitlines()) == 1


@pytest.mark.slow  # a full reconstruction
def test_noisy_nes_band_says_how_far_off_it_is():
    """NES at 20 dB, 5 s records: the restoring force is off the truth by more than at 60 dB, and the band
    `gmr fit` prints (two standard errors, RMS over the data's span) is of that size: it holds the error and is
    not vacuous."""
    s = g.systems.tristable_nes()
    recs = g.systems.make_recordings(s, 5e-4, snr_db=20.0, seed=0, duration=DURATION)
    sol, _ = _fit(recs)
    err = g.metrics.restoring_error(sol.value, s.truth, 0, s.x_range[0])
    xs = np.concatenate([r.x[:, 0] for r in recs])
    rel = _sanity.restoring_uncertainty(sol.value.stiffness[0], sol.value.covariance[0], xs.min(), xs.max())
    assert err < rel < 20 * err, (err, rel)


@pytest.mark.slow  # one reconstruction (~20 s)
@pytest.mark.xfail(strict=True, reason="x only at 30 dB, 0.45 % sweeps: the default resolves the value and slope at "
                   "each well but not the curvature (14-54 % over the box; the value-and-slope oracle is 14.6 %)")
def test_displacement_only_noisy_sweeps_resolve_the_curvature():
    """Shallow arch, x only, 30 dB, 0.45 % sweeps: the training R² is low (the balance's target holds the
    noise of x twice differentiated) but the law is within 3 % of the truth and no "explains its own
    training data poorly" warning."""
    s = g.systems.shallow_arch()
    recs = [g.Recording(t=r.t, x=r.x, base_acc=r.base_acc, masses=r.masses, name=r.name)
            for r in g.systems.make_recordings(s, 8.34e-4, snr_db=30.0, seed=0)]
    sol, msgs = _fit(recs, throw=False)
    assert restoring_error(sol.value, s.truth, 0, s.x_range[0]) < 0.03
    assert not _has(msgs, "poorly")


def _sine_outcome(joint, seed: int):
    """Displacement-only records of the bistable joint's steady response to a 1 degree, 10 Hz base sine about
    each well at 30 dB (noise seed `seed`), reconstructed with the defaults: the global law's slope F' at
    each well, its v^3 coefficient, and the restoring error against the truth's cubic over 1.5 x the wells'
    span (NumPy)."""
    ts = jnp.arange(int(DURATION * 1000) + 1) / 1000.0
    inp = g.BaseSine(np.deg2rad(1.0), 10.0)
    base = np.asarray(jax.vmap(lambda t: inp(t)[0])(ts))
    rng = np.random.default_rng(seed)
    recs = [g.Recording(t=np.asarray(ts), x=g.add_noise(np.asarray(g.simulate(joint.truth, inp, ts, xe).value[0]),
                                                          30.0, rng), base_acc=base, masses=np.ones(1),
                        name=f"sine_S{i + 1}") for i, xe in enumerate(joint.equilibria)]
    x = np.linspace(-1.5, 1.5, 301) * joint.equilibria.max()
    truth = np.polynomial.polynomial.polyval(x, [0.0, *g.systems.JOINT_STIFFNESS[:1], 0.0, g.systems.JOINT_STIFFNESS[1]])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = g.reconstruct(recs, throw=False)
    k = np.asarray(sol.value.stiffness[0])
    slope = np.polynomial.polynomial.polyval(np.asarray(joint.equilibria)[:, 0], np.polynomial.polynomial.polyder(k))
    model = np.polynomial.polynomial.polyval(x, k)
    return slope, float(sol.value.velocity_damping[0, 3]), np.linalg.norm(model - truth) / np.linalg.norm(truth)


@pytest.mark.slow  # two reconstructions of 10 Hz sine records (~20 s)
@pytest.mark.xfail(strict=True, reason="single 10 Hz tones from x at 30 dB: the default's slope at the wells is "
                   "2.6-2.8 % low on both seeds")
@pytest.mark.parametrize("seed", [1, 3])
def test_steady_sines_from_displacement_give_the_law_and_its_cubic_damping(joint, seed):
    """Displacement-only 10 Hz sines at 30 dB: on the fundamental the viscous v can stand in for the truth's
    10 v^3 and collinear powers of v share the dissipation; the law's slope at both wells within 1 % of the
    truth's, the restoring law within 0.5 % over 1.5 x the wells' span, v^3 within 5 %."""
    slope, cubic, err = _sine_outcome(joint, seed)
    true_slope = -2.0 * g.systems.JOINT_STIFFNESS[0]
    assert np.all(np.abs(slope / true_slope - 1) < 0.01), slope
    assert abs(cubic / 10.0 - 1) < 0.05, cubic
    assert err < 0.005, err


def test_6b_one_file_in_other_units_is_reported(nes):
    """Rule 6b (`check_scales`): the NES's records vibrate within 1.12 x of each other (the built-in systems within
    10.2 x, the torque-free Kresling's stiff deployed well); one record's x in mm (1000 x) is reported with the
    likely cause, the clean set is not."""
    _, recs = nes
    names = [r.name for r in recs]
    xs = [r.x[:, 0] for r in recs]
    assert _sanity.check_scales(0, names, xs, [0, 1, 2]) == []
    msgs = _sanity.check_scales(0, names, [xs[0], xs[1] * 1e3, xs[2]], [0, 1, 2])
    assert len(msgs) == 1 and "nes_S2 vibrates" in msgs[0] and "about 1000: one file in mm" in msgs[0], msgs
    # two records of one well: the well's largest counts, a quiet repeat of it is no mismatch
    assert _sanity.check_scales(0, names[:2], [xs[0], xs[0] * 1e-3], [0, 0]) == []


def test_a_force_input_without_masses_is_warned():
    """Audit 8: a 0.1 kg oscillator driven by a measured force, no mass given: the unit mass is not a rescaling
    there (damping 10x off, the warnings blamed hops); said, and not for base-driven records."""
    from gmr_jax._reconstruct._reconstruct import _resolve

    t = np.arange(2000) * 0.01
    def rec(x0, **inputs):
        return g.Recording(t=t, x=x0 + 0.01 * np.sin(3 * t), name=f"w{x0:+g}", **inputs)

    forced = [rec(-1.0, force=np.sin(2 * t)), rec(1.0, force=np.sin(2 * t))]
    msgs = _resolve(forced, None, None)[3]
    assert _has(msgs, "driven by a force: each mass is taken as 1", "--masses M"), msgs
    assert not _has(_resolve(forced, np.array([0.1]), None)[3], "driven by a force")
    based = [rec(-1.0, base_acc=np.sin(2 * t)), rec(1.0, base_acc=np.sin(2 * t))]
    assert not _has(_resolve(based, None, None)[3], "driven by a force")
