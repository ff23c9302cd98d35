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
    r = g.Recording(t=r.t, x=r.x, v=r.x * 2, force=r.x * 3, masses=np.array([1.0, 2.0]) if ext == "npz" else None)
    p = tmp_path / f"r.{ext}"
    g.save_recording(r, p)
    r2 = g.load_recording(p)
    for k in ("t", "x", "v", "force"):
        np.testing.assert_allclose(getattr(r2, k), getattr(r, k), rtol=1e-15 if ext == "npz" else 1e-12)


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
