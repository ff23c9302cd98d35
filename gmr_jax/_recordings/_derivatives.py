"""Noise-aware differentiation of sampled signals.

Savitzky-Golay differentiation (local quintic least-squares fit over a sliding window, Savitzky &
Golay 1964): a polynomial smoother whose window trades noise against bias. The window is chosen
from the data when not given: the odd window spanning 0.3 of the
period at the signal's band edge (the frequency below which 99.5 % of its power lies), so that a quintic follows the signal while averaging
many samples of noise. Edges use the same fitted polynomial (scipy's `mode="interp"`).
"""

import numpy as np
from scipy.signal import savgol_filter

from .._errors import GMRInputError, as_whole_number, check_real


def dominant_period(x: np.ndarray, dt: float) -> float:
    """Period of the largest spectral peak of x (mean removed), in seconds."""
    x = np.asarray(x, float) - np.mean(x)
    spec = np.abs(np.fft.rfft(x * np.hanning(x.size)))
    freqs = np.fft.rfftfreq(x.size, dt)
    spec[0] = 0.0
    f = freqs[int(np.argmax(spec))]
    return 1.0 / f if f > 0 else x.size * dt


def band_edge(x: np.ndarray, dt: float, fraction: float = 0.995) -> float:
    """Frequency below which `fraction` of the power of x (mean removed) lies, in Hz."""
    x = np.asarray(x, float) - np.mean(x)
    p = np.abs(np.fft.rfft(x * np.hanning(x.size))) ** 2
    p[0] = 0.0
    c = np.cumsum(p) / max(np.sum(p), 1e-300)
    freqs = np.fft.rfftfreq(x.size, dt)
    return float(freqs[min(int(np.searchsorted(c, fraction)), freqs.size - 1)])


def auto_window(x: np.ndarray, dt: float, polyorder: int = 5) -> int:
    f = band_edge(x, dt)
    period = 1.0 / f if f > 0 else dominant_period(x, dt)
    w = int(round(0.3 * period / dt))
    w = max(w, polyorder + 2)
    w = min(w, x.size - (1 - x.size % 2))
    return w if w % 2 == 1 else w + 1


def differentiate(
    x: np.ndarray, dt: float, order: int = 1, window: int | None = None, polyorder: int = 5
) -> np.ndarray:
    """d^order x / dt^order along axis 0 by Savitzky-Golay differentiation.

    `window` (odd, samples) defaults to `auto_window` of each column. A wrong argument (NaN in x,
    dt <= 0, a window not odd or longer than x, a constant column with the automatic window)
    raises `GMRInputError`."""
    xa = np.asarray(x)
    if xa.dtype.kind not in "iuf" or isinstance(x, (bool, np.bool_)):
        raise GMRInputError(f"differentiate: x must be an array of real numbers, got dtype {xa.dtype}")
    x = xa.astype(float)
    if x.ndim == 1:
        return differentiate(x[:, None], dt, order, window, polyorder)[:, 0]
    if x.ndim != 2:
        raise GMRInputError(f"differentiate: x must be (N,) or (N, D), got shape {x.shape}")
    check_real(dt, "differentiate: dt", lo=0.0, lo_open=True, fix="give the sampling step in seconds")
    order = as_whole_number(order, "differentiate: order", lo=0)
    polyorder = as_whole_number(polyorder, "differentiate: polyorder", lo=max(order, 1))
    n = x.shape[0]
    if n < polyorder + 2:
        raise GMRInputError(f"differentiate: x has {n} samples; at least {polyorder + 2} are needed for a "
                            f"degree-{polyorder} fit (record longer)")
    if not np.all(np.isfinite(x)):
        i, k = np.argwhere(~np.isfinite(x))[0]
        raise GMRInputError(f"differentiate: x has NaN/inf (first at sample {i}, column {k}); remove or "
                            f"interpolate them first")
    if window is not None:
        window = as_whole_number(window, "differentiate: window", lo=polyorder + 1,
                                 fix="give an odd number of samples larger than polyorder, or None")
        if window % 2 == 0 or window > n:
            raise GMRInputError(f"differentiate: window must be odd and at most {n} (the samples), got {window}")
    out = np.empty_like(x)
    for k in range(x.shape[1]):
        if window is None and np.ptp(x[:, k]) == 0:
            raise GMRInputError(f"differentiate: x of column {k} is constant: no signal to set the window "
                                f"from (nothing to fit); pass window=, or drop that column")
        w = window or auto_window(x[:, k], dt, polyorder)
        out[:, k] = savgol_filter(x[:, k], w, polyorder, deriv=order, delta=dt, mode="interp")
    return out
