"""Frequency response: displacement transmissibility under harmonic base motion (paper Eq. 24)."""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._solution import RESULTS
from ..model._model import AbstractMechanicalModel
from ._inputs import BaseSine
from ._simulate import _vector_field


@eqx.filter_jit
def transmissibility(
    model: AbstractMechanicalModel,
    frequencies: Float[Array, " nf"],
    amplitude: float,
    x_eq: Float[Array, " dof"],
    *,
    n_settle: int = 30,
    n_measure: int = 10,
    min_settle_time: float = 60.0,
    rtol: float = 1e-7,
    atol: float = 1e-10,
):
    """T_d = 20 log10(X_tip / X_b) (Eq. 24) at each frequency, one vmapped diffrax solve.

    Harmonic base displacement `amplitude`·sin(2π f t), starting at rest at `x_eq`. After
    max(`n_settle` periods, `min_settle_time`) the amplitude of the tip's absolute displacement
    (base plus all cell deformations) at the excitation frequency (its first Fourier coefficient
    over `n_measure` whole periods, 64 samples per period) is measured: what is left of the
    start-up transient of a lightly damped low mode is at another frequency and drops out.
    Returns (T_d (nf,) in dB, tip amplitude (nf,), result codes).
    """

    def one(f):
        period = 1.0 / f
        t_settle = jnp.maximum(n_settle * period, min_settle_time)
        exc = BaseSine(amplitude, f, n_dof=model.n_dof)
        ts = t_settle + jnp.arange(64 * n_measure) * (period / 64)

        sol = dfx.diffeqsolve(
            dfx.ODETerm(_vector_field(model, exc)), dfx.Tsit5(), 0.0, ts[-1], None, (x_eq, jnp.zeros_like(x_eq)),
            saveat=dfx.SaveAt(ts=ts), stepsize_controller=dfx.PIDController(rtol=rtol, atol=atol),
            max_steps=400_000, throw=False,
        )
        base = amplitude * jnp.sin(2 * jnp.pi * f * ts)
        tip = base + jnp.sum(sol.ys[0], axis=1) if model.topology == "chain" else base + sol.ys[0][:, -1]
        phase = 2 * jnp.pi * f * ts
        amp = 2 * jnp.abs(jnp.mean(tip * jnp.exp(-1j * phase)))
        ok = sol.result == dfx.RESULTS.successful
        code = jnp.where(ok, RESULTS.successful._value, RESULTS.simulation_failed._value)
        return 20 * jnp.log10(amp / amplitude), amp, code

    return jax.vmap(one)(jnp.asarray(frequencies, float))


def resonance_frequencies(freqs, td_db, prominence_db: float = 1.0):
    """Frequencies of the local maxima of a transmissibility curve (parabolic refinement)."""
    import numpy as np

    f = np.asarray(freqs)
    y = np.asarray(td_db)
    out = []
    for k in range(1, len(y) - 1):
        if y[k] > y[k - 1] and y[k] >= y[k + 1] and y[k] - min(y[max(0, k - 5):k + 6]) > prominence_db:
            den = y[k - 1] - 2 * y[k] + y[k + 1]
            off = 0.5 * (y[k - 1] - y[k + 1]) / den if den != 0 else 0.0
            out.append(float(f[k] + off * (f[k + 1] - f[k - 1]) / 2))
    return out


def resonance_peaks(model, freqs, amplitude, x_eq, *, zoom: float = 0.03, n_zoom: int = 41,
                    prominence_db: float = 1.0, **kwargs):
    """Resonance frequencies of `model` about `x_eq` from its transmissibility (Eq. 24).

    The curve on `freqs` locates the peaks (`resonance_frequencies`); each is then refined on
    its own +-`zoom` band of `n_zoom` frequencies (parabola through the top three points).
    **Returns:** (T_d on `freqs` (dB), refined peak frequencies (list), all solves succeeded).
    Extra keyword arguments go to `transmissibility`."""
    import numpy as np

    freqs = np.asarray(freqs, float)
    td, _, code = transmissibility(model, jnp.asarray(freqs), amplitude, jnp.asarray(x_eq, float), **kwargs)
    td = np.asarray(td)
    ok = bool(np.all(np.asarray(code) == RESULTS.successful._value))
    coarse = resonance_frequencies(freqs, td, prominence_db)
    if not coarse:
        return td, [], ok
    bands = np.stack([np.linspace(f * (1 - zoom), f * (1 + zoom), n_zoom) for f in coarse])
    ztd, _, zcode = transmissibility(model, jnp.asarray(bands.reshape(-1)), amplitude,
                                     jnp.asarray(x_eq, float), **kwargs)
    ztd = np.asarray(ztd).reshape(bands.shape)
    ok = ok and bool(np.all(np.asarray(zcode) == RESULTS.successful._value))
    peaks = []
    for band, row in zip(bands, ztd):
        k = int(np.argmax(row))
        if 0 < k < n_zoom - 1:
            den = row[k - 1] - 2 * row[k] + row[k + 1]
            off = 0.5 * (row[k - 1] - row[k + 1]) / den if den != 0 else 0.0
            peaks.append(float(band[k] + off * (band[1] - band[0])))
        else:
            peaks.append(float(band[k]))
    return td, peaks, ok
