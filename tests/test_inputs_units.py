"""What a new user meets first: inputs in any form, units that cannot silently be wrong, short CLI output."""

import os
import subprocess
import sys

import numpy as np
import pytest

import gmr_jax as g
from gmr_jax._cli._args import short_warning
from gmr_jax._cli._fit import _derivation_notes
from gmr_jax._cli._main import main
from gmr_jax._reconstruct._sanity import check_force_units, force_balance_factors
from gmr_jax._recordings._inputs import as_recording, as_recordings
from gmr_jax._topology import as_topology


@pytest.fixture(scope="module")
def joint():
    s = g.systems.bistable_joint("position_dependent")
    return g.systems.make_recordings(s, np.deg2rad(1.0), snr_db=45.0, seed=1, duration=4.0)


def _forced(rec, scale=1.0, sensing="xva"):
    """The record as the same motion under a force on the mass (force = -m base_acc, a relative), lengths x scale."""
    m = np.asarray(rec.masses, float)
    b = np.asarray(rec.base_acc, float)
    return g.Recording(t=rec.t, x=rec.x * scale, v=None if sensing == "x" else rec.v * scale,
                       a=None if sensing == "x" else (rec.a - b[:, None]) * scale, force=-b[:, None] * m,
                       masses=m, name=rec.name).complete("independent")


@pytest.mark.parametrize("sensing", ["xva", "x"])
def test_force_balance_names_a_length_unit_slip(joint, sensing):
    topo = as_topology("independent")
    r = joint[0]
    clean = _forced(r, 1.0, sensing)
    (mu, se), = force_balance_factors(clean, topo, clean.masses)
    assert abs(mu - 1) < 0.05 and se < 0.05
    assert check_force_units(r.name, clean, topo, clean.masses) == []
    for scale, said in ((1e3, "lengths in mm where the file says m (factor 1000)"),
                        (1e-3, "lengths in m where the file says mm (factor 0.001)")):
        rec = _forced(r, scale, sensing)
        msgs = check_force_units(r.name, rec, topo, rec.masses)
        assert len(msgs) == 1 and said in msgs[0], msgs
    # a base excitation scales with the kinematics: nothing to read, nothing said
    assert check_force_units(r.name, r.complete("independent"), topo, r.masses) == []


def test_reconstruct_runs_the_units_check(joint):
    from gmr_jax._reconstruct._reconstruct import _resolve

    recs = [_forced(r, 1e3) for r in joint]
    *_, warns = _resolve(recs, None, None)
    assert sum("factor 1000" in w for w in warns) == len(recs)
    *_, warns = _resolve([_forced(r) for r in joint], None, None)
    assert not any("units:" in w for w in warns)


def test_recordings_from_paths_dicts_and_structured_arrays(joint, tmp_path):
    r = joint[0]
    p = tmp_path / "w.npz"
    g.save_recording(r, p)
    from_path = as_recording(str(p))
    np.testing.assert_allclose(from_path.x, r.x)
    d = as_recording({"time": r.t, "x": r.x[:, 0], "base_acc": r.base_acc, "m": np.ones(r.t.size)}, 3)
    assert d.name == "recording 3" and d.x.shape == r.x.shape and np.allclose(d.masses, [1.0])
    s = np.zeros(r.t.size, dtype=[("t", float), ("x", float), ("force", float)])
    s["t"], s["x"] = r.t, r.x[:, 0]
    assert as_recording(s).force.shape == (r.t.size, 1)
    with pytest.raises(g.GMRInputError, match="without field names"):
        as_recording(np.zeros((10, 3)))
    with pytest.raises(g.GMRInputError, match="unknown field"):
        as_recording({"t": r.t, "disp": r.x})
    with pytest.raises(g.GMRInputError, match="wrap it in a list"):
        as_recordings(str(p))
    with pytest.raises(g.GMRInputError, match="wrap it in a list"):
        g.reconstruct(str(p))


def test_a_mapped_lab_header_carries_its_units(joint, tmp_path):
    r = joint[0]
    p = tmp_path / "lab.csv"
    np.savetxt(p, np.column_stack([r.t * 1e3, r.x[:, 0] * 1e3, r.base_acc]), delimiter=",", comments="",
               header="time [ms],disp [mm],table [m/s^2]")
    rec = g.load_recording(p, columns={"t": "time", "x": "disp", "base_acc": "table"})
    assert rec.length_unit == "mm"
    np.testing.assert_allclose(rec.t, r.t, atol=1e-12)
    np.testing.assert_allclose(rec.x, r.x * 1e3)
    np.testing.assert_allclose(rec.base_acc, r.base_acc * 1e3)  # one length unit: mm/s^2
    plain = g.load_recording(p, columns={"t": "time*1e-3", "x": "disp*1e-3", "base_acc": "table*1"})
    assert plain.length_unit is None  # a field computed from numbers is taken as it comes
    np.testing.assert_allclose(plain.x, r.x)


def test_compilation_cache_is_on_for_the_python_api(tmp_path):
    env = {k: v for k, v in os.environ.items() if not k.startswith("JAX_COMPILATION_CACHE")}
    code = "import gmr_jax, jax; print(jax.config.jax_compilation_cache_dir)"
    for setting, expected in ((str(tmp_path / "c"), str(tmp_path / "c")), ("off", "None")):
        out = subprocess.run([sys.executable, "-c", code], env=env | {"GMR_CACHE_DIR": setting},
                             capture_output=True, text=True, check=True).stdout.strip()
        assert out == expected


def test_derivation_notes_say_what_was_estimated_from_what(joint):
    r = joint[0]
    only_a = g.Recording(t=r.t, x=r.x, v=r.v, base_acc=r.base_acc, name="a")
    notes = _derivation_notes([only_a])
    assert len(notes) == 1 and "a differentiated from x" in notes[0] and "v differentiated" not in notes[0]
    x_only = g.Recording(t=r.t, x=r.x, base_acc=r.base_acc, name="x")
    assert "v differentiated from x, a differentiated from x" in _derivation_notes([x_only])[0]
    assert _derivation_notes([r]) == []


def test_short_warning_is_one_line_with_its_fix():
    msg = ("rec1: the measured velocity of DOF 0 is 1000 times the first derivative of its x (correlation 0.999; a "
           "power of 1000, as with t in ms or x in mm where the others are in s and m): the columns' units or signs "
           "disagree, and the fit takes them as consistent (the factor goes into the damping forces): fix the "
           "scale of t, x or v (e.g. --columns 'v=COLUMN*FACTOR')")
    s = short_warning(msg)
    assert "\n" not in s and len(s) <= 220 and s.startswith("rec1: the measured velocity") and "fix the scale" in s
    assert short_warning("short: give masses") == "short: give masses"


def test_every_fit_option_shows_its_default(capsys):
    with pytest.raises(SystemExit):
        main(["fit", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    for shown in ("local restoring fit (default: 5)", "(default: gmr)", "evidence (default:", "(default: from recordings"):
        assert shown in text, shown


def test_unit_checks_before_a_fit(joint):
    recs = [_forced(r, 1e3) for r in joint]
    said = g.unit_checks(recs)
    assert len(said) == len(recs) and all("factor 1000" in m for m in said)
    assert g.unit_checks([_forced(r) for r in joint]) == []
    assert g.unit_checks([_forced(r, 1.5) for r in joint]) == []  # within the default factor 3
    assert len(g.unit_checks([_forced(r, 1.5) for r in joint], factor=1.2)) == len(recs)
