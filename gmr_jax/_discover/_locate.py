"""Where a model's residual lives: phase plane, time, frequency, and classical residual tests.

Per DOF, the equation-error residual r = y - F(x, v) (y the measured force the DOF carries)
is summarised by

- `map`: mean residual on a `bins` x `bins` grid of the (x, v) plane (uniform edges over the
  1st-99th percentiles; NaN where fewer than 5 samples fall);
- region shares: share of residual energy vs share of samples at small speed (|v| below 25 % of
  its 99th percentile), at large speed (above 75 %), at large |x - mean| (above 75 %);
  `concentration` = energy share / sample share (> 1: the residual sits there);
- `sign_jump`: mean residual just above minus just below v = 0 (|v| < 10 %): a Coulomb force
  makes a jump of 2 Fc that no odd polynomial in v makes;
- time: RMS in 20 consecutive windows (max / median ratio); frequency: the band holding 90 %
  of the residual's power (Welch);
- tests (Billings & Voon 1986, nonlinear model validity): autocorrelation of r, and
  cross-correlations of r with the input u, of r with u^2 - mean, of r^2 with u^2 - mean, and of
  r with v and with x^2 - mean, for lags 0..`max_lag`, against the 95 % band +-1.96/sqrt(N)
  (white residual, independent of the input). A test fails when more than 5 % of the lags
  leave the band. With filtered derivatives the residual is never white: read the tests as
  relative (before vs after), not as absolute verdicts.
"""

import numpy as np


def _ccf(a, b, max_lag):
    a = (a - a.mean()) / (a.std() + 1e-300)
    b = (b - b.mean()) / (b.std() + 1e-300)
    n = a.size
    fa, fb = np.fft.rfft(a, 2 * n), np.fft.rfft(b, 2 * n)
    c = np.fft.irfft(fa * np.conj(fb))
    pos = c[: max_lag + 1] / n
    neg = c[-max_lag:][::-1] / n if max_lag else np.zeros(0)
    return np.concatenate([neg[::-1], pos])


def residual_tests(r, u, x, v, max_lag: int = 50) -> dict:
    """The correlation tests of the module docstring; each entry: max |corr|, share of lags
    outside the band, and `white` (share <= 5 %)."""
    n = r.size
    band = 1.96 / np.sqrt(n)
    out = {"band": float(band), "max_lag": int(max_lag)}
    acf = _ccf(r, r, max_lag)[max_lag + 1:]
    pairs = {"autocorrelation": acf}
    if u is not None and np.std(u) > 0:
        pairs["input"] = _ccf(r, u, max_lag)
        pairs["input_squared"] = _ccf(r, u**2, max_lag)
        pairs["squared_input_squared"] = _ccf(r**2, u**2, max_lag)
    pairs["velocity"] = _ccf(r, v, max_lag)
    pairs["position_squared"] = _ccf(r, x**2, max_lag)
    for k, c in pairs.items():
        share = float(np.mean(np.abs(c) > band))
        out[k] = {"max_abs": float(np.max(np.abs(c))), "outside_band": share, "white": share <= 0.05}
    return out


def locate(r, x, v, dt, u=None, *, bins: int = 12, max_lag: int = 50) -> dict:
    """Summary of where residual `r` of one DOF lives (module docstring); arrays (N,)."""
    r, x, v = (np.asarray(z, float) for z in (r, x, v))
    tot = float(np.sum(r**2)) + 1e-300
    av = np.abs(v)
    vs = np.percentile(av, 99) + 1e-300
    dx = np.abs(x - x.mean())
    xs = np.percentile(dx, 99) + 1e-300

    def region(mask):
        share = float(mask.mean())
        energy = float(np.sum(r[mask] ** 2) / tot)
        return {"sample_share": share, "energy_share": energy,
                "concentration": energy / share if share > 0 else float("nan")}

    near = av < 0.1 * vs
    up, dn = near & (v > 0), near & (v < 0)
    jump = float(r[up].mean() - r[dn].mean()) if up.any() and dn.any() else 0.0
    xe = np.linspace(*np.percentile(x, [1, 99]), bins + 1)
    ve = np.linspace(*np.percentile(v, [1, 99]), bins + 1)
    ix = np.digitize(x, xe) - 1
    iv = np.digitize(v, ve) - 1
    ok = (ix >= 0) & (ix < bins) & (iv >= 0) & (iv < bins)
    cnt = np.zeros((bins, bins))
    sm = np.zeros((bins, bins))
    np.add.at(cnt, (iv[ok], ix[ok]), 1)
    np.add.at(sm, (iv[ok], ix[ok]), r[ok])
    mp = np.where(cnt >= 5, sm / np.maximum(cnt, 1), np.nan)
    nw = 20
    wins = np.array_split(r, nw)
    wr = np.array([np.sqrt(np.mean(w**2)) for w in wins])
    nper = min(1024, r.size)
    from scipy.signal import welch

    f, p = welch(r, fs=1.0 / dt, nperseg=nper)
    c = np.cumsum(p) / (np.sum(p) + 1e-300)
    lo, hi = f[np.searchsorted(c, 0.05)], f[min(np.searchsorted(c, 0.95), f.size - 1)]
    return {
        "rms": float(np.sqrt(np.mean(r**2))),
        "mean": float(r.mean()),
        "small_speed": region(av < 0.25 * vs),
        "large_speed": region(av > 0.75 * vs),
        "large_displacement": region(dx > 0.75 * xs),
        "sign_jump": jump,
        "map": {"x_edges": xe.tolist(), "v_edges": ve.tolist(), "mean": mp.tolist()},
        "time": {"window_rms": wr.tolist(), "max_over_median": float(wr.max() / (np.median(wr) + 1e-300))},
        "frequency": {"band_90_hz": [float(lo), float(hi)],
                      "peak_hz": float(f[int(np.argmax(p))])},
        "tests": residual_tests(r, u, x, v, max_lag),
    }


def where_sentence(loc: dict, physics: str) -> str:
    """Plain words for where the residual attributed to `physics` sits, with the numbers."""
    s, L, X = loc["small_speed"], loc["large_speed"], loc["large_displacement"]
    if physics in ("coulomb_friction",):
        return (f"residual concentrated where |v| is small: {100 * s['energy_share']:.0f} % of its "
                f"energy in {100 * s['sample_share']:.0f} % of the samples (|v| < 25 % of max); "
                f"jump of {loc['sign_jump']:.3g} N across v = 0")
    if physics in ("quadratic_drag", "cubic_damping", "viscous_damping"):
        return (f"residual grows with speed: {100 * L['energy_share']:.0f} % of its energy in the "
                f"{100 * L['sample_share']:.0f} % of samples at |v| > 75 % of max")
    if physics == "preload":
        return f"a constant force: the residual has mean {loc['mean']:.3g} N"
    if physics.endswith("stiffness"):
        return (f"residual grows with displacement: {100 * X['energy_share']:.0f} % of its energy "
                f"in the {100 * X['sample_share']:.0f} % of samples at |x - mean| > 75 % of max")
    if physics == "position_dependent_damping":
        return (f"residual follows v and |x|: {100 * X['energy_share']:.0f} % of its energy at large "
                f"|x| ({100 * X['sample_share']:.0f} % of samples), "
                f"{100 * L['energy_share']:.0f} % at large |v|")
    return f"residual RMS {loc['rms']:.3g} N"
