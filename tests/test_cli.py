import json
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import gmr_jax as g
from gmr_jax.metrics._metrics import restoring_error
from gmr_jax._cli._main import main
from gmr_jax._cli._show import describe, equilibria


def run(args):
    return subprocess.run([sys.executable, "-m", "gmr_jax._cli._main", *args], capture_output=True, text=True)


@pytest.fixture(scope="module")
def joint_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    s = g.systems.bistable_joint("position_independent")
    recs = g.systems.make_recordings(s, np.deg2rad(1.0), seed=1, duration=5.0)
    paths = []
    for r in recs:
        p = d / f"{r.name}.csv"
        # by hand: only t, x and the base input, as a user with a displacement sensor would have
        np.savetxt(p, np.column_stack([r.t, r.x[:, 0], r.base_acc]), delimiter=",",
                   header="t,x0,base_acc", comments="")
        paths.append(str(p))
    return paths


def test_fit_masses_scale_the_forces(joint_files, tmp_path, capsys):
    # --masses: the inertial force m a is the regression's target, so every coefficient scales with m
    # (against the unit-mass fit of the same files); a bad list is refused by name
    one, two = tmp_path / "one.json", tmp_path / "two.json"
    assert main(["fit", *joint_files, "--out", str(one), "--no-figure"]) == 0
    capsys.readouterr()
    assert main(["fit", *joint_files, "--out", str(two), "--no-figure", "--masses", "2"]) == 0
    assert "taken as 1" not in capsys.readouterr().out
    m1, m2 = g.load_model(one), g.load_model(two)
    np.testing.assert_allclose(np.asarray(m2.masses), [2.0])
    np.testing.assert_allclose(np.asarray(m2.stiffness), 2 * np.asarray(m1.stiffness), rtol=1e-6, atol=1e-9)
    r = run(["fit", *joint_files, "--out", str(tmp_path / "bad.json"), "--masses", "1,x"])
    assert r.returncode == 2 and "--masses must be comma-separated numbers" in r.stderr and "Traceback" not in r.stderr


def test_fit_hand_made_csv(joint_files, tmp_path, capsys):
    out = tmp_path / "model.json"
    assert main(["fit", *joint_files, "--out", str(out)]) == 0
    m = g.load_model(out)
    k = np.asarray(m.stiffness)[0]
    np.testing.assert_allclose([k[1], k[3]], [-2244, 1755], rtol=0.03)
    printed = capsys.readouterr().out
    # short: the model, its wells, the fit, what was estimated from what, the figure, where the detail is
    assert len(printed.strip().splitlines()) <= 15, printed
    assert "v differentiated from x, a differentiated from x" in printed and "F_0(x, v)" in printed
    assert "taken as 1" in printed  # no masses: said, not silent
    lo, hi = json.loads(out.read_text())["data_range"][0]
    near = [(x, s) for x, s in equilibria(m.stiffness)[0] if lo - (hi - lo) / 2 <= x <= hi + (hi - lo) / 2]
    wells = [x for x, s in near if s > 0]
    assert "stable wells at x = " + ", ".join(f"{x:.4g}" for x in wells) in printed
    far = len(equilibria(m.stiffness)[0]) - len(near)  # zeros of the law far outside the data: said as such
    assert (f"{far} more zero" in printed) == (far > 0)
    # the band the file's covariance gives the restoring force is printed
    from gmr_jax._reconstruct._sanity import restoring_uncertainty

    xs = np.concatenate([g.load_recording(f).x[:, 0] for f in joint_files])
    band = restoring_uncertainty(k, np.asarray(m.covariance)[0], float(xs.min()), float(xs.max()))
    assert f"restoring-force band ±{100 * band:.2g} %" in printed
    # the stored standard errors, term by term, and the route and degree per DOF: gmr show (--detail)
    shown = describe(out, detail=True)
    assert "std. error" in shown and "from the data's noise" in shown
    route = json.loads(out.read_text())["coordination"][0]
    assert route["route"] == "evidence" and f"evidence, restoring degree {route['degree']}" in shown
    assert "restoring degree" not in describe(out)
    x3 = next(t for t in json.loads(out.read_text())["terms"] if t["physics"] == "stiffness" and t["order"] == 3)
    row = next(line for line in shown.splitlines() if line.split()[:2] == ["x^3", "stiffness"])
    assert float(row.split()[3]) == pytest.approx(x3["stderr"], rel=1e-2)
    # the figure: PNG and PDF beside the model, a real image (restoring, damping, residual panels)
    png, pdf = tmp_path / "model_fit.png", tmp_path / "model_fit.pdf"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and pdf.read_bytes()[:5] == b"%PDF-"
    assert str(png) in printed
    import matplotlib.image

    img = matplotlib.image.imread(png)
    assert img.shape[0] > 200 and img.shape[1] > 1000 and np.std(img[..., :3]) > 0.05
    written = json.loads(out.read_text())
    assert written["format"] == "gmr-model/1"
    # the region the model was fitted on, per DOF (where basins/actuate look for wells)
    x = np.concatenate([np.loadtxt(p, delimiter=",", skiprows=1)[:, 1] for p in joint_files])
    np.testing.assert_allclose(written["data_range"], [[x.min(), x.max()]])
    # and the speeds its damping law was fitted at (x only here: v as the fit estimated it, close to x's central
    # difference)
    data = [np.loadtxt(p, delimiter=",", skiprows=1) for p in joint_files]
    v = np.concatenate([np.gradient(d[:, 1], d[1, 0] - d[0, 0]) for d in data])
    np.testing.assert_allclose(written["speed_range"], [[v.min(), v.max()]], rtol=0.05)
    # a model saved from Python carries what gmr fit writes (audit: data_range, coordination and resolution were
    # missing, so basins and actuate read it as a hand-written model)
    sol = g.reconstruct([g.load_recording(p) for p in joint_files])
    g.save_model(sol, tmp_path / "api.json")
    api = json.loads((tmp_path / "api.json").read_text())
    for key in ("method", "library", "training", "data_range", "speed_range", "coordination"):
        assert key in api, key
        if key in ("data_range", "speed_range", "library", "method"):
            assert api[key] == written[key], key


@pytest.mark.slow
def test_fit_manual_threshold_and_baseline(joint_files, tmp_path):
    """A fixed threshold and the baseline (GMC-SINDy) from the CLI; end to end, so slow tier (the
    baseline itself is tested in test_reconstruct, its vmapped threshold kernels in test_stls)."""
    assert main(["fit", *joint_files, "--out", str(tmp_path / "a.json"), "--threshold", "0.01"]) == 0
    assert main(["fit", *joint_files, "--out", str(tmp_path / "b.json"), "--method", "gmc-sindy", "-r", "7", "-d", "7"]) == 0
    a, b = (json.loads((tmp_path / n).read_text()) for n in ("a.json", "b.json"))
    assert a["method"] != b["method"] and "sindy" in b["method"].lower(), (a["method"], b["method"])
    assert b["library"] == {"r": 7, "d": 7}


def _saved(recs, tmp_path) -> list[str]:
    """Each recording saved as `<name>.npz` under `tmp_path` (`Recording.save`); their paths."""
    paths = [str(tmp_path / f"{r.name}.npz") for r in recs]
    for r, p in zip(recs, paths):
        r.save(p)
    return paths


def _bad(tmp_path, name, **arrays):
    p = tmp_path / name
    np.savez(p, **arrays)
    return str(p)


def _main(args, capsys):
    """The command in-process (no interpreter start-up): (exit status, stderr)."""
    capsys.readouterr()
    rc = main(args)
    return rc, capsys.readouterr().err


def test_bad_inputs_one_line_exit_2(joint_files, tmp_path, capsys):
    t = np.arange(1000) * 1e-3
    x = np.sin(t)[:, None]
    cases = {
        "NaN": _bad(tmp_path, "nan.npz", t=t, x=np.where(t[:, None] > 0.5, np.nan, x)),
        "not uniformly sampled": _bad(tmp_path, "nonuni.npz", t=t**1.2, x=x),
        "only 10 samples": _bad(tmp_path, "short.npz", t=t[:10], x=x[:10]),
        "shape": _bad(tmp_path, "shape.npz", t=t, x=x[:900]),
    }
    for msg, path in cases.items():
        rc, err = _main(["fit", path, joint_files[0], "--out", str(tmp_path / "m.json")], capsys)
        assert rc == 2, err
        assert msg in err and "Traceback" not in err
        assert len(err.strip().splitlines()) == 1
    rc, err = _main(["fit", *joint_files, "--out", str(tmp_path / "m.json"), "--figure", "fit.jpg"], capsys)
    assert rc == 2 and "--figure must name a .png" in err and not (tmp_path / "m.json").exists()
    rc, err = _main(["fit", joint_files[0], "--out", str(tmp_path / "m.json")], capsys)
    assert rc == 2 and "at least two distinct equilibria" in err and "Traceback" not in err
    rc, err = _main(["fit", joint_files[0], joint_files[0], "--out", str(tmp_path / "m.json")], capsys)
    assert rc == 2 and "same equilibrium" in err
    # the installed entry point, in a fresh interpreter: same one line, same status
    r = run(["fit", str(tmp_path / "missing.csv"), "--out", str(tmp_path / "m.json")])
    assert r.returncode == 2 and "no such file" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


def test_basins_cli(tmp_path, capsys):
    terms = []
    for i, (k1, k3) in enumerate([(-30.0, 1e5), (-60.0, 2e5)]):
        terms += [{"dof": i, "physics": "stiffness", "order": 1, "coefficient": k1},
                  {"dof": i, "physics": "stiffness", "order": 3, "coefficient": k3},
                  {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": 0.5}]
    g.save_model(g.from_terms([0.05, 0.05], terms, "chain"), tmp_path / "m.json")
    out = tmp_path / "b"
    # the contract's shape, as written: no --x-range; the wells come from the model
    assert main(["basins", str(tmp_path / "m.json"), "--f", "0.5:4:3", "--A", "0.3:2.5:2", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "stable roots of the restoring polynomial" in printed
    z = np.load(out / "basins.npz")
    assert z["wells"].shape == (2, 3, 2) and z["config"].shape == (2, 3) and (out / "basins.png").exists() and (out / "basins.pdf").exists()
    assert np.all(z["config"] >= 0)
    # a map with unclassified points: the summary says how many and why, exit 0, map written
    out2 = tmp_path / "b2"
    assert main(["basins", str(tmp_path / "m.json"), "--f", "0.5:4:3", "--A", "0.3:2.5:2", "--settle-time",
                 "0.01", "--out", str(out2)]) == 0
    printed = capsys.readouterr().out
    z2 = np.load(out2 / "basins.npz")
    n_bad = int(np.sum(z2["config"] < 0))
    assert n_bad > 0 and f"-1 (not classified): {n_bad} not settled" in printed
    assert np.all(z2["result"][z2["config"] < 0] == g.RESULTS.not_settled._value)
    # ... and what settle time the model needs (its slowest linearised decay); with it every point settles
    advice = next(line for line in printed.splitlines() if "points not settled" in line)
    need = float(advice.rsplit("--settle-time ", 1)[1])
    assert 0.01 < need < 100, advice
    out4 = tmp_path / "b4"
    assert main(["basins", str(tmp_path / "m.json"), "--f", "0.5:4:3", "--A", "0.3:2.5:2", "--settle-time",
                 str(need), "--out", str(out4)]) == 0
    assert np.all(np.load(out4 / "basins.npz")["config"] >= 0) and "points not settled" not in capsys.readouterr().out
    # --x-range still overrides, and the same wells come out
    out3 = tmp_path / "b3"
    assert main(["basins", str(tmp_path / "m.json"), "--f", "0.5:4:3", "--A", "0.3:2.5:2", "--x-range=-0.05:0.05",
                 "--out", str(out3)]) == 0
    np.testing.assert_allclose(np.load(out3 / "basins.npz")["wells"], z["wells"])


def test_settle_advice_is_the_decay_time_of_the_slowest_mode():
    # one DOF, m x'' + c x' - k1 x + k3 x^3 = 0: about a well the decay rate is c / (2 m) (underdamped),
    # so the advice is 7 / (c / 2m) = 14 m / c; an undamped model is told no settle time will do
    from gmr_jax._cli._basins import _settle_advice

    m, c = 2.0, 0.1
    terms = [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -1.0},
             {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1.0},
             {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": c}]
    wells = np.array([[-1.0, 1.0]])
    said = _settle_advice(g.from_terms([m], terms), wells, 10.0)
    assert f"decays at {c / (2 * m):.3g} 1/s" in said and f"--settle-time {14 * m / c:g}" in said, said
    said = _settle_advice(g.from_terms([m], terms[:2]), wells, 10.0)
    assert "does not decay" in said and "no settle time will do" in said, said


@pytest.mark.slow
def test_fit_chain_recordings_one_file_per_configuration(tmp_path, capsys):
    """`gmr fit` on a chain: one NPZ per configuration (folded, deployed) of the 3-cell Kresling
    chain; the model is a 3-DOF chain with every cell's restoring force and wells right."""
    s = g.systems.kresling3()
    paths = []
    for r in g.systems.make_recordings(s, 3e-4, seed=0, duration=15.0):
        p = tmp_path / f"{r.name}.npz"
        g.save_recording(r, p)
        paths.append(str(p))
    out = tmp_path / "chain.json"
    assert main(["fit", *paths, "--out", str(out)]) == 0
    assert "DOF 2" in capsys.readouterr().out
    m = g.load_model(out)
    assert m.topology == "chain" and m.n_dof == 3
    np.testing.assert_allclose(np.asarray(m.masses), np.asarray(s.truth.masses))
    for i in range(3):
        assert restoring_error(m, s.truth, i, s.x_range[i]) < 0.03
    wells = g.stable_wells(m, s.x_range)
    np.testing.assert_allclose(wells[:, :2], s.equilibria.T, atol=0.02 * np.ptp(s.equilibria))
    # basins on the fitted chain as the contract writes it (no --x-range): the wells come from the
    # model within its recorded data range, and they are the truth's
    assert main(["basins", str(out), "--f", "1:3:2", "--A", "0.01:0.02:2", "--out", str(tmp_path / "b")]) == 0
    assert "within the training data range" in capsys.readouterr().out
    z = np.load(tmp_path / "b" / "basins.npz")
    assert z["config"].shape == (2, 2)


@pytest.mark.slow
def test_chain_demo_kresling3(tmp_path):
    """`gmr demo --system kresling3`: per-cell report, figures, models; GMR within the chain
    targets (restoring <= 3 %, equilibria right, resonances within 2 %).

    Run as a subprocess without the suite's `--xla_backend_optimization_level=0`: the long
    transmissibility sweeps execute several times slower unoptimised (245-324 s in process
    against ~95 s); the results are the same to the last digit."""
    import os

    flags = " ".join(f for f in os.environ.get("XLA_FLAGS", "").split() if "optimization_level" not in f)
    r = subprocess.run([sys.executable, "-m", "gmr_jax._cli._main", "demo", "--system", "kresling3", "--out",
                        str(tmp_path)], capture_output=True, text=True, env=dict(os.environ, XLA_FLAGS=flags))
    assert r.returncode == 0, r.stderr[-2000:]
    rep = json.loads((tmp_path / "report_kresling3.json").read_text())
    assert len(rep["cells"]) == 3
    for c in rep["cells"]:
        assert c["gmr"]["restoring_error"] < 0.03 and c["gmr"]["equilibria_ok"]
        assert (tmp_path / f"cell{c['cell']}_kresling3.png").exists()
    for conf in ("folded", "deployed"):
        assert len(rep["transmissibility"][conf]["truth"]["peaks"]) >= 2
        assert rep["transmissibility"][conf]["GMR"]["max_peak_error"] < 0.02
    assert (tmp_path / "transmissibility_kresling3.png").exists()
    m = g.load_model(tmp_path / "model_gmr_kresling3.json")
    assert m.n_dof == 3 and m.topology == "chain"
    # the fits' warnings go into the report (the baseline's inadmissible laws among them), not between its lines
    assert set(rep["warnings"]) == {"gmr", "gmc"}
    assert "Warnings of the fits" in (tmp_path / "report_kresling3.md").read_text()
    assert "GMRDataWarning" not in r.stderr


def test_fast_compile_flags_only_before_jax_starts(monkeypatch):
    """`gmr fit` compiles with XLA:CPU's older loop emitters (a third faster to compile): the
    flag is added to XLA_FLAGS in a fresh process, once, and never after JAX has started (where
    it would do nothing) or over the user's own choice."""
    import os

    from gmr_jax._config import fast_compile_flags

    code = ("import os, gmr_jax; from gmr_jax._config import fast_compile_flags as f; "
            "a = f(); b = f(); print(a, b, os.environ['XLA_FLAGS'])")
    env = dict(os.environ, XLA_FLAGS="--xla_backend_optimization_level=0")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert out.split() == ["True", "False", "--xla_backend_optimization_level=0", "--xla_cpu_use_fusion_emitters=false"]
    env["XLA_FLAGS"] = "--xla_cpu_use_fusion_emitters=true"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert out.split() == ["False", "False", "--xla_cpu_use_fusion_emitters=true"]
    __import__("jax").numpy.zeros(1).block_until_ready()  # started in this process
    monkeypatch.setenv("XLA_FLAGS", "")
    assert fast_compile_flags() is False and os.environ["XLA_FLAGS"] == ""
