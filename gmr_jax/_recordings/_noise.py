"""Measurement noise at a given signal-to-noise ratio."""

import numpy as np


def add_noise(signal: np.ndarray, snr_db: float, rng: np.random.Generator) -> np.ndarray:
    """Add zero-mean white Gaussian noise at `snr_db` per column.

    The signal power is that of the column's fluctuation about its mean (the vibration a sensor
    resolves), so a static equilibrium offset does not inflate the noise."""
    s = np.asarray(signal, float)
    p = np.var(s, axis=0, keepdims=s.ndim > 1)
    std = np.sqrt(p / 10 ** (snr_db / 10))
    return s + std * rng.standard_normal(s.shape)
