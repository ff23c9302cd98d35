"""Noise-aware differentiation of sampled signals.

Savitzky-Golay differentiation (local quintic least-squares fit over a sliding window, Savitzky &
Golay 1964): a polynomial smoother whose window trades noise against bias. The window is chosen
from the data when not given (`window_choice`), as the smaller of two:

- **band edge**: the odd window spanning 0.3 of the period at the signal's band edge (the
  frequency below which 99.5 % of its power above the white noise floor lies), so that a quintic follows the signal while
  averaging many samples of noise;
- **noise floor**: the window whose -3 dB cut-off (Schafer 2011: f_c / f_Nyquist ~ (p + 1) /
  (3.2 M - 4.6), window 2M + 1, p the degree) is the highest frequency at which the signal still
  stands 10 dB above its noise floor (Welch spectrum; the floor is the median level of the top
  fifth of the band). A signal whose power is at low frequency but which carries real content
  far above (a trapezoidal motion profile with sharp velocity reversals, as the EMPS drive:
  99.5 % band edge 0.44 Hz, clear of the encoder's quantisation floor up to ~250 Hz) would be
  smeared by the band-edge window (677 samples there; 13 by the noise floor).

Edges use the same fitted polynomial (scipy's `mode="interp"`).

`exclude_center` leaves each sample out of its own estimate (the polynomial is fitted to the
other 2M samples of the window): the estimate's noise is then independent of the sample's own
noise. A regression of a derived acceleration on x(t) needs that: with the sample in, the
second-derivative filter's large centre weight correlates the target's noise with the regressor's
(shallow arch, x only, 30 dB: the local stiffness 4.7-7.1 % high; left out: within 1 %).
"""

import math
from collections.abc import Sequence

import numpy as np

from .._errors import GMRInputError, as_whole_number, check_real


def dominant_period(x: np.ndarray, dt: float) -> float:
    """Period of the largest spectral peak of x (mean removed), in seconds."""
    x = np.asarray(x, float) - np.mean(x)
    spec = np.abs(np.fft.rfft(x * np.hanning(x.size)))
    freqs = np.fft.rfftfreq(x.size, dt)
    spec[0] = 0.0
    f = freqs[int(np.argmax(spec))]
    return 1.0 / f if f > 0 else x.size * dt


def _power(x: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies in Hz, Hann-windowed power of x with its mean removed; the DC bin 0)."""
    x = np.asarray(x, float) - np.mean(x)
    p = np.abs(np.fft.rfft(x * np.hanning(x.size))) ** 2
    p[0] = 0.0
    return np.fft.rfftfreq(x.size, dt), p


#: the band edge counts the power above the white noise floor (`band_edge`) where the noise holds more than this
#: share of the power the edge leaves out (1 - fraction, 0.5 %): from about 26 dB down; above, all the power
NOISE_SHARE = 0.5


def band_edge(x: np.ndarray, dt: float, fraction: float = 0.995) -> float:
    """Frequency below which `fraction` of the power of x (mean removed) above its white noise floor
    lies, in Hz. The floor, the mean level of the top fifth of the band (its periodogram's median / ln 2,
    robust to lines), is taken off every bin where the noise holds more than `NOISE_SHARE` of 1 - `fraction`
    of the power: white noise holding more than 1 - `fraction` otherwise sets the edge inside the noise, and
    the Savitzky-Golay window with it."""
    freqs, p = _power(x, dt)
    if freqs.size >= 10:
        floor = float(np.median(p[freqs >= 0.8 * freqs[-1]])) / np.log(2.0)  # white noise's periodogram: exponential
        above = p - floor
        if floor * p.size > NOISE_SHARE * (1.0 - fraction) * np.sum(p) and np.sum(above) > 0:
            c = np.cumsum(above) / np.sum(above)  # not clipped at 0: the noise's excursions cancel
            return float(freqs[int(np.argmax(c >= fraction))])
    c = np.cumsum(p) / max(np.sum(p), 1e-300)
    return float(freqs[min(int(np.searchsorted(c, fraction)), freqs.size - 1)])


#: a record with this share of its power at one line is a steady sine (`tonal_fraction`; `reconstruct`'s
#: row filter and its default structured noise are off there)
TONAL = 0.95


def tonal_fraction(x: np.ndarray, dt: float) -> float:
    """Share of the power of x (mean removed) within 5 % (at least 3 bins) of its spectral peak: near 1
    for the steady response to a sine (0.998-1 on the single-tone records of `studies/single_tone.py`),
    0.2-0.8 for a base sweep (0.7-0.82 where it dwells on a lightly damped resonance)."""
    f, p = _power(x, dt)
    k = int(np.argmax(p))
    near = np.abs(f - f[k]) <= max(0.05 * f[k], 3.0 * (f[1] - f[0]))
    return float(p[near].sum() / max(p.sum(), 1e-300))


#: the signal must stand this far above the noise floor (power ratio, 10 dB) to set the cut-off
FLOOR_RATIO = 10.0


def floor_spectrum(x: np.ndarray, dt: float, nperseg: int, smooth: int, detrend: str = "constant"):
    """(f, p, floor): the Welch spectrum of x (segments of up to `nperseg` samples, each
    detrended by `detrend`), smoothed by a running median over `smooth` bins (against isolated
    lines), and its noise floor, the median level of the top fifth of the band."""
    from scipy.ndimage import median_filter
    from scipy.signal import welch

    f, p = welch(x, fs=1.0 / dt, nperseg=int(min(x.size, nperseg)), detrend=detrend)
    p = median_filter(p, size=smooth, mode="nearest")
    return f, p, float(np.median(p[f >= 0.8 * f[-1]]))


def noise_cutoff(x: np.ndarray, dt: float, f_band: float | None = None) -> float:
    """Frequency (Hz) at which the Welch spectrum of x (mean removed; segments of up to 2048
    samples, running median over 9 bins against isolated lines) first falls below `FLOOR_RATIO`
    times the noise floor (the median level of the top fifth of the band), searching upwards
    from the 99.5 % band edge (`f_band`, computed when not given); the Nyquist frequency when it
    never does."""
    x = np.asarray(x, float)
    x = x - np.mean(x)
    f, p, floor = floor_spectrum(x, dt, 2048, 9)
    if f.size < 10:
        return float(f[-1])
    f_band = band_edge(x, dt) if f_band is None else f_band
    below = np.nonzero((p < FLOOR_RATIO * floor) & (f >= f_band))[0]
    return float(f[below[0]]) if below.size else float(f[-1])


def _odd_window(w: float, n: int, polyorder: int) -> int:
    w = max(int(round(w)), polyorder + 2)
    w = min(w, n - (1 - n % 2))
    return w if w % 2 == 1 else w + 1


def window_choice(x: np.ndarray, dt: float, polyorder: int = 5) -> dict:
    """The automatic Savitzky-Golay window of x and why (module docstring): `window`, `rule`
    ("band edge" or "noise floor"), `band_edge_hz`, `noise_cutoff_hz` and both windows."""
    x = np.asarray(x, float)
    f = band_edge(x, dt)
    period = 1.0 / f if f > 0 else dominant_period(x, dt)
    w_band = _odd_window(0.3 * period / dt, x.size, polyorder)
    fc = noise_cutoff(x, dt, f)
    frac = min(fc * 2 * dt, 1.0)
    w_noise = _odd_window(2 * (((polyorder + 1) / max(frac, 1e-12) + 4.6) / 3.2) + 1, x.size, polyorder)
    rule = "noise floor" if w_noise < w_band else "band edge"
    return {"window": min(w_band, w_noise), "rule": rule, "band_edge_hz": f, "noise_cutoff_hz": fc,
            "band_edge_window": w_band, "noise_floor_window": w_noise}


def auto_window(x: np.ndarray, dt: float, polyorder: int = 5) -> int:
    """The automatic Savitzky-Golay window of x (samples, odd): `window_choice`."""
    return window_choice(x, dt, polyorder)["window"]


def savgol_taps(window: int, polyorder: int, order: int, dt: float, exclude_center: bool = False) -> np.ndarray:
    """The (window,) taps h of the Savitzky-Golay estimate of d^order x / dt^order at a window's
    centre: estimate[t] = sum_j h[j] x[t + j - window // 2]. With `exclude_center`, the centre
    sample is left out of the fit (its tap is 0; module docstring)."""
    half = window // 2
    k = np.arange(-half, half + 1, dtype=float)
    keep = k != 0 if exclude_center else np.ones(window, bool)
    vander = np.vander(k[keep], polyorder + 1, increasing=True)
    taps = np.zeros(window)
    taps[keep] = np.linalg.pinv(vander)[order] * math.factorial(order) / dt**order
    return taps


def filter_gain(sig: np.ndarray, taps: np.ndarray, order: int, dt: float) -> np.ndarray:
    """`sig` (N,) or (N, p) through the gain G(w) = H(w) / (i w)^order of the Savitzky-Golay taps of
    a derivative of `order` (H their frequency response; G(0) = 1): what the differentiation did to the
    derivative it estimated. On the mirror-extended record (no edge jump), by FFT, along axis 0."""
    sig = np.asarray(sig, float)
    n = sig.shape[0]
    ext = np.concatenate([sig, sig[::-1]], axis=0)
    w = 2.0 * np.pi * np.fft.rfftfreq(2 * n, dt)
    half = taps.size // 2
    lag = np.arange(-half, half + 1) * dt
    if order == 2:
        h = np.cos(np.outer(w, lag)) @ taps
        gain = np.divide(h, -(w**2), out=np.ones_like(w), where=w > 0)
    else:
        h = np.sin(np.outer(w, lag)) @ taps
        gain = np.divide(h, w, out=np.ones_like(w), where=w > 0)
    spec = np.fft.rfft(ext, axis=0) * (gain if sig.ndim == 1 else gain[:, None])
    return np.fft.irfft(spec, n=2 * n, axis=0)[:n]


def apply_gain(segs, a: np.ndarray) -> np.ndarray:
    """`a` (samples, ...) of one well with each record's rows through its filter's gain (`filter_gain`;
    `segs` one well's list of (start, stop, dt, taps, order), as `_reconstruct/_filter_gain.gain_segments` gives it), padding and records without one left as they are."""
    out = np.array(a, float)
    for seg in segs:
        if seg is not None:
            start, stop, dt, taps, order = seg
            out[start:stop] = filter_gain(out[start:stop], taps, order, dt)
    return out


def differentiate(
    x: np.ndarray, dt: float, order: int = 1, window: "int | Sequence[int | None] | None" = None,
    polyorder: int = 5, exclude_center: bool = False,
) -> np.ndarray:
    """d^order x / dt^order along axis 0 by Savitzky-Golay differentiation.

    `window` (odd, samples) defaults to `auto_window` of each column; a sequence gives one per
    column (None: that column's automatic window). `exclude_center`: each
    sample's estimate leaves that sample out (module docstring; the first and last window // 2
    samples keep scipy's edge fit). A wrong argument (NaN in x, dt <= 0, a window not odd or
    longer than x, a constant column with the automatic window) raises `GMRInputError`.

    Examples:
        >>> import numpy as np
        >>> import gmr_jax as gmr
        >>> t = np.arange(2001) * 1e-3
        >>> v = gmr.differentiate(np.sin(2 * np.pi * t), 1e-3)        # d/dt sin(2 pi t)
        >>> bool(np.max(np.abs(v - 2 * np.pi * np.cos(2 * np.pi * t))) < 1e-6)
        True
    """
    xa = np.asarray(x)
    if xa.dtype.kind not in "iuf" or isinstance(x, (bool, np.bool_)):
        raise GMRInputError(f"differentiate: x must be an array of real numbers, got dtype {xa.dtype}")
    x = xa.astype(float)
    if x.ndim == 1:
        return differentiate(x[:, None], dt, order, window, polyorder, exclude_center)[:, 0]
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
    windows = list(window) if isinstance(window, (list, tuple, np.ndarray)) else [window] * x.shape[1]
    if len(windows) != x.shape[1]:
        raise GMRInputError(f"differentiate: {len(windows)} windows for {x.shape[1]} columns; give one per "
                            f"column, one for all, or None")
    for k, wk in enumerate(windows):
        if wk is not None:
            wk = windows[k] = as_whole_number(wk, "differentiate: window", lo=polyorder + 1,
                                              fix="give an odd number of samples larger than polyorder, or None")
            if wk % 2 == 0 or wk > n:
                raise GMRInputError(f"differentiate: window must be odd and at most {n} (the samples), got {wk}")
    from scipy.signal import savgol_filter as _savgol  # imported here: scipy.signal costs ~0.5 s at start-up

    out = np.empty_like(x)
    for k in range(x.shape[1]):
        if windows[k] is None and np.ptp(x[:, k]) == 0:
            raise GMRInputError(f"differentiate: x of column {k} is constant: no signal to set the window "
                                f"from (nothing to fit); pass window=, or drop that column")
        w = windows[k] or auto_window(x[:, k], dt, polyorder)
        out[:, k] = _savgol(x[:, k], w, polyorder, deriv=order, delta=dt, mode="interp")
        if exclude_center and n > w:
            half = w // 2
            out[half:n - half, k] = np.correlate(x[:, k], savgol_taps(w, polyorder, order, dt, True), mode="valid")
    return out
