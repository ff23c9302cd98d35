"""Equation-error regression rows: the model's force residual against candidate basis functions.

For DOF i the equation of motion (contracts) gives the force the DOF carries,
y_i = f_i - m_i a_i (independent) or sum_{k>=i} (f_k - m_k a_k) (chain), and the residual of a
model is r_i = y_i - F_i(x_i, v_i). A correction sum_j c_j phi_j(x_i, v_i) of the model's force
(re-calibrated existing terms plus new physics) is fitted to r_i by least squares, in one of two
forms:

- **strong** (`form="strong"`): one row per sample, with the measured or estimated v and a.
  `decimate=q > 1` low-passes and decimates every column and the target together (zero-phase
  Chebyshev, as `scipy.signal.decimate`; the EMPS benchmark's "parallel filtering"), which
  removes disturbances above the new Nyquist frequency from both sides alike.
- **weak** (`form="weak"`, the default when `a` was estimated): the equation is integrated
  against compactly supported test functions psi_k(t) = (1 - s^2)^4, s = (t - c_k)/h, so that
  the inertia needs no acceleration: int a psi dt = int x_rel psi'' dt + int base_acc psi dt
  (integration by parts twice; psi, psi' vanish at the ends of the support). Rows are the
  integrals over overlapping supports (stride = 1/4 of the support). The basis functions still use
  x and v (v from Savitzky-Golay when not recorded), but no second derivative of noisy data
  is taken. (Weak SINDy: Messenger & Bortz, J. Comput. Phys. 2021.)
"""

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from .._recordings._recording import regression_targets
from .._recordings._derivatives import band_edge
from ._catalogue import Term, basis

WEAK_POWER = 4


@dataclass
class Rows:
    """Regression rows of one DOF from one recording: target `y` (rows,), `columns` (rows,
    n_terms) for `terms`, and `mass` (rows,) the column of a mass correction (independent
    topology; None for a chain)."""

    y: np.ndarray
    columns: np.ndarray
    mass: np.ndarray | None
    target: np.ndarray | None = None  # the force the DOF carries (y + model force)
    x: np.ndarray | None = None  # strong form: the DOF's x, v and input at the rows
    v: np.ndarray | None = None
    u: np.ndarray | None = None
    scale: float = 1.0  # squared norm of the applied force rows (inertia rows if no force)
    applied_sq: float = 0.0  # squared norm of the applied (input) force rows
    inertia_sq: float = 0.0  # squared norm of the inertial force rows


def model_force(model, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    """F(x, v) of every DOF at every sample (N, D)."""
    return np.asarray(jax.vmap(model.force)(jnp.asarray(x), jnp.asarray(v)))


def test_functions(support: int, dt: float):
    """psi, psi'' sampled on `support` points (the bump (1 - s^2)^4 on [-1, 1]), in 1/s^2 for
    psi''; both vanish with their first derivative at the ends. The sampled psi'' is corrected by
    a multiple of psi so that its sum is exactly zero, as its integral is: a constant offset of x
    (an unobserved equilibrium, a sensor's zero) then adds nothing to the inertia rows."""
    s = np.linspace(-1.0, 1.0, support)
    h = 0.5 * (support - 1) * dt
    p = WEAK_POWER
    u = 1.0 - s**2
    psi = u**p
    d2 = (p * (p - 1) * u ** (p - 2) * 4 * s**2 - 2 * p * u ** (p - 1)) / h**2
    d2 = d2 - psi * (d2.sum() / psi.sum())
    return psi, d2


def weak_support(x: np.ndarray, dt: float) -> int:
    """Default support of the test functions (samples): one period at the band edge of x (the
    frequency below which 99.5 % of its power lies), at least 15 samples, odd."""
    f = max(band_edge(x - x.mean(0), dt) if x.ndim == 1 else
            max(band_edge(x[:, k], dt) for k in range(x.shape[1])), 1e-12)
    n = int(round(1.0 / (f * dt)))
    n = max(15, min(n, x.shape[0] // 4))
    return n | 1


def _integrate(sig: np.ndarray, kernel: np.ndarray, stride: int, dt: float) -> np.ndarray:
    """Rows int sig psi dt over every window (start 0, stride), trapezoid = sum (psi ends are 0)."""
    w = sliding_window_view(sig, kernel.size, axis=0)[::stride]  # (K, ..., L)
    return np.tensordot(w, kernel, axes=([-1], [0])) * dt


def _pdecimate(a: np.ndarray, q: int, trim: int) -> np.ndarray:
    from scipy.signal import decimate as _decimate

    out = _decimate(a, q, ftype="iir", zero_phase=True, axis=0)
    return out[trim: out.shape[0] - trim]


def dof_rows(
    rec,
    model,
    dof: int,
    terms: list[Term],
    *,
    form: str = "strong",
    support: int | None = None,
    decimate: int = 1,
    mass_column: bool = False,
) -> Rows:
    """Rows of DOF `dof` from one completed recording (x, v and a present) for `terms`.

    The target is the residual of `model`; a mass column is the correction direction of the
    DOF's mass (independent topology only)."""
    masses = np.asarray(model.masses)
    topo = model.topology
    x, v = rec.x, rec.v
    F = model_force(model, x, v)[:, dof]
    cols = np.stack([basis(t, x[:, t.dof], v[:, t.dof]) for t in terms], 1) if terms else np.zeros((x.shape[0], 0))
    if form == "strong":
        tgt = regression_targets(rec, masses, topo)[:, dof]
        applied = regression_targets(rec, np.zeros_like(masses), topo)[:, dof]
        y = tgt - F
        m = rec.a[:, dof] if mass_column else None
        b, f = rec.inputs()
        u = b if rec.base_acc is not None else f[:, -1]
        xd, vd = x[:, dof], v[:, dof]
        if decimate > 1:
            trim = 5
            y, tgt, xd, vd, u, applied = (_pdecimate(z, decimate, trim)
                                          for z in (y, tgt, xd, vd, u, applied))
            cols = _pdecimate(cols, decimate, trim) if cols.shape[1] else np.zeros((y.shape[0], 0))
            m = None if m is None else _pdecimate(m, decimate, trim)
        return Rows(y, cols, m, tgt, xd, vd, u, _scale(applied, applied - tgt),
                    float(applied @ applied), float((applied - tgt) @ (applied - tgt)))
    if form != "weak":
        raise ValueError(f"form must be 'strong' or 'weak', got {form!r}")
    dt = rec.dt
    L = support or weak_support(x, dt)
    psi, d2 = test_functions(L, dt)
    stride = max(1, L // 4)
    b, f = rec.inputs()
    rel = topo.displacements(x)  # displacement of each mass vs the base
    # int a_k psi = int rel_k psi'' + int base_acc psi
    acc = _integrate(rel, d2, stride, dt) + _integrate(b, psi, stride, dt)[:, None]  # (K, D)
    inert = acc * masses[None, :]
    fw = _integrate(f, psi, stride, dt)
    tgt = topo.carried(fw - inert)[:, dof]
    applied = topo.carried(fw)[:, dof]
    y = tgt - _integrate(F, psi, stride, dt)
    cw = _integrate(cols, psi, stride, dt) if cols.shape[1] else np.zeros((y.shape[0], 0))
    return Rows(y, cw, acc[:, dof] if mass_column else None, tgt, scale=_scale(applied, applied - tgt),
                applied_sq=float(applied @ applied), inertia_sq=float((applied - tgt) @ (applied - tgt)))


#: strong-form rows where sgn(v) is uncertain are left out of the regression (`sign_certain`): |v| within this many
#: standard deviations of the noise of a measured v (`_noise.white_floor`), or below `STICK` x its RMS (a mass that
#: sticks: sgn(v) is not the friction's sign there)
SIGN_SIGMAS = 3.0
STICK = 1e-3


def sign_certain(rows: Rows, rec, dof: int) -> Rows:
    """Strong-form `rows` without the samples where sgn(v) is uncertain. A Coulomb column sgn(v) of a noisy v flips
    where |v| is within the noise, and where the mass sticks its sign is not the friction's: both bias the
    friction low and push the viscous term up, by more than the bootstrap's interval (hand-made Duffing with 0.05
    sgn(v), 40 dB on x, v, a: 0.0466, 95 % CI 0.0458-0.0472, viscous +23 %; exact v: 0.0490, stick rows only).
    Where v and a were estimated from a measured x, the samples within half the Savitzky-Golay window of a
    reversal of v are left out too: the window straddles the friction's jump there, so the estimated a and v mix
    its two sides (hand-made linear oscillator with 9.417 sgn(v), x only, noise-free: 8.849, 95 % CI 8.805-8.902;
    without them 9.418; the EMPS drive's 7 reversals: 20.29 -> 20.58 N, the benchmark's 20.39). Weak-form rows
    (integrals over windows) and an estimated v (its noise is not white) are otherwise returned as they are, but
    for the stick rows."""
    from .._recordings._derivatives import auto_window
    from .._recordings._noise import white_floor

    if rows.v is None:
        return rows
    v = np.asarray(rows.v, float)
    floor = None
    if rec.v is not None and "v" not in rec.derived:
        var = white_floor(np.asarray(rec.v[:, dof], float), rec.dt)
        floor = None if var is None else SIGN_SIGMAS * float(np.sqrt(var))
    cut = max(floor or 0.0, STICK * float(np.sqrt(np.mean(v**2))))
    keep = np.abs(v) > cut
    if keep.sum() < 0.5 * keep.size:
        keep = np.ones_like(keep)
    if "v" in rec.derived and "x" not in rec.derived and v.size == rec.n_samples and np.ptp(rec.x[:, dof]):
        half = auto_window(np.asarray(rec.x[:, dof], float), rec.dt) // 2
        flips = np.nonzero(np.sign(v[1:]) * np.sign(v[:-1]) < 0)[0]
        near = np.zeros(v.size, bool)
        for i in flips:
            near[max(0, i - half): i + half + 2] = True
        if (keep & ~near).sum() >= 0.5 * keep.size:
            keep = keep & ~near
    if keep.all():
        return rows
    take = lambda a: None if a is None else np.asarray(a)[keep]  # noqa: E731
    return Rows(rows.y[keep], rows.columns[keep], take(rows.mass), take(rows.target), take(rows.x), v[keep],
                take(rows.u), rows.scale, rows.applied_sq, rows.inertia_sq)


def _scale(applied, inertia) -> float:
    """Squared norm for relative equation errors: the applied force (the EMPS benchmark's
    ||tau||), or the inertial force when no force is applied (base excitation)."""
    a = float(applied @ applied)
    return a if a > 0 else float(inertia @ inertia)
