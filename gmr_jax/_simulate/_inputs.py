"""Excitations: base motion and forces on the masses, as functions of time."""

import abc

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float


class AbstractInput(eqx.Module):
    """An excitation: `__call__(t)` gives (base acceleration, force on each mass (dof,))."""

    n_dof: eqx.AbstractVar[int]

    @abc.abstractmethod
    def __call__(self, t) -> tuple[Float[Array, ""], Float[Array, " dof"]]:
        """(base_acc, force) at time t."""

    def jump_times(self) -> Float[Array, " jumps"] | None:
        """Times where the input is discontinuous (declared to the step-size controller)."""
        return None

    def step_times(self) -> Float[Array, " steps"] | None:
        """Times where the input has a kink (a step is made there, no step straddles them)."""
        return None


class NoInput(AbstractInput):
    n_dof: int = eqx.field(static=True, default=1)

    def __call__(self, t):
        return jnp.zeros(()), jnp.zeros(self.n_dof)


class BaseChirp(AbstractInput):
    """Base displacement x_b = A sin(2π(f0 t + (f1 - f0) t² / (2T))): a linear sweep
    (the paper's sweep excitation). Gives the analytic base acceleration."""

    amplitude: Float[Array, ""] | float
    f0: float
    f1: float
    duration: float
    n_dof: int = eqx.field(static=True, default=1)

    def __call__(self, t):
        k = (self.f1 - self.f0) / self.duration
        phase = 2 * jnp.pi * (self.f0 * t + 0.5 * k * t**2)
        w = 2 * jnp.pi * (self.f0 + k * t)
        wd = 2 * jnp.pi * k
        acc = self.amplitude * (-(w**2) * jnp.sin(phase) + wd * jnp.cos(phase))
        return acc, jnp.zeros(self.n_dof)

    def displacement(self, t):
        k = (self.f1 - self.f0) / self.duration
        return self.amplitude * jnp.sin(2 * jnp.pi * (self.f0 * t + 0.5 * k * t**2))


class BaseSine(AbstractInput):
    """Harmonic base displacement A sin(2π f t) (transmissibility, paper Eq. 24)."""

    amplitude: Float[Array, ""] | float
    frequency: Float[Array, ""] | float
    n_dof: int = eqx.field(static=True, default=1)

    def __call__(self, t):
        w = 2 * jnp.pi * self.frequency
        return -self.amplitude * w**2 * jnp.sin(w * t), jnp.zeros(self.n_dof)


def _half_sine(t, frequency, amplitude):
    """Eq. (25): A sin(2π f t) for t <= 1/(2f), then 0."""
    return jnp.where(t <= 0.5 / frequency, amplitude * jnp.sin(2 * jnp.pi * frequency * t), 0.0)


def _half_sine_end(frequency):
    """The half-sine's end 1/(2f), as the (1,) jump times of its input."""
    return jnp.reshape(0.5 / jnp.asarray(frequency, float), (1,))


class HalfSineTip(AbstractInput):
    """Paper Eq. (25): tip force A sin(2π f t) for t <= 1/(2f), then 0, on the last mass."""

    frequency: Float[Array, ""] | float
    amplitude: Float[Array, ""] | float
    n_dof: int = eqx.field(static=True, default=1)

    def __call__(self, t):
        f = _half_sine(t, self.frequency, self.amplitude)
        return jnp.zeros(()), jnp.zeros(self.n_dof).at[-1].set(f)

    def jump_times(self):
        return _half_sine_end(self.frequency)


class HalfSineNodes(AbstractInput):
    """Eq. (25) on chosen masses: the force A sin(2π f t) for t <= 1/(2f), then 0, on each mass
    in `nodes` (e.g. the first level of a lattice, to start a transition front)."""

    frequency: Float[Array, ""] | float
    amplitude: Float[Array, ""] | float
    nodes: tuple[int, ...] = eqx.field(static=True, converter=lambda k: tuple(int(i) for i in k))
    n_dof: int = eqx.field(static=True, default=1)

    def __check_init__(self):
        if not self.nodes or min(self.nodes) < 0 or max(self.nodes) >= self.n_dof:
            raise ValueError(f"nodes must be mass indices in 0..{self.n_dof - 1}, got {self.nodes}")

    def __call__(self, t):
        f = _half_sine(t, self.frequency, self.amplitude)
        return jnp.zeros(()), jnp.zeros(self.n_dof).at[jnp.asarray(self.nodes)].set(f)

    def jump_times(self):
        return _half_sine_end(self.frequency)


class HalfSineBase(AbstractInput):
    """Base-excitation variant of Eq. (25): base acceleration A sin(2π f t) for t <= 1/(2f),
    then 0 (A in m/s²; the base is then left moving at constant velocity, which a chain of
    relative deformations does not feel)."""

    frequency: Float[Array, ""] | float
    amplitude: Float[Array, ""] | float
    n_dof: int = eqx.field(static=True, default=1)

    def __call__(self, t):
        b = _half_sine(t, self.frequency, self.amplitude)
        return b, jnp.zeros(self.n_dof)

    def jump_times(self):
        return _half_sine_end(self.frequency)


def half_sine(load: str, f, A, n_dof: int) -> AbstractInput:
    """The Eq. (25) half-sine as an input: `load` "tip" (force on the last mass, `HalfSineTip`)
    or "base" (base acceleration, `HalfSineBase`)."""
    if load == "tip":
        return HalfSineTip(f, A, n_dof=n_dof)
    if load == "base":
        return HalfSineBase(f, A, n_dof=n_dof)
    raise ValueError(f"load must be 'tip' or 'base', got {load!r}")


class Sampled(AbstractInput):
    """Measured inputs, linearly interpolated between samples (zero after the last).

    `declare_samples=True` declares the sample times to the step-size controller (a step ends
    at every sample, where the interpolant has a kink): without it a long record with a rough
    input costs many rejected steps (~17 per sample on a 30,000-sample EMPS run)."""

    t: Float[Array, " samples"]
    base_acc: Float[Array, " samples"]
    force: Float[Array, "samples dof"]
    n_dof: int = eqx.field(static=True, default=1)
    declare_samples: bool = eqx.field(static=True, default=False)

    def step_times(self):
        return self.t if self.declare_samples else None

    def __call__(self, t):
        inside = t <= self.t[-1]
        b = jnp.where(inside, jnp.interp(t, self.t, self.base_acc), 0.0)
        f = jnp.stack([jnp.interp(t, self.t, self.force[:, i]) for i in range(self.n_dof)])
        return b, jnp.where(inside, f, 0.0)


class SampledSpline(AbstractInput):
    """Measured band-limited inputs, interpolated by a not-a-knot cubic spline between samples
    (C2, so no kink for the step-size controller; zero after the last sample). Build it with
    `sampled_spline`. For a band-limited input sampled at ~9 points per period a linear
    interpolant distorts the response (each kink excites the model); the spline does not."""

    t: Float[Array, " samples"]
    coef_b: Float[Array, "4 intervals"]
    coef_f: Float[Array, "4 intervals dof"]
    n_dof: int = eqx.field(static=True, default=1)

    def __call__(self, t):
        i = jnp.clip(jnp.searchsorted(self.t, t, side="right") - 1, 0, self.t.shape[0] - 2)
        s = t - self.t[i]

        def horner(c):
            return ((c[0, i] * s + c[1, i]) * s + c[2, i]) * s + c[3, i]

        inside = t <= self.t[-1]
        return jnp.where(inside, horner(self.coef_b), 0.0), jnp.where(inside, horner(self.coef_f), 0.0)


def sampled_spline(t, base_acc, force, n_dof: int) -> SampledSpline:
    """`SampledSpline` of sampled inputs (numpy arrays: t (N,), base_acc (N,), force (N, dof))."""
    import numpy as np
    from scipy.interpolate import CubicSpline

    t = np.asarray(t, float)
    cb = CubicSpline(t, np.asarray(base_acc, float)).c
    cf = CubicSpline(t, np.asarray(force, float).reshape(t.size, n_dof), axis=0).c
    return SampledSpline(jnp.asarray(t), jnp.asarray(cb), jnp.asarray(cf), n_dof=n_dof)


#: `smooth_input`'s cut-off over the input's band edge. At 1.5 the zero-phase Butterworth (order 4,
#: applied twice) took 4 % off the amplitude at the band edge and up to 2.3 % (of its peak) off a pure sine (0.25 Hz at
#: 100 Hz, interior); at 3, with the padding below, 0.01 % (0.04 % in the last seconds).
CUTOFF_OVER_BAND = 3.0
#: `smooth_input` leaves an input alone whose white noise holds less than this share of its power (above
#: 60 dB): the filter would change it more than it removes (audit: a noise-free multisine at 1 kHz, changed
#: by 0.065 % RMS, 1 % at its ends, took the exact model's free run of a crossing record to 152 %; unfiltered 0.1 %)
INPUT_NOISE_SHARE = 1e-6


def _cutoff(u: np.ndarray, dt: float) -> float | None:
    """`smooth_input`'s low-pass cut-off (Hz) for an input column, or None where it is left as it is: it is
    constant, its white noise holds less than `INPUT_NOISE_SHARE` of its power, or the cut-off is not below
    0.45 / dt."""
    u = np.asarray(u, float)
    if np.std(u) == 0 or white_share(u, dt) < INPUT_NOISE_SHARE:
        return None
    from .._recordings._derivatives import band_edge

    fc = CUTOFF_OVER_BAND * band_edge(u, dt)
    return fc if 0 < fc < 0.45 / dt else None


def white_share(u: np.ndarray, dt: float) -> float:
    """Share of the power of u (mean removed) held by its white noise floor: the periodogram's median
    over the top fifth of the band, / ln 2 (`band_edge`'s floor), over every bin."""
    from .._recordings._derivatives import _power

    freqs, p = _power(u, dt)
    if freqs.size < 10 or np.sum(p) <= 0:
        return 0.0
    return float(np.median(p[freqs >= 0.8 * freqs[-1]]) / np.log(2.0) * p.size / np.sum(p))


def smooth_input(u: np.ndarray, dt: float) -> np.ndarray:
    """Measured input without its broadband noise: zero-phase Butterworth (order 4) low-pass at
    `CUTOFF_OVER_BAND` x the input's band edge (99.5 % of its power below); a white measurement
    noise on the input would otherwise drive the simulated resonances. The record is padded (odd
    extension) by three periods of the cut-off, so the filter's start-up transient stays outside it
    (scipy's default of 15 samples left the last seconds of a 0.25 Hz sine at 100 Hz up to 97 % off).
    Columns that are zero stay zero; a column without measurable white noise (`_cutoff`) is
    returned unchanged, which the filter could only change.
    """
    u = np.asarray(u, float)
    if u.ndim == 1:
        return smooth_input(u[:, None], dt)[:, 0]
    out = u.copy()
    for k in range(u.shape[1]):
        fc = _cutoff(u[:, k], dt)
        if fc is not None:
            from scipy.signal import butter, filtfilt

            bb, aa = butter(4, fc * 2 * dt)
            out[:, k] = filtfilt(bb, aa, u[:, k], padlen=min(u.shape[0] - 1, int(np.ceil(3.0 / (fc * dt)))))
    return out
