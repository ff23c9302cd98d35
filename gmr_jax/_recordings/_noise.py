"""Measurement noise: added at a given signal-to-noise ratio, and read from a channel's spectrum."""

import numpy as np


def add_noise(signal: np.ndarray, snr_db: float, rng: np.random.Generator) -> np.ndarray:
    """Add zero-mean white Gaussian noise at `snr_db` per column.

    The signal power is that of the column's fluctuation about its mean (the vibration a sensor
    resolves), so a static equilibrium offset does not inflate the noise."""
    s = np.asarray(signal, float)
    p = np.var(s, axis=0, keepdims=s.ndim > 1)
    std = np.sqrt(p / 10 ** (snr_db / 10))
    return s + std * rng.standard_normal(s.shape)


def channel_variance(signal: np.ndarray, dt: float) -> float:
    """The variance of a channel's white noise, from its Welch spectrum's high-frequency floor:
    the mean level over the top fifth of the band (segments of 256 samples; the one-sided density
    of white noise of variance s² is 2 s² dt). The mean, not the median: a periodogram's median
    is ln 2 of its mean where few segments are averaged (a 3000-sample record: the noise 28 %
    low, the standard errors half the scatter)."""
    f, p = _welch(signal, dt)
    return float(np.mean(p[f >= 0.8 * f[-1]])) / (2.0 * dt)


def _welch(signal: np.ndarray, dt: float):
    """(f, p): the Welch spectrum of the signal, mean removed, segments of up to 256 samples
    (`channel_variance`, `white_floor`)."""
    from scipy.signal import welch

    sig = np.asarray(signal, float)
    return welch(sig - np.mean(sig), fs=1.0 / dt, nperseg=int(min(sig.size, 256)))


#: The spectrum's level over the top fifth of the band and over the fifth centred on half of it
#: may differ by at most this factor for the floor to be read as white noise (`white_floor`; the
#: band means of white noise scatter by a few per cent).
FLAT = 1.5


def white_floor(signal: np.ndarray, dt: float) -> float | None:
    """`channel_variance` where the top of the spectrum is flat, else None: its mean level over
    the top fifth of the band and over 0.4-0.6 of it within a factor `FLAT` (white noise: 1
    within its scatter; a response whose spectrum still falls there, or an anti-aliasing filter's
    roll-off, fails it, and the noise of x is then not known well enough to correct for)."""
    sig = np.asarray(signal, float)
    if sig.size < 64 or not np.all(np.isfinite(sig)):
        return None
    f, p = _welch(sig, dt)
    top, below = float(np.mean(p[f >= 0.8 * f[-1]])), float(np.mean(p[(f >= 0.4 * f[-1]) & (f < 0.6 * f[-1])]))
    if not (top > 0 and below > 0) or max(top / below, below / top) > FLAT:
        return None
    return top / (2.0 * dt)
