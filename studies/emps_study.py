"""What physics does a viscous-only model of the EMPS leave out? A study on real recordings.

The force equation of the EMPS (benchmark description, Eq. 1) is

    tau = M a + Fv v + Fc sgn(v) + offset,        tau = gtau * vir.

The "simulation" model keeps M and Fv only (model 1). Fitting it by least squares to the
estimation run and looking at where its residual sits shows the missing Coulomb friction and
offset; the augmented model (2) recovers the benchmark's reference values. Everything here is a
pure function returning plain dicts (JSON-ready); `run_emps_study` runs the whole study and
`python studies/emps_study.py` prints it (and writes `results/emps_study.md`).

Protocol (the benchmark's IDIM-LS): velocity and acceleration from the measured position by a
zero-phase Butterworth low-pass (order 4, 100 Hz) and central differences; then every column
of the regression and the force are low-passed and decimated together by 10 (100 Hz), which
removes the force ripples the controller rejects (`decimate=10`); 0.05 s is cut at both ends
(filter transients). `decimate=1` gives the same fits at 1 kHz (larger errors, the ripples stay).

Confidence intervals: the residuals are autocorrelated (filtered derivatives, unmodelled
dynamics), so white-noise OLS intervals are too narrow. The primary 95 % intervals are
percentile intervals of a moving-block bootstrap of the regression rows, blocks of 1 s: the
residual autocorrelation drops to ~0.1 within 0.1 s but keeps a weak tail that follows the
~3.1 s period of the trajectory, and the interval widths stop growing with the block length
near 1 s (0.1 s blocks give intervals about half as wide; `ci_block_length_sensitivity`).
Newey-West (HAC, 1 s of lags) and naive white-noise OLS intervals are given beside them; the
OLS ones are 3-5 x too narrow. None of these covers the bias of least squares in closed loop
with noisy regressors.
"""

import itertools
import json
import math
from pathlib import Path

import numpy as np

import gmr_jax as g
from gmr_jax.data import (
    EMPS_BENCHMARK_DECIMATION,
    EMPS_CUTOFF_HZ,
    EMPS_REFERENCE,
    EMPS_REFERENCE_ASYMMETRIC,
    EMPS_REFERENCE_RELATIVE_ERROR,
    EMPS_SAMPLE_TIME,
    emps_raw,
    load_emps,
    lowpass_derivatives,
    parallel_decimate,
)

BENCHMARK_DECIMATION = EMPS_BENCHMARK_DECIMATION
DEFAULT_CUTOFF_HZ = EMPS_CUTOFF_HZ
REFERENCE = EMPS_REFERENCE
REFERENCE_ASYMMETRIC = EMPS_REFERENCE_ASYMMETRIC
REFERENCE_RELATIVE_ERROR = EMPS_REFERENCE_RELATIVE_ERROR
SAMPLE_TIME = EMPS_SAMPLE_TIME

RESULTS_DIR = Path(__file__).resolve().parents[1] / "results"

# -- regression terms ------------------------------------------------------------------------

#: name -> column of the force equation, as a function of (x, v, a).
TERMS = {
    "M": lambda x, v, a: a,
    "Fv": lambda x, v, a: v,
    "Fc": lambda x, v, a: np.sign(v),
    "offset": lambda x, v, a: np.ones_like(v),
    # asymmetric friction (description, Eq. 12): 0+(v) = v for v > 0 else 0, and so on.
    "Fv+": lambda x, v, a: np.where(v > 0, v, 0.0),
    "Fv-": lambda x, v, a: np.where(v < 0, v, 0.0),
    "Fc+": lambda x, v, a: (v > 0).astype(float),
    "Fc-": lambda x, v, a: -(v < 0).astype(float),
}

#: The models compared. "asymmetric_coulomb" spans the same space as "coulomb" (sgn(v) and 1
#: against the two one-sided steps), so from one run an offset cannot be told apart from a
#: Coulomb level that differs between directions: it is kept to show that. "asymmetric" is the
#: benchmark's Eq. (12) (no offset column: it would be collinear with Fc+ and Fc-).
MODELS = {
    "viscous": ("M", "Fv"),
    "coulomb_no_offset": ("M", "Fv", "Fc"),
    "coulomb": ("M", "Fv", "Fc", "offset"),
    "asymmetric_coulomb": ("M", "Fv", "Fc+", "Fc-"),
    "asymmetric": ("M", "Fv+", "Fv-", "Fc+", "Fc-"),
}

#: contract `physics` names of the model-format basis functions, for the findings.
PHYSICS = {"Fc": "coulomb_friction", "offset": "preload", "Fv": "viscous_damping"}


def design(data: dict, terms) -> np.ndarray:
    """Regression matrix (N, len(terms)) of the named `TERMS`, from `prepare`'s data: each
    column built at 1 kHz and then decimated (the benchmark's parallel filtering; a filtered
    sgn(v) is a smooth step, as the filtered force is at a velocity reversal)."""
    return np.stack([data["cols"][k] for k in terms], axis=1)


def nrmse(y, yhat) -> float:
    """The benchmark's relative error ||y - yhat|| / ||y|| (its Eq. 11, as a fraction)."""
    y = np.asarray(y, float)
    return float(np.linalg.norm(y - np.asarray(yhat, float)) / np.linalg.norm(y))


# -- data --------------------------------------------------------------------------------------


def prepare(
    which: str = "estimation",
    *,
    cutoff_hz: float | None = DEFAULT_CUTOFF_HZ,
    decimate: int = BENCHMARK_DECIMATION,
    trim_s: float = 0.05,
    add_pulses: bool = False,
    derivative: str = "butterworth",
    sg_window: int | None = None,
) -> dict:
    """One run ready for regression: `y` (= gtau vir), `x`, `v`, `a`, `t` and the regression
    columns `cols` of every `TERMS` entry, all decimated and trimmed (1-D arrays).

    `derivative`: "butterworth" (zero-phase low-pass at `cutoff_hz`, then central differences;
    `cutoff_hz=None`: plain central differences) or "savgol" (`gmr_jax.differentiate`,
    Savitzky-Golay of its default order, `sg_window` samples; None = its automatic window).
    The regression columns (built at 1 kHz from x, v, a) and the force are then decimated in
    parallel by `decimate`; x and v are decimated too (for locating the residual)."""
    raw = emps_raw(which)
    qm = raw["qm"]
    y = raw["gtau"] * raw["vir"]
    if add_pulses:
        y = y + raw["pulses_N"]
    if derivative == "butterworth":
        _, v, a = lowpass_derivatives(qm, SAMPLE_TIME, cutoff_hz)
    elif derivative == "savgol":
        v = g.differentiate(qm, SAMPLE_TIME, 1, sg_window)
        a = g.differentiate(qm, SAMPLE_TIME, 2, sg_window)
    else:
        raise ValueError(f"derivative must be 'butterworth' or 'savgol', got {derivative!r}")
    sig = {"x": qm, "v": v, "a": a, "y": y}
    sig.update({f"col:{k}": f(qm, v, a) for k, f in TERMS.items()})
    sig = parallel_decimate(sig, decimate)
    dt = SAMPLE_TIME * decimate
    n = sig["x"].shape[0]
    cut = round(trim_s / dt)
    keep = slice(cut, n - cut)
    out = {k: s[keep] for k, s in sig.items() if not k.startswith("col:")}
    out["cols"] = {k[4:]: s[keep] for k, s in sig.items() if k.startswith("col:")}
    out["t"] = (np.arange(n) * dt)[keep]
    out["dt"] = dt
    out["which"] = which
    return out


# -- least squares and intervals ---------------------------------------------------------------


def fit(data: dict, terms) -> dict:
    """Least squares y ~ design(data, terms): coefficients, prediction and residual."""
    terms = tuple(terms)
    X = design(data, terms)
    coef, *_ = np.linalg.lstsq(X, data["y"], rcond=None)
    yhat = X @ coef
    return {"terms": terms, "coef": coef, "yhat": yhat, "resid": data["y"] - yhat,
            "nrmse": nrmse(data["y"], yhat), "cond": float(np.linalg.cond(X))}


def predict(data: dict, terms, coef) -> np.ndarray:
    return design(data, terms) @ np.asarray(coef)


def autocorrelation(r, max_lag: int) -> np.ndarray:
    """Sample autocorrelation of r at lags 0..max_lag (FFT, biased normalisation)."""
    r = np.asarray(r, float) - np.mean(r)
    n = r.size
    f = np.fft.rfft(r, 2 * n)
    c = np.fft.irfft(f * np.conj(f))[: max_lag + 1]
    return c / c[0]


def integrated_time(r, max_lag: int) -> float:
    """Integrated autocorrelation time 1 + 2 sum_k rho_k (Sokal window: stop where the sum
    passes 5 x the lag)."""
    rho = autocorrelation(r, max_lag)
    tau = 1.0
    for k in range(1, max_lag + 1):
        tau += 2 * rho[k]
        if k >= 5 * tau:
            break
    return float(max(tau, 1.0))


def ols_intervals(X, resid, coef) -> np.ndarray:
    """White-noise OLS 95 % intervals (too narrow here; shown for contrast), (p, 2)."""
    n, p = X.shape
    s2 = resid @ resid / (n - p)
    se = np.sqrt(np.diag(s2 * np.linalg.inv(X.T @ X)))
    return np.stack([coef - 1.96 * se, coef + 1.96 * se], axis=1)


def hac_intervals(X, resid, coef, lags: int) -> np.ndarray:
    """Newey-West (Bartlett kernel, `lags`) heteroscedasticity-and-autocorrelation-consistent
    95 % intervals, (p, 2)."""
    u = X * resid[:, None]
    s = u.T @ u
    for lag in range(1, lags + 1):
        gam = u[lag:].T @ u[:-lag]
        s += (1.0 - lag / (lags + 1.0)) * (gam + gam.T)
    xtx_inv = np.linalg.inv(X.T @ X)
    se = np.sqrt(np.diag(xtx_inv @ s @ xtx_inv))
    return np.stack([coef - 1.96 * se, coef + 1.96 * se], axis=1)


def block_bootstrap(data: dict, models: dict, block: int, n_boot: int = 1000, seed: int = 0):
    """Moving-block bootstrap of the regression rows: coefficient replicates of every model.

    Every replicate concatenates ceil(N / block) blocks of `block` consecutive rows drawn with
    replacement, and refits each model on it (all models see the same replicate, so
    differences between models are bootstrapped jointly). Uses cumulative sums of the
    per-row normal equations, so a replicate costs O(blocks). Returns {model: (n_boot, p)}."""
    names = sorted({k for terms in models.values() for k in terms})
    G = design(data, names)
    y = data["y"]
    n, k = G.shape
    gg = np.concatenate([np.zeros((1, k, k)), np.cumsum(G[:, :, None] * G[:, None, :], 0)])
    gy = np.concatenate([np.zeros((1, k)), np.cumsum(G * y[:, None], 0)])
    rng = np.random.default_rng(seed)
    n_blocks = math.ceil(n / block)
    starts = rng.integers(0, n - block + 1, size=(n_boot, n_blocks))
    A = (gg[starts + block] - gg[starts]).sum(1)  # (n_boot, k, k)
    b = (gy[starts + block] - gy[starts]).sum(1)  # (n_boot, k)
    out = {}
    for m, terms in models.items():
        idx = [names.index(t) for t in terms]
        out[m] = np.linalg.solve(A[:, idx][:, :, idx], b[:, idx][..., None])[..., 0]
    return out


def _percentile(samples, q=(2.5, 97.5)):
    return np.percentile(samples, q, axis=0).T


# -- where the viscous-only model misses ------------------------------------------------------


def _eta2(resid, labels) -> float:
    """Fraction of the residual's mean-square explained by its bin means (between-bin / total
    of the mean-square about zero)."""
    total = float(np.mean(resid**2))
    between = 0.0
    for lab in np.unique(labels):
        m = labels == lab
        between += m.sum() * resid[m].mean() ** 2
    return between / (resid.size * total)


def mismatch_location(data: dict, resid, *, small_frac: float = 0.4, n_bins: int = 12) -> dict:
    """Where in the (x, v) plane and at what speeds a residual force concentrates.

    - `velocity_bins`: count, mean and RMS residual per velocity bin (symmetric edges).
    - `small_speed`: the share of samples and of residual energy at |v| < `small_frac` x
      max|v|, and their ratio ("concentration": > 1 means the residual sits at low speed).
    - `sign_jump`: mean residual just above minus just below v = 0 (0 < |v| < 0.2 max|v|); a
      Coulomb term shows up as a jump of about 2 Fc that no odd polynomial in v can make.
    - `eta2_velocity`, `eta2_position`: fraction of the residual mean-square explained by 20
      quantile bins of v, resp. of x; `eta2_position_given_velocity`: x bins within each of 4
      |v|-sign classes, after removing the velocity-bin means (position dependence left over).
    - `xv_rms`: an 8 x 8 table of RMS residual over the (x, v) plane (quantile edges)."""
    x, v = data["x"], data["v"]
    r = np.asarray(resid, float)
    vmax = float(np.max(np.abs(v)))
    edges = np.linspace(-vmax, vmax, n_bins + 1)
    edges[-1] += 1e-12
    vb = []
    for lo, hi in itertools.pairwise(edges):
        m = (v >= lo) & (v < hi)
        if m.any():
            vb.append({"v_lo": float(lo), "v_hi": float(hi), "n": int(m.sum()),
                       "mean": float(r[m].mean()), "rms": float(np.sqrt(np.mean(r[m] ** 2)))})
    small = np.abs(v) < small_frac * vmax
    energy = float(np.sum(r[small] ** 2) / np.sum(r**2))
    share = float(small.mean())
    near = np.abs(v) < 0.2 * vmax
    jump = float(r[near & (v > 0)].mean() - r[near & (v < 0)].mean())
    qv = np.digitize(v, np.quantile(v, np.linspace(0, 1, 21)[1:-1]))
    qx = np.digitize(x, np.quantile(x, np.linspace(0, 1, 21)[1:-1]))
    r_v = r.copy()
    for lab in np.unique(qv):
        r_v[qv == lab] -= r[qv == lab].mean()
    xe = np.quantile(x, np.linspace(0, 1, 9))
    ve = np.quantile(v, np.linspace(0, 1, 9))
    ix = np.clip(np.digitize(x, xe[1:-1]), 0, 7)
    iv = np.clip(np.digitize(v, ve[1:-1]), 0, 7)
    table = np.full((8, 8), np.nan)
    for i in range(8):
        for j in range(8):
            m = (ix == i) & (iv == j)
            if m.sum() >= 5:
                table[i, j] = np.sqrt(np.mean(r[m] ** 2))
    return {
        "v_max": vmax,
        "velocity_bins": vb,
        "small_speed": {"threshold": small_frac * vmax, "sample_share": share,
                        "energy_share": energy, "concentration": energy / share},
        "sign_jump": jump,
        "eta2_velocity": _eta2(r, qv),
        "eta2_position": _eta2(r, qx),
        "eta2_position_given_velocity": _eta2(r_v, qx),
        "xv_rms": {"x_edges": xe.tolist(), "v_edges": ve.tolist(),
                   "rms": [[None if not np.isfinite(c) else float(c) for c in row]
                           for row in table]},
    }


def where_sentence(loc: dict) -> str:
    s = loc["small_speed"]
    return (f"residual concentrated where |v| is small: |v| < {s['threshold']:.3g} m/s holds "
            f"{100 * s['sample_share']:.0f} % of the samples and {100 * s['energy_share']:.0f} % "
            f"of the residual energy; the mean residual jumps by {loc['sign_jump']:.3g} N across "
            f"v = 0; velocity bins explain {100 * loc['eta2_velocity']:.0f} % of it, position "
            f"bins at given velocity {100 * loc['eta2_position_given_velocity']:.0f} %")


# -- optional output-error check: the closed loop simulated -----------------------------------


def simulate_closed_loop(which: str, coef: dict, *, substeps: int = 10,
                         pulses_volts: bool = True) -> dict:
    """Simulate the EMPS in closed loop with the benchmark's controller and a force model.

    Controller at 1 kHz (description, Eq. 6 and section 2.2): vir = kp kv (qg - q) - kv dq_m,
    dq_m from the FIR-filtered position (0.5 q_k + 0.5 q_(k-1)) differenced, saturated at
    +-10 V; on the validation run the pulses are added to vir as volts (the recorded vir steps
    by ~5 V at each pulse edge). Plant M q'' = gtau vir - Fv q' - Fc sgn(q') - offset
    (missing entries of `coef` are 0), semi-implicit Euler with `substeps` per sample.
    Returns the relative errors of simulated force and position against the measured ones."""
    import jax
    import jax.numpy as jnp

    raw = emps_raw(which)
    dt = SAMPLE_TIME
    h = dt / substeps
    gtau, kp, kv = raw["gtau"], raw["kp"], raw["kv"]
    M = coef["M"]
    fv, fc, off = coef.get("Fv", 0.0), coef.get("Fc", 0.0), coef.get("offset", 0.0)
    pulse = raw.get("pulses_N", np.zeros_like(raw["qm"])) if pulses_volts else 0 * raw["qm"]
    qg = jnp.asarray(raw["qg"])
    pul = jnp.asarray(pulse)
    _, v_meas, _ = lowpass_derivatives(raw["qm"], dt)

    def step(carry, inp):
        q, dq, q1, q2 = carry  # q_k, q'_k, q_(k-1), q_(k-2)
        qg_k, p_k = inp
        dqm = (0.5 * (q + q1) - 0.5 * (q1 + q2)) / dt
        vir = jnp.clip(kp * kv * (qg_k - q) - kv * dqm + p_k, -10.0, 10.0)
        tau = gtau * vir

        def sub(_, s):
            qq, vv = s
            vv = vv + h * (tau - fv * vv - fc * jnp.sign(vv) - off) / M
            return qq + h * vv, vv

        qn, dqn = jax.lax.fori_loop(0, substeps, sub, (q, dq))
        return (qn, dqn, q, q1), (q, vir)

    k0 = 2
    init = (jnp.asarray(raw["qm"][k0]), jnp.asarray(v_meas[k0]),
            jnp.asarray(raw["qm"][k0 - 1]), jnp.asarray(raw["qm"][k0 - 2]))
    _, (q_s, vir_s) = jax.jit(lambda c, xs: jax.lax.scan(step, c, xs))(init, (qg[k0:], pul[k0:]))
    q_s, vir_s = np.asarray(q_s), np.asarray(vir_s)
    f_meas = gtau * raw["vir"][k0:]
    return {"force_rel_error": nrmse(f_meas, gtau * vir_s),
            "position_rel_error": nrmse(raw["qm"][k0:], q_s),
            "max_abs_position_error_m": float(np.max(np.abs(raw["qm"][k0:] - q_s)))}


# -- the study ----------------------------------------------------------------------------------


def compare_differentiation(decimate_options=(1, BENCHMARK_DECIMATION)) -> list[dict]:
    """Fit the Coulomb model with several ways of getting v and a from the position, and score
    each by the final estimates: force NRMSE on the estimation run and on the validation run,
    and the distance of (M, Fv, Fc, offset) from the benchmark's reference values."""
    choices = [("central differences", {"derivative": "butterworth", "cutoff_hz": None})]
    choices += [(f"butterworth {fc:g} Hz", {"derivative": "butterworth", "cutoff_hz": fc})
                for fc in (20.0, 40.0, 60.0, 100.0, 200.0)]
    choices += [(f"savgol w={w}", {"derivative": "savgol", "sg_window": w})
                for w in (11, 21, 41, 81, 161)]
    choices += [("savgol auto window", {"derivative": "savgol", "sg_window": None})]
    terms = MODELS["coulomb"]
    ref = np.array([REFERENCE[k] for k in terms])
    rows = []
    for dec in decimate_options:
        for label, kw in choices:
            est = prepare("estimation", decimate=dec, **kw)
            val = prepare("validation", decimate=dec, **kw)
            f = fit(est, terms)
            rows.append({
                "method": label, "decimate": dec,
                "coef": dict(zip(terms, f["coef"].tolist())),
                "max_rel_dev_from_reference": float(np.max(np.abs(f["coef"] - ref) / np.abs(ref))),
                "nrmse_estimation": f["nrmse"],
                "nrmse_validation": nrmse(val["y"], predict(val, terms, f["coef"])),
            })
    return rows


def run_emps_study(
    *,
    cutoff_hz: float = DEFAULT_CUTOFF_HZ,
    decimate: int = BENCHMARK_DECIMATION,
    block_s: float = 1.0,
    n_boot: int = 1000,
    seed: int = 0,
    block_sensitivity=(0.1, 0.25, 0.5, 2.0),
    full_rate: bool = True,
    simulate: bool = False,
    differentiation: bool = False,
) -> dict:
    """The whole EMPS study, as a JSON-ready dict.

    - `models`: per model of `MODELS`: coefficients with bootstrap (primary), HAC and OLS 95 %
      intervals, NRMSE on the estimation and validation runs (and at 1 kHz, `full_rate`).
    - `mismatch`: where the viscous-only residual sits (`mismatch_location`), and the same
      statistics for the Coulomb model's residual.
    - `asymmetry`: bootstrap intervals of Fc+ - Fc- and Fv+ - Fv-.
    - `findings`: the discovery-report entries for the terms the viscous model left out.
    - `pulses`: validation NRMSE with and without adding `pulses_N` to the force.
    - `simulation` (`simulate`): output-error check of models 1 and 2 in closed loop.
    - `differentiation` (`differentiation`): `compare_differentiation()`."""
    est = prepare("estimation", cutoff_hz=cutoff_hz, decimate=decimate)
    val = prepare("validation", cutoff_hz=cutoff_hz, decimate=decimate)
    block = max(1, round(block_s / est["dt"]))
    boots = block_bootstrap(est, MODELS, block, n_boot, seed)
    fits = {m: fit(est, terms) for m, terms in MODELS.items()}
    if full_rate and decimate != 1:
        est1 = prepare("estimation", cutoff_hz=cutoff_hz, decimate=1)
        val1 = prepare("validation", cutoff_hz=cutoff_hz, decimate=1)
    models = {}
    for m, terms in MODELS.items():
        f = fits[m]
        X = design(est, terms)
        lags = block
        ci_boot = _percentile(boots[m])
        ci_hac = hac_intervals(X, f["resid"], f["coef"], lags)
        ci_ols = ols_intervals(X, f["resid"], f["coef"])
        entry = {
            "terms": list(terms),
            "coef": {t: float(c) for t, c in zip(terms, f["coef"])},
            "ci95": {t: ci_boot[i].tolist() for i, t in enumerate(terms)},
            "ci95_hac": {t: ci_hac[i].tolist() for i, t in enumerate(terms)},
            "ci95_ols_white": {t: ci_ols[i].tolist() for i, t in enumerate(terms)},
            "bootstrap_se": {t: float(s) for t, s in zip(terms, boots[m].std(0, ddof=1))},
            "nrmse_estimation": f["nrmse"],
            "nrmse_validation": nrmse(val["y"], predict(val, terms, f["coef"])),
            "condition_number": f["cond"],
            "residual_integrated_time_samples": integrated_time(f["resid"], 10 * block),
        }
        if full_rate and decimate != 1:
            f1 = fit(est1, terms)
            entry["full_rate"] = {
                "coef": {t: float(c) for t, c in zip(terms, f1["coef"])},
                "nrmse_estimation": f1["nrmse"],
                "nrmse_validation": nrmse(val1["y"], predict(val1, terms, f1["coef"])),
            }
        models[m] = entry

    sens = {}
    for bs in block_sensitivity:
        b = max(1, round(bs / est["dt"]))
        bb = block_bootstrap(est, {"coulomb": MODELS["coulomb"]}, b, n_boot, seed + 1)
        ci = _percentile(bb["coulomb"])
        sens[f"{bs:g}s"] = {t: ci[i].tolist() for i, t in enumerate(MODELS["coulomb"])}

    loc_visc = mismatch_location(est, fits["viscous"]["resid"])
    loc_coul = mismatch_location(est, fits["coulomb"]["resid"])
    loc_visc_val = mismatch_location(
        val, val["y"] - predict(val, MODELS["viscous"], fits["viscous"]["coef"]))

    ba = boots["asymmetric"]
    ia = {t: i for i, t in enumerate(MODELS["asymmetric"])}
    bc = boots["asymmetric_coulomb"]
    ic = {t: i for i, t in enumerate(MODELS["asymmetric_coulomb"])}
    ca = fits["asymmetric"]["coef"]
    cc = fits["asymmetric_coulomb"]["coef"]
    asym = {
        "asymmetric_coulomb_Fc+_minus_Fc-": {
            "value": float(cc[ic["Fc+"]] - cc[ic["Fc-"]]),
            "ci95": _percentile(bc[:, ic["Fc+"]] - bc[:, ic["Fc-"]]).tolist(),
            "note": "equals 2 x offset of the coulomb model: the same fit, reparametrised",
        },
        "asymmetric_Fv+_minus_Fv-": {
            "value": float(ca[ia["Fv+"]] - ca[ia["Fv-"]]),
            "ci95": _percentile(ba[:, ia["Fv+"]] - ba[:, ia["Fv-"]]).tolist(),
        },
        "asymmetric_Fc+_minus_Fc-": {
            "value": float(ca[ia["Fc+"]] - ca[ia["Fc-"]]),
            "ci95": _percentile(ba[:, ia["Fc+"]] - ba[:, ia["Fc-"]]).tolist(),
        },
        "reference": REFERENCE_ASYMMETRIC,
    }

    # findings: corrections to the viscous-only model, bootstrapped jointly.
    rss = {m: float(f["resid"] @ f["resid"]) for m, f in fits.items()}
    bv, bco = boots["viscous"], boots["coulomb"]
    cv = dict(zip(MODELS["viscous"], fits["viscous"]["coef"]))
    c2 = dict(zip(MODELS["coulomb"], fits["coulomb"]["coef"]))
    i2 = {t: i for i, t in enumerate(MODELS["coulomb"])}
    explained = {
        "Fc": 1 - rss["coulomb_no_offset"] / rss["viscous"],
        "offset": (rss["coulomb_no_offset"] - rss["coulomb"]) / rss["viscous"],
    }
    # the Fv correction: how much worse the Coulomb model fits with Fv held at the viscous value
    est_fixed = dict(est, y=est["y"] - cv["Fv"] * est["cols"]["Fv"])
    f_fixed = fit(est_fixed, ("M", "Fc", "offset"))
    explained["Fv"] = (float(f_fixed["resid"] @ f_fixed["resid"]) - rss["coulomb"]) / rss["viscous"]
    r_no_off = fits["coulomb_no_offset"]["resid"]
    where = {
        "Fc": where_sentence(loc_visc),
        "offset": f"a constant force: the residual of the model with Coulomb friction and no "
                  f"offset has mean {r_no_off.mean():.3g} N (equivalently, the Coulomb level "
                  f"differs between directions; one run cannot tell the two apart)",
        "Fv": "correction: the viscous-only fit had absorbed the Coulomb force into Fv",
    }
    findings = []
    for t in ("Fc", "offset"):
        findings.append({
            "dof": 0, "physics": PHYSICS[t], "coefficient": float(c2[t]),
            "ci95": _percentile(bco[:, i2[t]]).tolist(),
            "explained_fraction": float(explained[t]),
            "where": where[t],
        })
    findings.append({
        "dof": 0, "physics": PHYSICS["Fv"], "coefficient": float(c2["Fv"] - cv["Fv"]),
        "ci95": _percentile(bco[:, i2["Fv"]] - bv[:, 1]).tolist(),
        "explained_fraction": float(explained["Fv"]),
        "where": where["Fv"],
    })
    report = {
        "findings": findings,
        "before": {"nrmse": models["viscous"]["nrmse_validation"],
                   "nrmse_estimation": models["viscous"]["nrmse_estimation"]},
        "after": {"nrmse": models["coulomb"]["nrmse_validation"],
                  "nrmse_estimation": models["coulomb"]["nrmse_estimation"]},
        "model": "coulomb (tau = M a + Fv v + Fc sgn(v) + offset)",
    }

    val_p = prepare("validation", cutoff_hz=cutoff_hz, decimate=decimate, add_pulses=True)
    pulses = {
        "nrmse_validation_coulomb_without_pulses": models["coulomb"]["nrmse_validation"],
        "nrmse_validation_coulomb_with_pulses_added": nrmse(
            val_p["y"], predict(val_p, MODELS["coulomb"], fits["coulomb"]["coef"])),
    }
    X5 = np.column_stack([design(val, MODELS["coulomb"]), val_p["y"] - val["y"]])
    c5, *_ = np.linalg.lstsq(X5, val["y"], rcond=None)
    pulses["free_coefficient_on_pulses_N_fitted_on_validation"] = float(c5[-1])

    out = {
        "protocol": {
            "derivatives": f"Butterworth order 4, {cutoff_hz:g} Hz, filtfilt (zero phase), "
                           "then central differences (np.gradient)",
            "decimate": decimate, "sample_time_s": est["dt"], "trim_s": 0.05,
            "n_estimation": int(est["y"].size), "n_validation": int(val["y"].size),
            "force": "gtau * vir on both runs (pulses_N already inside vir)",
            "ci": f"moving-block bootstrap, blocks of {block_s:g} s ({block} samples), "
                  f"{n_boot} replicates, percentile 95 %; HAC: Newey-West, {block} lags",
        },
        "reference": {"coef": REFERENCE, "relative_error": REFERENCE_RELATIVE_ERROR},
        "models": models,
        "ci_block_length_sensitivity": sens,
        "mismatch": {"viscous_estimation": loc_visc, "viscous_validation": loc_visc_val,
                     "coulomb_estimation": loc_coul},
        "asymmetry": asym,
        "report": report,
        "pulses": pulses,
    }
    if simulate:
        sim = {}
        for m in ("viscous", "coulomb"):
            coef = models[m]["coef"]
            sim[m] = {w: simulate_closed_loop(w, coef) for w in ("estimation", "validation")}
        sim["reference_coef"] = {w: simulate_closed_loop(w, REFERENCE)
                                 for w in ("estimation", "validation")}
        out["simulation"] = sim
    if differentiation:
        out["differentiation"] = compare_differentiation()
    return out


def summary(study: dict) -> str:
    """A readable summary of `run_emps_study`'s dict."""
    lines = []
    p = study["protocol"]
    lines.append(f"EMPS study: {p['derivatives']}; decimate {p['decimate']}; CI: {p['ci']}")
    for m, e in study["models"].items():
        lines.append(f"\nmodel {m}: NRMSE estimation {100 * e['nrmse_estimation']:.2f} %, "
                     f"validation {100 * e['nrmse_validation']:.2f} %"
                     + (f"  (1 kHz: {100 * e['full_rate']['nrmse_estimation']:.2f} %, "
                        f"{100 * e['full_rate']['nrmse_validation']:.2f} %)"
                        if "full_rate" in e else ""))
        for t, c in e["coef"].items():
            lo, hi = e["ci95"][t]
            hlo, hhi = e["ci95_hac"][t]
            olo, ohi = e["ci95_ols_white"][t]
            lines.append(f"  {t:7s} {c:10.4f}  boot [{lo:.4f}, {hi:.4f}]  HAC [{hlo:.4f}, "
                         f"{hhi:.4f}]  OLS [{olo:.4f}, {ohi:.4f}]")
    lines.append("\nwhere model 'viscous' misses: " + study["report"]["findings"][0]["where"])
    lines.append("asymmetry: " + json.dumps({k: v for k, v in study["asymmetry"].items()
                                             if k != "reference"}))
    lines.append("pulses: " + json.dumps(study["pulses"]))
    if "simulation" in study:
        lines.append("simulation (closed loop): " + json.dumps(study["simulation"]))
    if "differentiation" in study:
        lines.append("\ndifferentiation (coulomb model):")
        for r in study["differentiation"]:
            lines.append(f"  dec {r['decimate']:2d} {r['method']:22s} est "
                         f"{100 * r['nrmse_estimation']:6.2f} %  val "
                         f"{100 * r['nrmse_validation']:6.2f} %  max dev from ref "
                         f"{100 * r['max_rel_dev_from_reference']:6.2f} %")
    return "\n".join(lines)


def _main(argv=None):
    import argparse
    import sys

    ap = argparse.ArgumentParser(description="EMPS study: the physics a viscous model misses")
    ap.add_argument("--out", default=str(RESULTS_DIR / "emps_study.md"),
                    help="write the readable summary here (markdown)")
    ap.add_argument("--json", help="write the full study dict to this file "
                                   "(e.g. results/data/emps_study.json)")
    ap.add_argument("--simulate", action="store_true", help="closed-loop output-error check")
    ap.add_argument("--differentiation", action="store_true",
                    help="compare ways of differentiating the position")
    ap.add_argument("--n-boot", type=int, default=1000)
    args = ap.parse_args(argv)
    study = run_emps_study(n_boot=args.n_boot, simulate=args.simulate,
                           differentiation=args.differentiation)
    text = summary(study)
    print(text)
    cmd = "python studies/emps_study.py" + " ".join([""] + list(sys.argv[1:] if argv is None else argv))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(f"# EMPS: the physics a viscous model misses\n\nCommand: `{cmd}`\n\n```\n{text}\n```\n")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        with open(args.json, "w") as fh:
            json.dump(study, fh, indent=1)


# -- the same study through the generic API ----------------------------------------------------


def discover_emps(*, decimate: int = BENCHMARK_DECIMATION, n_boot: int = 200):
    """The EMPS story with `gmr_jax.discover`: start from the mass + viscous model fitted to the
    estimation run (Fv absorbs the friction), discover on the estimation run, measure the force
    error on the validation (pulses) run. Returns (viscous-only GlobalModel, DiscoveryReport).

    Same protocol as `prepare`: v, a by zero-phase Butterworth (100 Hz) and central differences
    at 1 kHz, then the regression columns decimated in parallel (`decimate`)."""
    visc = fit(prepare("estimation", decimate=decimate), MODELS["viscous"])
    model = g.from_terms([visc["coef"][0]], [{"dof": 0, "physics": "velocity_damping", "order": 1,
                                              "coefficient": float(visc["coef"][1])}])
    rep = g.discover(model, [load_emps("estimation")], [load_emps("validation")], decimate=decimate,
                     error="equation", rule=g.SelectionRule(n_boot=n_boot)).value
    return model, rep


if __name__ == "__main__":
    _main()
