"""Concealed-physics scenarios: a truth with an effect the simulation model lacks.

A scenario simulates the truth (a `GlobalModel`) under random-phase multisine inputs, records
noisy signals at a given SNR (optionally displacement and inputs only), and calibrates the
user's simulation model - the truth's terms without the effect - to the estimation recordings
by equation-error least squares, so that the effect hides inside the calibrated coefficients
(e.g. Coulomb friction inside viscous damping). Used by `studies/discover_scenarios.py` and
the tests. `build_full` also keeps the noise-free signals of every recording (`Clean`), so that a
benchmark can score a model against the noise-free truth response (`model_error`), not only
against the noisy record.
"""

from dataclasses import dataclass, replace
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from gmr_jax import (
    AbstractTopology,
    Chain,
    Independent,
    Integrator,
    Recording,
    Sampled,
    Term,
    add_noise,
    from_terms,
    regression_targets,
    simulate,
)

SIM = Integrator(rtol=1e-7, atol=1e-10, max_steps=400_000)


@dataclass(frozen=True)
class Scenario:
    """`terms`: the simulation model's terms (gmr-model/1 dicts); `effect`: (Term, ratio, host)
    with the effect sized so that its RMS force is `ratio` x the RMS force of the `host` term
    (a Term of the model); None for a control. `excite`: "force" (multisine on the last mass)
    or "base"."""

    name: str
    masses: tuple
    topology: str
    terms: tuple
    effect: tuple | None
    snr_db: float = 50.0
    measured: str = "xva"  # "x": displacement and inputs only; "v" / "a": velocity / acceleration only
    excite: str = "force"
    amplitude: float = 1.0
    band: tuple = (0.3, 6.0)
    duration: float = 40.0
    fs: float = 200.0
    seed: int = 0
    sign_eps: float = 1e-4
    noise_seed: int = 0  # 0: the original noise draw; k > 0: another draw, same inputs and truth
    time_dtype: str = "float64"  # "float32": time stamps stored in single precision (a logger's column)
    # closed loop: a position controller (Kp, Kd) drives the plant to a multisine reference; the
    # recorded force is the controller's output Kp (r - x) - Kd v (the EMPS drive's situation)
    controller: tuple | None = None


@dataclass(frozen=True)
class Clean:
    """The noise-free signals of one recording: the truth's response to its noise-free input."""

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    base_acc: np.ndarray
    force: np.ndarray
    drive: np.ndarray | None = None  # closed loop: the reference force Kp r on the last mass


def closed_loop(model, sc: Scenario):
    """The plant with its controller: stiffness Kp and viscous damping Kd added on the last DOF."""
    if sc.controller is None:
        return model
    kp, kd = sc.controller
    d = model.n_dof - 1
    return from_terms(model.masses, model.terms() + [
        {"dof": d, "physics": "stiffness", "order": 1, "coefficient": kp},
        {"dof": d, "physics": "velocity_damping", "order": 1, "coefficient": kd}], model.topology,
        duplicates="add")


def multisine(t, band, rms, seed):
    """Random-phase multisine with flat amplitude over `band` (Hz), scaled to `rms`."""
    rng = np.random.default_rng(seed)
    T = t[-1] - t[0] + (t[1] - t[0])
    f = np.arange(1, int(band[1] * T) + 1) / T
    f = f[f >= band[0]]
    ph = rng.uniform(0, 2 * np.pi, f.size)
    s = np.sin(2 * np.pi * f[None, :] * t[:, None] + ph[None, :]).sum(1)
    return rms * s / np.std(s)


def _simulate_run(model, sc: Scenario, seed: int):
    d = model.n_dof
    t = np.arange(int(sc.duration * sc.fs)) / sc.fs
    u = multisine(t, sc.band, sc.amplitude, seed)
    ramp = np.clip(t / 2.0, 0, 1)  # 2 s fade-in
    u = u * ramp
    if sc.excite == "base":
        b, f = u, np.zeros((t.size, d))
    else:
        b, f = np.zeros(t.size), np.zeros((t.size, d))
        f[:, -1] = u
    inp = Sampled(jnp.asarray(t), jnp.asarray(b), jnp.asarray(f), n_dof=d)
    cl = closed_loop(model, sc)
    sol = simulate(cl.with_sign_eps(sc.sign_eps), inp, jnp.asarray(t), jnp.zeros(d),
                   integrator=SIM, throw=False)
    x, v = (np.asarray(z) for z in sol.value)
    if not np.all(np.isfinite(x)):
        raise RuntimeError(f"{sc.name}: truth simulation failed")
    m = cl.with_sign_eps(sc.sign_eps)
    xdd = np.asarray(jax.vmap(m.accelerations)(jnp.asarray(x), jnp.asarray(v), jnp.asarray(b),
                                               jnp.asarray(f)))
    a = np.asarray(model.absolute_accelerations(jnp.asarray(xdd), jnp.asarray(b)))
    if sc.controller is not None:  # the plant's force: the controller's output
        kp, kd = sc.controller
        drive = f
        f = drive.copy()
        f[:, -1] = drive[:, -1] - kp * x[:, -1] - kd * v[:, -1]
        return t, x, v, a, b, f, drive
    return t, x, v, a, b, f, None


def _noise_rng(sc: Scenario, seed: int) -> np.random.Generator:
    if sc.noise_seed == 0:
        return np.random.default_rng(seed + 1000)
    return np.random.default_rng([seed + 1000, sc.noise_seed])


def record(sc: Scenario, model, seed: int, name: str) -> Recording:
    """One noisy recording of `model` under the scenario's input (inputs noisy too)."""
    return record_with_clean(sc, model, seed, name)[0]


def record_with_clean(sc: Scenario, model, seed: int, name: str) -> tuple[Recording, Clean]:
    """`record` and the noise-free signals it was made from."""
    t, x, v, a, b, f, drive = _simulate_run(model, sc, seed)
    rng = _noise_rng(sc, seed)
    if sc.measured in ("v", "a"):  # a velocity- or acceleration-only sensor
        sig = {sc.measured: add_noise({"v": v, "a": a}[sc.measured], sc.snr_db, rng)}
    else:
        sig = {"x": add_noise(x, sc.snr_db, rng)}
    if sc.measured == "xva":
        sig["v"] = add_noise(v, sc.snr_db, rng)
        sig["a"] = add_noise(a, sc.snr_db, rng)
    if sc.excite == "base":
        sig["base_acc"] = add_noise(b, sc.snr_db, rng)
    else:
        fn = f.copy()
        fn[:, -1] = add_noise(f[:, -1], sc.snr_db, rng)
        sig["force"] = fn
    rec = Recording(t=t.astype(sc.time_dtype), masses=np.asarray(sc.masses, float), name=name, **sig)
    return rec, Clean(t=t, x=x, v=v, a=a, base_acc=b, force=f, drive=drive)


def effect_coefficient(sc: Scenario, base_model) -> float:
    """Size the effect: RMS of its force = ratio x RMS of the host term's force (pilot run of the
    model without the effect)."""
    term, ratio, host = sc.effect
    _, x, v, *_ = _simulate_run(base_model, sc, sc.seed + 77)
    c_host = [t["coefficient"] for t in sc.terms if t["dof"] == host.dof and t["physics"] == host.family
              and t["order"] == host.order][0]
    host_f = c_host * basis(host, x[:, host.dof], v[:, host.dof])
    eff = basis(term, x[:, term.dof], v[:, term.dof])
    sgn = np.sign(c_host) if term.family == host.family else 1.0
    return float(sgn * ratio * np.std(host_f) / np.sqrt(np.mean(eff**2)))


def basis(term: Term, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The basis function of `term` at (x, v) of its DOF (arrays of one DOF), as in the
    gmr-model/1 format: stiffness x^k, velocity damping sgn(v)|v|^j, position damping x^j v."""
    if term.family == "stiffness":
        return x ** term.order
    if term.family == "velocity_damping":
        return np.sign(v) * np.abs(v) ** term.order if term.order != 1 else v
    return x ** term.order * v


# -- equation-error calibration (strong form, or weak form with test functions) ---------------
# The same rows as `gmr_jax.discover` builds for a model with every coefficient zero.

WEAK_POWER = 4


def band_edge(x: np.ndarray, dt: float, fraction: float = 0.995) -> float:
    """Frequency below which `fraction` of the power of x (mean removed) lies, in Hz."""
    x = np.asarray(x, float) - np.mean(x)
    p = np.abs(np.fft.rfft(x * np.hanning(x.size))) ** 2
    p[0] = 0.0
    c = np.cumsum(p) / max(np.sum(p), 1e-300)
    return float(np.fft.rfftfreq(x.size, dt)[int(np.searchsorted(c, fraction))])


def _test_functions(support: int, dt: float):
    """psi = (1 - s^2)^4 on `support` points over [-1, 1] and psi'' (1/s^2)."""
    s = np.linspace(-1.0, 1.0, support)
    h = 0.5 * (support - 1) * dt
    p = WEAK_POWER
    u = 1.0 - s**2
    return u**p, (p * (p - 1) * u ** (p - 2) * 4 * s**2 - 2 * p * u ** (p - 1)) / h**2


def _weak_support(x: np.ndarray, dt: float) -> int:
    """One period at the band edge of x (samples), at least 15, odd."""
    f = max(max(band_edge(x[:, k], dt) for k in range(x.shape[1])), 1e-12)
    n = max(15, min(int(round(1.0 / (f * dt))), x.shape[0] // 4))
    return n | 1


def _integrate(sig: np.ndarray, kernel: np.ndarray, stride: int, dt: float) -> np.ndarray:
    w = sliding_window_view(sig, kernel.size, axis=0)[::stride]
    return np.tensordot(w, kernel, axes=([-1], [0])) * dt


def _rows(rec, masses, topology, dof: int, terms: list, form: str):
    """(target, columns) of DOF `dof` from a completed recording: the force the DOF carries
    against the basis functions of `terms`, one row per sample ("strong") or per test-function
    window ("weak": inertia integrated by parts twice, no acceleration used)."""
    x, v = rec.x, rec.v
    cols = (np.stack([basis(t, x[:, t.dof], v[:, t.dof]) for t in terms], 1) if terms
            else np.zeros((x.shape[0], 0)))
    if form == "strong":
        return regression_targets(rec, masses, topology)[:, dof], cols
    dt = rec.dt
    L = _weak_support(x, dt)
    psi, d2 = _test_functions(L, dt)
    stride = max(1, L // 4)
    b, f = rec.inputs()
    acc = _integrate(topology.displacements(x), d2, stride, dt) + _integrate(b, psi, stride, dt)[:, None]
    tgt = topology.carried(_integrate(f, psi, stride, dt) - acc * masses[None, :])[:, dof]
    return tgt, _integrate(cols, psi, stride, dt)


def calibrate(terms, masses, topology, recs, form: str) -> "object":
    """Least-squares equation-error calibration of the model structure `terms` (their
    coefficients are refitted; masses kept) on the recordings (completed)."""
    masses = np.asarray(masses, float)
    topo = topology if isinstance(topology, AbstractTopology) else {"chain": Chain(), "independent": Independent()}[topology]
    d = len(masses)
    out = []
    for i in range(d):
        ts = [Term(i, t["physics"], t["order"]) for t in terms if t["dof"] == i]
        rows = [_rows(r, masses, topo, i, ts, form) for r in recs]
        X = np.concatenate([c for _, c in rows])
        y = np.concatenate([t for t, _ in rows])
        c, *_ = np.linalg.lstsq(X, y, rcond=None)
        out += [tm.model_term(ci) for tm, ci in zip(ts, c)]
    return from_terms(masses, out, topology)


class Built(NamedTuple):
    truth: object
    model: object
    est: list
    hold: list
    c_eff: float | None
    est_clean: list  # Clean per estimation recording
    hold_clean: list  # Clean per holdout recording


def build(sc: Scenario, n_estimation: int = 2, n_holdout: int = 1):
    """(truth model, calibrated simulation model, estimation recordings, holdout recordings,
    true effect coefficient or None)."""
    return tuple(build_full(sc, n_estimation, n_holdout)[:5])


def build_full(sc: Scenario, n_estimation: int = 2, n_holdout: int = 1) -> Built:
    """`build` plus the noise-free signals of every recording (`Built`)."""
    base = from_terms(sc.masses, list(sc.terms), sc.topology)
    truth, c_eff = base, None
    if sc.effect is not None:
        c_eff = effect_coefficient(sc, base)
        term = sc.effect[0]
        truth = from_terms(sc.masses, list(sc.terms) + [term.model_term(c_eff)], sc.topology)
    est = [record_with_clean(sc, truth, sc.seed + 10 * k, f"{sc.name}_est{k}")
           for k in range(n_estimation)]
    hold = [record_with_clean(sc, truth, sc.seed + 500 + 10 * k, f"{sc.name}_hold{k}")
            for k in range(n_holdout)]
    form = "weak" if sc.measured in ("x", "v") else "strong"
    done = [r.complete(sc.topology) for r, _ in est]
    model = calibrate(list(sc.terms), sc.masses, sc.topology, done, form)
    return Built(truth, model, [r for r, _ in est], [r for r, _ in hold], c_eff,
                 [c for _, c in est], [c for _, c in hold])


def model_error(model, clean: list, sc: Scenario) -> float:
    """Model error proper: NRMSE ||x_sim - x_true|| / ||x_true - mean|| of `model` simulated under
    the noise-free inputs of the recordings `clean` from the truth's initial state (rest), with
    the truth's sign smoothing, against the noise-free truth response; 0 for the truth itself.
    nan when the model cannot be simulated."""
    num = den = 0.0
    m = closed_loop(model, sc).with_sign_eps(sc.sign_eps)
    for c in clean:
        d = model.n_dof
        f = c.force if c.drive is None else c.drive  # closed loop: the controller simulated with it
        inp = Sampled(jnp.asarray(c.t), jnp.asarray(c.base_acc), jnp.asarray(f), n_dof=d)
        sol = simulate(m, inp, jnp.asarray(c.t), jnp.zeros(d), integrator=SIM, throw=False)
        x = np.asarray(sol.value[0])
        if not np.all(np.isfinite(x)):
            return float("nan")
        num += np.sum((x - c.x) ** 2)
        den += np.sum((c.x - c.x.mean(0)) ** 2)
    return float(np.sqrt(num / den))


def with_noise(sc: Scenario, snr_db: float) -> Scenario:
    return replace(sc, snr_db=snr_db)
