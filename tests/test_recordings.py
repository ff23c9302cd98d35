import dataclasses
import warnings

import numpy as np
import pytest

import gmr_jax as g


def rec(n=500, d=1):
    t = np.arange(n) * 1e-3
    x = np.sin(2 * np.pi * 5 * t)[:, None] * np.ones((1, d))
    return g.Recording(t=t, x=x, base_acc=np.zeros(n))


@pytest.mark.parametrize("ext", ["npz", "csv"])
def test_round_trip(tmp_path, ext):
    r = rec(d=2)
    r = g.Recording(t=r.t, x=r.x, v=r.x * 2, force=r.x * 3, masses=np.array([1.0, 0.5]))
    p = tmp_path / f"r.{ext}"
    g.save_recording(r, p)
    r2 = g.load_recording(p)
    for k in ("t", "x", "v", "force", "masses"):  # a CSV keeps the masses as columns m0, m1 (they were dropped)
        np.testing.assert_allclose(getattr(r2, k), getattr(r, k), rtol=1e-15 if ext == "npz" else 1e-12)


def test_a_csv_mass_column_and_a_chain_without_masses(tmp_path):
    """A one-DOF 'mass [kg]' column repeating one value is the recording's mass; one that varies is refused. A
    chain fitted with no masses anywhere is warned (unit masses are a rescaling only when they are equal); one
    DOF, or masses given, is not."""
    from gmr_jax._reconstruct._reconstruct import _resolve

    t = np.arange(0.0, 2.0, 1e-3)
    x = 0.1 * np.sin(5 * t)
    rows = "\n".join(f"{a:.17g},{b:.17g},{c:.17g}" for a, b, c in zip(t, x, np.full_like(t, 0.25)))
    (tmp_path / "m.csv").write_text("t,x,mass [kg]\n" + rows)
    assert g.load_recording(tmp_path / "m.csv").masses.tolist() == [0.25]
    (tmp_path / "bad.csv").write_text("t,x,m\n" + rows.replace(",0.25\n", ",0.5\n", 1))
    with pytest.raises(g.GMRInputError, match="the mass column varies over the record"):
        g.load_recording(tmp_path / "bad.csv")
    chain = [g.Recording(t=t, x=np.stack([x + e, x - e], 1), base_acc=np.sin(7 * t), name=f"c{e}") for e in (-1, 1)]
    *_, warned = _resolve(chain, None, None)
    assert any("no masses given" in w and "chain" in w for w in warned)
    assert not any("no masses" in w for w in _resolve(chain, np.array([1.0, 0.5]), None)[-1])
    assert not any("no masses" in w for w in _resolve(chain, None, "independent")[-1])


@pytest.mark.parametrize("mutate,msg", [
    (lambda d: d.update(x=np.where(np.arange(500)[:, None] == 7, np.nan, d["x"])), "NaN/inf"),
    (lambda d: d.update(t=d["t"] ** 1.1), "not uniformly sampled"),
    (lambda d: d.update(t=d["t"][:50], x=d["x"][:50], base_acc=d["base_acc"][:50]), "only 50 samples"),
    (lambda d: d.update(x=d["x"][:400]), "shape"),
    (lambda d: d.update(t=d["t"][::-1].copy()), "strictly increasing"),
])
def test_validation_messages(tmp_path, mutate, msg):
    r = rec()
    d = {"t": r.t.copy(), "x": r.x.copy(), "base_acc": r.base_acc.copy()}
    mutate(d)
    p = tmp_path / "bad.npz"
    np.savez(p, **d)
    with pytest.raises(g.GMRInputError, match=msg):
        g.load_recording(p)


def test_missing_file_and_garbage(tmp_path):
    with pytest.raises(g.GMRInputError, match="no such file"):
        g.load_recording(tmp_path / "nope.npz")
    p = tmp_path / "garbage.npz"
    p.write_bytes(b"not a zip")
    with pytest.raises(g.GMRInputError, match="cannot read"):
        g.load_recording(p)
    p = tmp_path / "nox.npz"
    np.savez(p, t=np.arange(100.0))
    with pytest.raises(g.GMRInputError, match="'t' and 'x'"):
        g.load_recording(p)


def test_differentiate_noisy_sine():
    rng = np.random.default_rng(0)
    t = np.arange(4000) * 1e-3
    w = 2 * np.pi * 3
    x = np.sin(w * t) + 1e-3 * rng.standard_normal(t.size)
    v = g.differentiate(x, 1e-3, 1)
    a = g.differentiate(x, 1e-3, 2)
    sl = slice(200, -200)
    assert np.sqrt(np.mean((v - w * np.cos(w * t))[sl] ** 2)) < 0.01 * w
    assert np.sqrt(np.mean((a + w**2 * np.sin(w * t))[sl] ** 2)) < 0.03 * w**2


def test_add_noise_snr():
    rng = np.random.default_rng(0)
    s = 5.0 + np.sin(np.linspace(0, 100, 100000))
    n = g.add_noise(s, 20.0, rng) - s
    assert abs(10 * np.log10(np.var(s) / np.var(n)) - 20.0) < 0.1


def _sweep_file(tmp_path, t, name="lab.npz"):
    """A lab-style file: samples taken uniformly at 1 kHz, stamped as given by `t`."""
    k = np.arange(t.size)
    x = 1e-3 * np.sin(2 * np.pi * 3 * k * 1e-3)[:, None]
    p = tmp_path / name
    np.savez(p, t=t, x=x, base_acc=np.sin(k * 1e-3))
    return p, x


def test_float32_time_stamps_are_put_on_the_uniform_grid(tmp_path):
    """A 100 s record with float32 stamps (rounded to 8e-6 s, 0.8 % of a step) is the uniform
    record it is; the channels are untouched."""
    k = np.arange(100_000)
    p, x = _sweep_file(tmp_path, (k * 1e-3).astype(np.float32))
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = g.load_recording(p)
    assert r.t.dtype == np.float64
    np.testing.assert_allclose(np.diff(r.t), 1e-3, rtol=1e-6)
    np.testing.assert_array_equal(r.x, x)


def test_small_jitter_is_snapped_and_larger_jitter_resampled_with_a_warning(tmp_path):
    k = np.arange(5000)
    jitter = np.random.default_rng(0).uniform(-1, 1, k.size)
    # 4e-5 of a step (the EMPS files' stamps): uniform sampling, put on the grid silently
    p, x = _sweep_file(tmp_path, (k + 4e-5 * jitter) * 1e-3)
    r = g.load_recording(p)
    np.testing.assert_allclose(r.t, k * 1e-3, atol=1e-9)
    np.testing.assert_array_equal(r.x, x)
    # 5 % of a step: the samples were taken at the stamped times; resampled onto the grid
    tj = (k + 0.05 * jitter) * 1e-3
    p = tmp_path / "j.npz"
    np.savez(p, t=tj, x=1e-3 * np.sin(2 * np.pi * 3 * tj)[:, None], base_acc=np.sin(tj))
    with pytest.warns(g.GMRDataWarning, match="resampled linearly onto the uniform grid"):
        r = g.load_recording(p)
    np.testing.assert_allclose(np.diff(r.t), np.diff(r.t).mean(), rtol=1e-9)
    np.testing.assert_allclose(r.x[:, 0], 1e-3 * np.sin(2 * np.pi * 3 * r.t), atol=1e-3 * 1e-3)
    # a missing sample is a gap, not jitter: refused with the tolerances named
    tg = np.delete(k * 1e-3, 2500)
    p = tmp_path / "gap.npz"
    np.savez(p, t=tg, x=np.sin(tg)[:, None], base_acc=np.sin(tg))
    with pytest.raises(g.GMRInputError, match=r"not uniformly sampled.*0.001 of a step is accepted.*first irregular "
                       r"step is from sample 2499 \(t = 2.499 s\) to 2500 \(t = 2.501 s\), 2 x .*samples dropped"):
        g.load_recording(p)


def test_cli_prints_load_time_warnings_and_keeps_them(tmp_path, capsys):
    """`gmr fit`/`discover`/`refine` load through this: the resampling warning is a `warning:` line
    (and `gmr fit` writes it into the model's "warnings")."""
    from gmr_jax._cli._args import load_recordings

    k = np.arange(3000)
    tj = (k + 0.05 * np.random.default_rng(1).uniform(-1, 1, k.size)) * 1e-3
    p = tmp_path / "jittered.npz"
    np.savez(p, t=tj, x=np.sin(2 * np.pi * 3 * tj)[:, None], base_acc=np.sin(tj))
    recs, msgs = load_recordings([p, p])
    assert len(recs) == 2 and len(msgs) == 2 and "resampled linearly" in msgs[0]
    err = capsys.readouterr().err
    assert err.count("warning: ") == 2 and "jittered.npz: time stamps deviate" in err


def test_lab_files_with_a_column_mapping(tmp_path):
    """.mat (scipy.io), NPZ and CSV with the lab's own names and scale factors (EMPS: force = gtau * vir,
    column vectors (N, 1), a scalar gain): the same recording from each."""
    import scipy.io

    k = np.arange(2000)
    t = k * 1e-3
    qm = 0.1 * np.sin(2 * np.pi * 2 * t)
    vir = np.cos(2 * np.pi * 2 * t)
    lab = {"t": t[:, None], "qm": qm[:, None], "vir": vir[:, None], "gtau": np.array([[35.15]])}
    scipy.io.savemat(tmp_path / "run.mat", lab)
    np.savez(tmp_path / "run.npz", **lab)
    (tmp_path / "run.csv").write_text("time,qm,vir\n" + "\n".join(f"{a:.17g},{b:.17g},{c:.17g}" for a, b, c in zip(t, qm, vir)))
    mapping = {"x": "qm", "force": "gtau*vir"}
    for name, cols in (("run.mat", mapping), ("run.npz", mapping),
                       ("run.csv", {"t": "time", "x": "qm*1000/1000", "force": "35.15*vir"})):
        r = g.load_recording(tmp_path / name, cols)
        np.testing.assert_allclose(r.t, t, rtol=1e-15, atol=0)
        np.testing.assert_allclose(r.x[:, 0], qm, rtol=1e-14)
        np.testing.assert_allclose(r.force[:, 0], 35.15 * vir, rtol=1e-14)
    # names with a unit holding '/' are names, not divisions (longest match first), and scale as any name
    (tmp_path / "units.csv").write_text("Zeit [s],Weg [m],Geschw [m/s],Kraft [N/V]\n" + "\n".join(
        f"{a:.17g},{b:.17g},{c:.17g},{c:.17g}" for a, b, c in zip(t, qm, vir)))
    r = g.load_recording(tmp_path / "units.csv", {"t": "Zeit [s]", "x": "Weg [m]", "v": "Geschw [m/s] / 2",
                                                   "force": "35.15*Kraft [N/V]"})
    np.testing.assert_allclose(r.v[:, 0], vir / 2, rtol=1e-15)
    np.testing.assert_allclose(r.force[:, 0], 35.15 * vir, rtol=1e-14)
    with pytest.raises(g.GMRInputError, match=r"v='Gesch \[m/s\]': 'Gesch \[m' is neither"):
        g.load_recording(tmp_path / "units.csv", {"t": "Zeit [s]", "x": "Weg [m]", "v": "Gesch [m/s]"})
    # two DOFs, one expression each
    r = g.load_recording(tmp_path / "run.npz", {"x": ["qm", "2*qm"], "force": ["vir", "vir"]})
    assert r.x.shape == (2000, 2) and np.allclose(r.x[:, 1], 2 * qm)
    # what goes wrong says what the file has
    with pytest.raises(g.GMRInputError, match=r"no 'x': the file has \['gtau', 'qm', 't', 'vir'\]"):
        g.load_recording(tmp_path / "run.mat")
    with pytest.raises(g.GMRInputError, match="'vr' is neither a variable of the file nor a number"):
        g.load_recording(tmp_path / "run.mat", {"x": "qm", "force": "gtau*vr"})
    with pytest.raises(g.GMRInputError, match="unknown field"):
        g.load_recording(tmp_path / "run.mat", {"x": "qm", "forcing": "vir"})
    with pytest.raises(g.GMRInputError, match="single number for 'force'"):
        g.load_recording(tmp_path / "run.mat", {"x": "qm", "force": "gtau"})
    # a v7.3 header on a file that is not HDF5: named (with h5py: unreadable; without: the fix)
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Nov 23 2026 HDF5 schema 1.00 .".ljust(116)
    (tmp_path / "v73.mat").write_bytes(header + b" " * 8 + b"\x00\x02" + b"IM" + b"\x89HDF\r\n\x1a\n" + b"\0" * 512)
    try:
        import h5py  # noqa: F401

        why = r"cannot read as a MATLAB v7.3 \(HDF5\) file"
    except ImportError:
        why = r"v7.3 \(HDF5\) file; reading it needs h5py"
    with pytest.raises(g.GMRInputError, match=why):
        g.load_recording(tmp_path / "v73.mat", {"x": "qm"})
    import builtins

    real_import = builtins.__import__

    def no_h5py(name, *a, **k):
        if name == "h5py":
            raise ImportError("no h5py")
        return real_import(name, *a, **k)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(builtins, "__import__", no_h5py)
        with pytest.raises(g.GMRInputError, match=r"v7.3 \(HDF5\) file; reading it needs h5py"):
            g.load_recording(tmp_path / "v73.mat", {"x": "qm"})
    (tmp_path / "junk.mat").write_bytes(b"MATLAB 5.0 junk" * 20)
    with pytest.raises(g.GMRInputError, match="cannot read as a MATLAB .mat file"):
        g.load_recording(tmp_path / "junk.mat")


def _write_mat73(path, variables: dict):
    """A file as MATLAB's save(..., '-v7.3') writes it: a 512-byte user block whose first 128 bytes
    are the MAT header (version 0x0200), then HDF5; each variable transposed, with its MATLAB_class."""
    h5py = pytest.importorskip("h5py")
    with h5py.File(path, "w", userblock_size=512) as fh:
        for k, v in variables.items():
            if isinstance(v, str):
                d = fh.create_dataset(k, data=np.frombuffer(v.encode("utf-16-le"), np.uint16)[None, :].T)
                d.attrs["MATLAB_class"] = np.bytes_("char")
                continue
            v = np.asarray(v)
            v = v.reshape(-1, 1) if v.ndim == 1 else np.atleast_2d(v)
            d = fh.create_dataset(k, data=v.T)
            d.attrs["MATLAB_class"] = np.bytes_({"f": "double", "i": "int32", "u": "uint8", "b": "logical"}[v.dtype.kind])
        fh.create_group("#refs#")
        fh.create_group("meta")  # a struct
        d = fh.create_dataset("when", data=np.arange(6, dtype=np.uint32)[None, :])  # a datetime object's reference
        d.attrs["MATLAB_class"], d.attrs["MATLAB_object_decode"] = np.bytes_("datetime"), 3
        d = fh.create_dataset("nothing", data=np.zeros(2, np.uint64))  # [] as MATLAB stores it
        d.attrs["MATLAB_class"], d.attrs["MATLAB_empty"] = np.bytes_("double"), np.uint8(1)
        d = fh.create_dataset("z", data=np.zeros((1, 3), [("real", "f8"), ("imag", "f8")]))  # complex
        d.attrs["MATLAB_class"] = np.bytes_("double")
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Thu Nov 26 2026 HDF5 schema 1.00 .".ljust(116)
    with open(path, "r+b") as fh:
        fh.write(header + b"\0" * 8 + b"\x00\x02" + b"IM")


def test_matlab_v73_files_read_as_the_older_formats(tmp_path):
    import scipy.io

    rng = np.random.default_rng(0)
    t = np.arange(500) / 100.0
    qm, vir = rng.standard_normal(500), rng.standard_normal(500)
    variables = {"t": t, "qm": qm, "vir": vir, "gtau": 35.15, "two": np.stack([qm, 2 * qm], 1), "label": "run 1",
                 "mask": qm > 0}
    _write_mat73(tmp_path / "run73.mat", variables)
    scipy.io.savemat(tmp_path / "run5.mat", {k: v for k, v in variables.items()})
    cols = {"t": "t", "x": "qm", "force": "gtau*vir"}
    new, old = g.load_recording(tmp_path / "run73.mat", cols), g.load_recording(tmp_path / "run5.mat", cols)
    for f in ("t", "x", "force"):
        np.testing.assert_array_equal(getattr(new, f), getattr(old, f))
    from gmr_jax._recordings._mapping import read_mat

    got = read_mat(tmp_path / "run73.mat", "run73.mat")
    assert sorted(got) == ["gtau", "qm", "t", "two", "vir"]  # no text, logical, struct, object, empty, complex
    np.testing.assert_array_equal(got["two"], variables["two"])  # (N, 2) as MATLAB holds it
    assert got["qm"].shape == (500, 1) and got["gtau"].shape == (1, 1)


def test_column_mapping_sums_and_differences(tmp_path):
    """A relative acceleration made absolute (a = acc + base_acc, rule 13c's fix), an offset removed, a leading
    minus, exponents that are not terms (1e-3, 2E+1), names holding + or -, a column added to each of a chain's
    columns; mismatched lengths named."""
    t = np.arange(500) * 1e-2
    acc, base, q = np.sin(t), 0.3 * np.cos(3 * t), 0.01 * np.sin(2 * t) + 0.2
    lab = {"t": t, "acc": acc, "base": base, "q": q, "x-ref": q - 0.2, "q+off": q, "short": t[:10],
           "q2": np.stack([q, 2 * q], axis=1)}
    np.savez(tmp_path / "run.npz", **lab)
    r = g.load_recording(tmp_path / "run.npz", {"x": "q - 0.2", "a": "acc+base", "base_acc": "base"})
    np.testing.assert_allclose(r.a[:, 0], acc + base, rtol=1e-15)
    np.testing.assert_allclose(r.x[:, 0], q - 0.2, rtol=1e-13)
    r = g.load_recording(tmp_path / "run.npz", {"x": "-q*1e-3 + 2E+1*q", "a": "-acc - base*2"})
    np.testing.assert_allclose(r.x[:, 0], -q * 1e-3 + 20 * q, rtol=1e-14)
    np.testing.assert_allclose(r.a[:, 0], -acc - 2 * base, rtol=1e-15)
    r = g.load_recording(tmp_path / "run.npz", {"x": "x-ref + q+off", "a": "acc"})  # names, not operations
    np.testing.assert_allclose(r.x[:, 0], 2 * q - 0.2, rtol=1e-13)
    r = g.load_recording(tmp_path / "run.npz", {"x": "q2 + base"})
    np.testing.assert_allclose(r.x, lab["q2"] + base[:, None], rtol=1e-15)
    with pytest.raises(g.GMRInputError, match=r"x='q \+ short': its terms have different shapes"):
        g.load_recording(tmp_path / "run.npz", {"x": "q + short"})
    with pytest.raises(g.GMRInputError, match=r"terms by \+ or -"):
        g.load_recording(tmp_path / "run.npz", {"x": "q + "})


def test_cli_columns_option():
    from gmr_jax._cli._args import columns

    assert columns("x=qm, force=gtau*vir") == {"x": "qm", "force": "gtau*vir"}
    assert columns("x=q1*1e-3;q2*1e-3") == {"x": ["q1*1e-3", "q2*1e-3"]}
    assert columns(None) is None
    for bad in ("x", "=qm", "x=", ","):
        with pytest.raises(g.GMRInputError, match="--columns"):
            columns(bad)


def _trapezoid_motion(rng, snr_quant=1e-6):
    """A slow point-to-point motion with sharp velocity reversals (the EMPS shape): trapezoidal
    velocity at 1 kHz, position quantised like an encoder."""
    dt = 1e-3
    t = np.arange(20000) * dt
    ph = (t % 4.0) / 4.0
    v = np.interp(ph, [0, 0.05, 0.45, 0.5, 0.55, 0.95, 1.0], [0, 0.2, 0.2, 0, -0.2, -0.2, 0])
    x = np.cumsum(v) * dt
    return t, dt, np.round(x / snr_quant) * snr_quant, v


def test_window_from_the_noise_floor_when_the_signal_is_clear_far_above_its_band_edge(rng):
    from gmr_jax._recordings._derivatives import window_choice

    t, dt, xq, v = _trapezoid_motion(rng)
    ch = window_choice(xq, dt)
    assert ch["rule"] == "noise floor" and ch["window"] < ch["band_edge_window"] / 10
    assert ch["noise_cutoff_hz"] > 20 * ch["band_edge_hz"]
    vb = g.differentiate(xq, dt, 1, ch["band_edge_window"])
    va = g.differentiate(xq, dt)  # automatic: the noise-floor window
    inner = slice(500, -500)
    err = lambda e: np.sqrt(np.mean((e[inner] - v[inner]) ** 2))  # noqa: E731
    assert err(va) < 0.3 * err(vb)  # the band-edge window smears the reversals
    # a band-limited noisy signal keeps the band-edge window (the noise floor starts at its edge)
    s = np.sin(2 * np.pi * 1.3 * t) + 0.5 * np.sin(2 * np.pi * 3.1 * t) + 1e-2 * rng.normal(size=t.size)
    assert window_choice(s, dt)["rule"] == "band edge"


def test_the_band_edge_is_the_signal_s_not_the_white_noise_s(rng):
    """White noise holding more than 0.5 % of the power set the 99.5 % band edge inside the noise (a
    Duffing well at 20 Hz, x only, 20 dB: 3.7 Hz for 0.37 Hz) and the window fell to the minimum. The
    edge of a lightly damped response to a 0.1-0.35 Hz multisine, against scipy's periodogram of the clean
    signal, stays put from 60 dB down to 10 dB, and the window with it."""
    from scipy.signal import periodogram

    from gmr_jax._recordings._derivatives import band_edge, window_choice

    dt, n = 0.05, 6000
    t = np.arange(n) * dt
    s = sum(np.sin(2 * np.pi * f * t + p) / (1 + 20 * (f - 0.22) ** 2)
            for f, p in zip(np.linspace(0.1, 0.35, 12), rng.uniform(0, 2 * np.pi, 12)))
    f, p = periodogram(s - s.mean(), fs=1 / dt, window="hann")
    clean = f[np.searchsorted(np.cumsum(p) / p.sum(), 0.995)]
    w0 = window_choice(s, dt)["window"]
    for snr in (60, 30, 20, 10):
        noisy = s + np.std(s) * 10 ** (-snr / 20) * rng.normal(size=n)
        assert abs(band_edge(noisy, dt) - clean) <= 0.15 * clean, snr
        assert window_choice(noisy, dt)["window"] >= w0 - 2, snr


def test_sampled_spline_input_is_smooth_and_matches_a_band_limited_signal():
    import jax
    import jax.numpy as jnp

    from gmr_jax._simulate._inputs import Sampled, sampled_spline

    dt = 0.1  # ~9 samples per period at 1.1 Hz
    t = np.arange(100) * dt
    f = np.sin(2 * np.pi * 1.1 * t)
    sp = sampled_spline(t, np.zeros_like(t), f[:, None], 1)
    lin = Sampled(jnp.asarray(t), jnp.zeros(t.size), jnp.asarray(f[:, None]), n_dof=1)
    tt = np.linspace(0.5, 9.0, 997)
    true = np.sin(2 * np.pi * 1.1 * tt)
    e_sp = np.max(np.abs(np.asarray(jax.vmap(lambda s: sp(s)[1][0])(tt)) - true))
    e_li = np.max(np.abs(np.asarray(jax.vmap(lambda s: lin(s)[1][0])(tt)) - true))
    assert e_sp < 0.05 * e_li
    np.testing.assert_allclose(np.asarray(jax.vmap(lambda s: sp(s)[1][0])(jnp.asarray(t))), f, atol=1e-12)
    assert float(sp(t[-1] + 1.0)[1][0]) == 0.0  # zero after the last sample, as Sampled
    # C1 under jit: the derivative matches finite differences
    g = jax.jit(jax.grad(lambda s: sp(s)[1][0]))
    for s in (2.03, 4.5, 7.77):
        fd = (float(sp(s + 1e-6)[1][0]) - float(sp(s - 1e-6)[1][0])) / 2e-6
        assert float(g(s)) == pytest.approx(fd, rel=1e-5, abs=1e-8)


def _oscillation(rng, n=8000, dt=5e-3):
    """A broadband motion (random-phase multisine, every line 0.5-5 Hz at 1/record length
    spacing, flat in x) that starts and ends anywhere (x, v, a exact)."""
    t = np.arange(n) * dt
    T = n * dt
    f = np.arange(int(0.5 * T), int(5 * T) + 1) / T + 0.37 / T  # off the record's own grid
    ph = rng.uniform(0, 2 * np.pi, f.size)
    amp = np.full(f.size, 1.0 / np.sqrt(f.size))
    w = 2 * np.pi * f
    x = (amp * np.sin(w * t[:, None] + ph)).sum(1)
    v = (amp * w * np.cos(w * t[:, None] + ph)).sum(1)
    a = -(amp * w**2 * np.sin(w * t[:, None] + ph)).sum(1)
    return t, x, v, a


@pytest.mark.parametrize("sensor", ["v", "a"])
def test_velocity_or_acceleration_only_sensors_are_integrated(rng, sensor, tmp_path):
    """x (and v from a) integrated with drift removal: a sensor bias and 50 dB noise leave the
    displacement within 4 % (mean removed: the equilibrium is unobservable; most of the error is
    the record's own straight-line / parabola trend, removed with the bias's ramp: ~2-3 % on
    40 s of a 0.5-5 Hz band)."""
    t, x, v, a = _oscillation(rng)
    sig = {"v": v, "a": a}[sensor]
    meas = sig + 0.02 * np.std(sig) + g.add_noise(sig, 50.0, rng) - sig  # a bias and noise
    rec = g.Recording(t=t, force=np.zeros_like(t), **{sensor: meas}, name="lab")
    assert rec.derived == (("x",) if sensor == "v" else ("x", "v")), rec.derived
    assert rec.integration["from"] == sensor and "unobservable" in rec.integration["equilibrium"]
    assert not rec.equilibrium_observed
    xc = x - x.mean()
    assert np.linalg.norm(rec.x[:, 0] - xc) <= 0.04 * np.linalg.norm(xc)
    assert abs(rec.x.mean()) < 1e-12
    if sensor == "a":
        assert np.linalg.norm(rec.v[:, 0] - v) <= 0.04 * np.linalg.norm(v)
    full = rec.complete("independent")
    assert full.derived == ("x", "a") if sensor == "v" else ("x", "v")
    if sensor == "v":  # a from one derivative of the measured v
        assert np.linalg.norm(full.a[:, 0] - a) <= 0.02 * np.linalg.norm(a)
    # the equilibrium, when given, is where the mean goes; round trip keeps it
    placed = g.Recording(t=t, force=np.zeros_like(t), equilibrium=0.3, **{sensor: meas})
    assert placed.equilibrium_observed and placed.x.mean() == pytest.approx(0.3)
    placed.save(tmp_path / "p.npz")
    back = g.load_recording(tmp_path / "p.npz")
    assert set(np.load(tmp_path / "p.npz").files) == {"t", sensor, "force", "equilibrium"}
    np.testing.assert_allclose(back.x, placed.x, atol=1e-12)


def test_velocity_only_csv_and_refusals(rng, tmp_path):
    t, x, v, a = _oscillation(rng, n=2000)
    p = tmp_path / "vib.csv"
    np.savetxt(p, np.stack([t, v, np.zeros_like(t)], 1), delimiter=",", header="t,v0,f0", comments="")
    rec = g.load_recording(p)
    assert rec.derived == ("x",) and rec.n_dof == 1
    with pytest.raises(g.GMRInputError, match="'equilibrium' is for velocity- or acceleration-only"):
        g.Recording(t=t, x=x, equilibrium=0.1)
    with pytest.raises(g.GMRInputError, match="'x' is required"):
        g.Recording(t=t, force=np.zeros_like(t))
    vn = v.copy()
    vn[5] = np.nan
    with pytest.raises(g.GMRInputError, match="'v' has 1 NaN"):
        g.Recording(t=t, v=vn)
    # a global fit needs each equilibrium's position: refused, with the fix named
    with pytest.raises(g.GMRInputError, match="equilibrium it vibrated about is unobservable.*'equilibrium'"):
        g.reconstruct([rec, rec])


def test_acceleration_only_chain_becomes_cell_deformations(rng):
    """Accelerometers on the masses of a 2-cell chain: integrated mass displacements become cell
    deformations (x_1 = y_1 - y_0) for a chain, stay mass displacements when independent."""
    t, y0, _, a0 = _oscillation(rng)
    _, y1, _, a1 = _oscillation(rng)
    rec = g.Recording(t=t, a=np.stack([a0, a1], 1), force=np.zeros((t.size, 2)))
    chain = rec.complete("chain")
    d1 = (y1 - y1.mean()) - (y0 - y0.mean())
    assert np.linalg.norm(chain.x[:, 1] - d1) <= 0.02 * np.linalg.norm(d1)
    assert "cell deformations" in chain.integration["coordinates"]
    ind = rec.complete("independent")
    np.testing.assert_allclose(ind.x, rec.x)
    # idempotent: completing twice does not difference twice
    np.testing.assert_allclose(chain.complete("chain").x, chain.x)
    # the equilibrium is each cell's rest deformation (formats.md), for a chain as for one DOF (audit: cell 1's
    # was read as mass 1's position, its wells moved by cell 0's rest deformation)
    eq = np.array([-0.8, 1.2])
    placed = g.Recording(t=t, a=np.stack([a0, a1], 1), force=np.zeros((t.size, 2)), equilibrium=eq)
    np.testing.assert_allclose(placed.complete("chain").x.mean(0), eq, atol=1e-9)
    np.testing.assert_allclose(placed.complete("chain").x - eq, chain.x, atol=1e-12)
    np.testing.assert_allclose(placed.complete("independent").x.mean(0), eq, atol=1e-9)


def test_csv_separated_by_semicolons_or_tabs(tmp_path):
    """A spreadsheet's CSV in a locale with decimal commas (';' between columns, ',' in numbers) and a
    tab-separated one read as the comma-separated file; a bad cell is still named by line and column."""
    t = np.arange(0.0, 1.0, 1e-3)
    x, b = 0.1 * np.sin(5 * t) - 1.0, np.cos(3 * t)
    rows = np.column_stack([t, x, b])
    np.savetxt(tmp_path / "comma.csv", rows, delimiter=",", header="t,x0,base_acc", comments="", fmt="%.12g")
    (tmp_path / "semi.csv").write_text("t;x0;base_acc\n" + "\n".join(
        ";".join(f"{v:.12g}".replace(".", ",") for v in r) for r in rows))
    np.savetxt(tmp_path / "tab.csv", rows, delimiter="\t", header="t\tx0\tbase_acc", comments="", fmt="%.12g")
    ref = g.load_recording(tmp_path / "comma.csv")
    for name in ("semi.csv", "tab.csv"):
        r = g.load_recording(tmp_path / name)
        for k in ("t", "x", "base_acc"):
            np.testing.assert_array_equal(getattr(r, k), getattr(ref, k))
    lines = (tmp_path / "semi.csv").read_text().splitlines()
    lines[5] = lines[5].split(";")[0] + ";oops;1"
    (tmp_path / "bad.csv").write_text("\n".join(lines))
    with pytest.raises(g.GMRInputError, match=r"line 6 \(sample 4\), column 'x0': 'oops' is not a number"):
        g.load_recording(tmp_path / "bad.csv")


def test_one_dof_csv_with_plain_column_names(tmp_path):
    """A one-DOF lab CSV headed t, x, v, force (the NPZ keys) reads as t, x0, v0, f0; naming a
    column twice (x and x0) is refused with a message that says why."""
    t = np.arange(0.0, 1.0, 1e-3)
    x, v, f = 0.1 * np.sin(5 * t), 0.5 * np.cos(5 * t), np.sin(t)
    np.savetxt(tmp_path / "plain.csv", np.column_stack([t, x, v, f]), delimiter=",", header="t, x, v, force",
               comments="")
    np.savetxt(tmp_path / "numbered.csv", np.column_stack([t, x, v, f]), delimiter=",", header="t,x0,v0,f0",
               comments="")
    a, b = g.load_recording(tmp_path / "plain.csv"), g.load_recording(tmp_path / "numbered.csv")
    for k in ("t", "x", "v", "force"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))
    assert a.x.shape == (t.size, 1) and a.base_acc is None
    np.savetxt(tmp_path / "twice.csv", np.column_stack([t, x, x]), delimiter=",", header="t,x,x0", comments="")
    with pytest.raises(g.GMRInputError, match=r"\['x0'\] appear more than once.*x, v, a, f, force are read as"):
        g.load_recording(tmp_path / "twice.csv")


def test_lab_csv_headers_units_case_time_and_equilibrium(tmp_path):
    """Headers as labs write them read without a mapping: any case, `time` for t, a unit in brackets or
    parentheses ('v [m/s]'), the time column's unit applied ('t [ms]': the stamps scaled to s); an `equilibrium`
    column (one value repeated) is the recording's equilibrium; a varying one, an unknown time unit and a
    header-less file are refused with the fix."""
    t = np.arange(0.0, 2.0, 1e-3)
    x, v = 0.1 * np.sin(5 * t), 0.5 * np.cos(5 * t)
    base = np.sin(t)
    plain = tmp_path / "plain.csv"
    np.savetxt(plain, np.column_stack([t, x, v, base]), delimiter=",", header="t,x,v,base_acc", comments="")
    ref = g.load_recording(plain)
    for name, header, scale in (("case.csv", "Time,X,V,Base_Acc", 1.0), ("units.csv", "t [s],x [m],v (m/s),base_acc", 1.0),
                                ("ms.csv", "t [ms],x,v,base_acc", 1e3)):
        np.savetxt(tmp_path / name, np.column_stack([t * scale, x, v, base]), delimiter=",", header=header,
                   comments="")
        rec = g.load_recording(tmp_path / name)
        for k in ("t", "x", "v", "base_acc"):
            np.testing.assert_allclose(getattr(rec, k), getattr(ref, k), rtol=1e-12, atol=1e-15, err_msg=name)
    np.savetxt(tmp_path / "eq.csv", np.column_stack([t, v, base, np.full_like(t, 0.25)]), delimiter=",",
               header="t,v,base_acc,equilibrium", comments="")
    rec = g.load_recording(tmp_path / "eq.csv")
    assert rec.derived == ("x",) and rec.equilibrium.tolist() == [0.25]
    np.savetxt(tmp_path / "eqvar.csv", np.column_stack([t, v, base, t]), delimiter=",",
               header="t,v,base_acc,equilibrium", comments="")
    with pytest.raises(g.GMRInputError, match="'equilibrium' column varies over the record"):
        g.load_recording(tmp_path / "eqvar.csv")
    np.savetxt(tmp_path / "h.csv", np.column_stack([t, x]), delimiter=",", header="t [hours],x", comments="")
    with pytest.raises(g.GMRInputError, match=r"time column's unit 'hours' is not one of"):
        g.load_recording(tmp_path / "h.csv")
    np.savetxt(tmp_path / "nohdr.csv", np.column_stack([t, x]), delimiter=",")
    with pytest.raises(g.GMRInputError, match="the first line holds numbers .* not column names"):
        g.load_recording(tmp_path / "nohdr.csv")


def test_lists_are_taken_as_arrays():
    """A notebook's lists of floats make a recording as arrays do (audit: a raw TypeError from a slice)."""
    t = np.linspace(0.0, 1.0, 200)
    x, b = np.sin(5 * t), np.cos(t)
    r = g.Recording(t=list(t), x=list(x), base_acc=tuple(b))
    ref = g.Recording(t=t, x=x, base_acc=b)
    for k in ("t", "x", "base_acc"):
        np.testing.assert_array_equal(getattr(r, k), getattr(ref, k))
    with pytest.raises(g.GMRInputError, match="not a rectangular array"):
        g.Recording(t=list(t), x=[[1.0, 2.0], [3.0]], base_acc=list(b))
    ints = g.Recording(t=list(range(200)), x=list(x), base_acc=list(b), masses=[2])  # Python ints, as floats
    assert ints.t.dtype == float and ints.masses.tolist() == [2.0]


def test_labelled_units_are_made_coherent(tmp_path):
    """A unit in a header is applied, not dropped (audit: an accelerometer file 'a0 [g]' was read as m/s^2, the
    barriers 75 % off, and nothing said so): g becomes the file's length unit per s^2, lengths follow the first
    labelled one (x [mm] with a [m/s^2]: a in mm/s^2), SI throughout where a force or mass is labelled; an unknown
    unit, or lengths beside angles, are refused with the fix; an unlabelled column is taken as it is."""
    t = np.arange(0.0, 2.0, 1e-3)
    a, b = np.sin(5 * t), 0.3 * np.cos(3 * t)

    def read(header, *cols):
        np.savetxt(tmp_path / "u.csv", np.column_stack([t, *cols]), delimiter=",", header=header, comments="")
        return g.load_recording(tmp_path / "u.csv")

    r = read("t,a0 [g],base_acc [g],equilibrium [m]", a, b, np.full_like(t, 0.5))
    np.testing.assert_allclose(r.a[:, 0], 9.80665 * a)
    np.testing.assert_allclose(r.base_acc, 9.80665 * b)
    assert r.equilibrium.tolist() == [0.5]
    with pytest.warns(g.GMRDataWarning, match=r"equilibrium \[mm\] converted to m .* but base_acc carries no unit "
                                              r"and is taken as it is, in m: if not, label it"):
        r = read("t,a0 [m/s^2],base_acc,equilibrium [mm]", a, b, np.full_like(t, 12.0))  # the first label is m
    np.testing.assert_allclose(r.a[:, 0], a)
    np.testing.assert_allclose(r.base_acc, b)  # unlabelled: as it is
    np.testing.assert_allclose(r.equilibrium, [0.012])
    r = read("t,x [mm],v [mm/s],a [m/s²],base_acc [g]", a, a, a, b)
    np.testing.assert_allclose(r.x[:, 0], a)
    np.testing.assert_allclose(r.a[:, 0], 1e3 * a)
    np.testing.assert_allclose(r.base_acc, 9806.65 * b)
    r = read("t,x [mm],f [kN],m [g]", a, b, np.full_like(t, 500.0))
    np.testing.assert_allclose(r.x[:, 0], 1e-3 * a)
    np.testing.assert_allclose(r.force[:, 0], 1e3 * b)
    assert r.masses.tolist() == [0.5]
    with pytest.warns(g.GMRDataWarning, match=r"a \[g\] converted to m .* but x carries no unit"):
        r = read("t,x,a [g]", a, a)  # audit: x in mm unlabelled beside 'a0 [g]': 1000x apart, unsaid
    np.testing.assert_allclose(r.x[:, 0], a)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read("t,x,a [m/s^2]", a, a)  # nothing converted: silent
    # which unit the lengths end in is said: the recording's length_unit (None: nothing labelled)
    assert read("t,x [mm],v [mm/s],a [m/s²],base_acc [g]", a, a, a, b).length_unit == "mm"
    assert read("t,x,a [m/s^2]", a, a).length_unit == "m" and read("t,x,a", a, a).length_unit is None
    assert read("t,x [mm],f [kN],m [g]", a, b, np.full_like(t, 500.0)).length_unit == "m"  # SI with a force
    mm = read("t,x [mm],a [mm/s^2],base_acc [mm/s^2]", a, a, b)
    m = dataclasses.replace(read("t,x [m],a [m/s^2],base_acc [m/s^2]", a, a, b), name="other")
    with pytest.raises(g.GMRInputError, match=r"lengths are in different units \(u: mm, other: m\)"):
        g.reconstruct([mm, m])
    with pytest.raises(g.GMRInputError, match="the unit 'V' of column 'a0' is not one gmr_jax converts.*leave the "
                                              "unit out"):
        read("t,x,a [V]", a, a)
    with pytest.raises(g.GMRInputError, match="mixes lengths and angles"):
        read("t,x [deg],v [m/s]", a, a)


def test_dead_channels_and_repeated_time_stamps_are_named(tmp_path):
    """A constant v or a column (a dead sensor) is refused by name, not left to fail in the fit; a repeated time
    stamp is called a duplicated row, a stamp going back a new run."""
    from gmr_jax._recordings._recording import validate  # what load_recording and reconstruct run

    t = np.arange(0.0, 2.0, 1e-3)
    x = 0.1 * np.sin(5 * t)
    with pytest.raises(g.GMRInputError, match=r"v of column 0 is constant \(0 throughout\): a dead or disconnected"):
        validate(g.Recording(t=t, x=x, v=np.zeros_like(t)))
    with pytest.raises(g.GMRInputError, match=r"a of column 0 is constant"):
        validate(g.Recording(t=t, x=x, a=np.full_like(t, 9.81)))
    td = t.copy()
    td[500] = td[499]
    with pytest.raises(g.GMRInputError, match=r"sample 500 repeats the time stamp of sample 499.*duplicated row"):
        validate(g.Recording(t=td, x=x))
    tb = t.copy()
    tb[500:] -= 1.0
    with pytest.raises(g.GMRInputError, match=r"sample 500 .* comes before sample 499.*sort the rows"):
        validate(g.Recording(t=tb, x=x))
