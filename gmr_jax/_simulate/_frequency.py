"""Frequency response: displacement transmissibility under harmonic base motion (paper Eq. 24)."""

import diffrax as dfx
import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._model._model import AbstractMechanicalModel
from .._solution import RESULTS, Solution, error_if_failed, first_failure
from ._inputs import BaseSine
from ._integrate import Integrator, integrate, vector_field

#: Tolerances of the frequency sweeps: the transient must die out to well below the response.
SWEEP_INTEGRATOR = Integrator(rtol=1e-7, atol=1e-10, max_steps=400_000)


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
    integrator: Integrator = SWEEP_INTEGRATOR,
    throw: bool = True,
) -> Solution:
    """T_d = 20 log10(X_tip / X_b) (Eq. 24) at each frequency, one vmapped diffrax solve.

    Harmonic base displacement `amplitude`·sin(2π f t), starting at rest at `x_eq`. After
    max(`n_settle` periods, `min_settle_time`) the amplitude of the tip's absolute displacement
    (base plus the last mass's displacement, `AbstractTopology.tip`) at the excitation frequency
    (its first Fourier coefficient over `n_measure` whole periods, 64 samples per period) is
    measured: what is left of the start-up transient of a lightly damped low mode is at another
    frequency and drops out.

    **Returns:** a `Solution` with `value = (T_d (nf,) in dB, tip amplitude (nf,))`, `result`
    the first failure over the frequencies (`successful` if none), and `stats["results"]`
    (nf,) the code of each frequency (its T_d is NaN when it failed).
    """

    def one(f):
        period = 1.0 / f
        t_settle = jnp.maximum(n_settle * period, min_settle_time)
        exc = BaseSine(amplitude, f, n_dof=model.n_dof)
        ts = t_settle + jnp.arange(64 * n_measure) * (period / 64)
        x_eq0 = jnp.asarray(x_eq, float)
        traj = integrate(vector_field(model, exc), 0.0, ts[-1], (x_eq0, jnp.zeros_like(x_eq0)), integrator,
                         saveat=dfx.SaveAt(ts=ts))
        base = amplitude * jnp.sin(2 * jnp.pi * f * ts)
        tip = base + model.topology.tip(traj.ys[0])
        phase = 2 * jnp.pi * f * ts
        amp = 2 * jnp.abs(jnp.mean(tip * jnp.exp(-1j * phase)))
        good = traj.result == RESULTS.successful
        return jnp.where(good, 20 * jnp.log10(amp / amplitude), jnp.nan), jnp.where(good, amp, jnp.nan), traj.result

    td, amp, codes = jax.vmap(one)(jnp.asarray(frequencies, float))
    sol = Solution(value=(td, amp), result=first_failure(codes), stats={"results": codes._value})
    return error_if_failed(sol, throw)


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
    sol = transmissibility(model, jnp.asarray(freqs), amplitude, jnp.asarray(x_eq, float), throw=False, **kwargs)
    td = np.asarray(sol.value[0])
    ok = sol.result == RESULTS.successful
    coarse = resonance_frequencies(freqs, td, prominence_db)
    if not coarse:
        return td, [], bool(ok)
    bands = np.stack([np.linspace(f * (1 - zoom), f * (1 + zoom), n_zoom) for f in coarse])
    zsol = transmissibility(model, jnp.asarray(bands.reshape(-1)), amplitude, jnp.asarray(x_eq, float),
                            throw=False, **kwargs)
    ztd = np.asarray(zsol.value[0]).reshape(bands.shape)
    ok = bool(ok & (zsol.result == RESULTS.successful))
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
