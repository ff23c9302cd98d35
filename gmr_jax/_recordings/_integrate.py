"""Displacement from velocity- or acceleration-only sensors (a laser vibrometer, accelerometers).

A recording may carry `v` or `a` without `x` (contracts). The missing displacement (and, from an
acceleration, the velocity) is integrated, per column:

1. integrate by the interpolating cubic spline's antiderivative (for `a`, the acceleration relative to the
   base, a - base_acc);
2. remove the least-squares polynomial of the integration's degree (a line for v -> x, a
   parabola for a -> x: the unknown initial values, and what a sensor's bias integrates to);
3. remove the drift: zero the content below `f_hp` (cosine transform of the record, i.e. the
   Fourier series of its mirror extension: no edge transient, no phase shift), with
   `f_hp` = `HP_FRACTION` x the measured signal's low edge: going down from the peak of its
   Welch spectrum, the last frequency at which it stands 10 dB per integration (v: 10 dB,
   a: 20 dB; the error of each integration grows as 1/f) above its noise floor (the median level of the top fifth
   of the band, as `_derivatives.noise_cutoff`); never below 3 / record length. Below that
   frequency the integral would be the integrated noise (a random walk), not the motion.

Content below `f_hp` (a static offset, a slow creep) is not recoverable from v or a and is
removed; the cut-off is reported (`Recording.integration`). The result has zero mean: the static
position the record vibrates about (its equilibrium) is unobservable. It is placed at
`equilibrium` when given; otherwise the recording says so (`integration["equilibrium"]`), a fit
refuses it, and `discover` estimates it from the model (see `_discover`).

An acceleration-only recording integrates a - base_acc, the displacement of each mass relative
to the base; `Recording.complete(topology)` turns those into the cell deformations of a chain.
"""

import numpy as np

from .._errors import GMRInputError
from ._derivatives import FLOOR_RATIO, floor_spectrum

#: the drift cut-off as a fraction of the measured signal's low edge
HP_FRACTION = 0.8


def low_edge(s: np.ndarray, dt: float, ratio: float = FLOOR_RATIO) -> float:
    """Low edge (Hz) of the band that holds s: from the peak of its Welch spectrum (segments of
    up to 4096 samples, each with its straight line removed; running median over 5 bins) down
    to the last frequency where it still stands `ratio` x above its noise floor (a slow
    disturbance below a gap is not followed)."""
    f, p, floor = floor_spectrum(np.asarray(s, float), dt, 4096, 5, detrend="linear")
    k = int(np.argmax(np.where(np.arange(f.size) >= 2, p, 0.0)))
    while k > 2 and p[k - 1] >= ratio * floor:
        k -= 1
    return float(f[k])


def highpass_cutoff(s: np.ndarray, dt: float, times: int = 1) -> float:
    """The drift-removal cut-off (Hz) for integrating the measured signal s `times` times
    (module docstring): the margin over the noise floor is 10 dB per integration."""
    n = np.shape(s)[0]
    return float(min(max(HP_FRACTION * low_edge(s, dt, FLOOR_RATIO**times), 3.0 / (n * dt)), 0.2 / dt))


def remove_drift(y: np.ndarray, dt: float, f_hp: float, keep_mean: bool = False) -> np.ndarray:
    """y (N,) or (N, p) without its content below `f_hp`, along axis 0: the cosine-transform (DCT-II)
    coefficients of frequency k / (2 N dt) < f_hp are zeroed (with `keep_mean`, all but k = 0: the
    band between 0 and `f_hp` goes, the mean stays). The DCT is the
    Fourier series of the record extended by its mirror image, which is continuous at both ends: no
    edge transient (a recursive high-pass this far below the sampling rate rings for most of a
    record), no phase."""
    from scipy.fft import dct, idct

    c = dct(np.asarray(y, float), type=2, norm="ortho", axis=0)
    k = np.arange(c.shape[0]) / (2.0 * c.shape[0] * dt)
    c[(k < f_hp) & ((k > 0) if keep_mean else True)] = 0.0
    return idct(c, type=2, norm="ortho", axis=0)


def detrend(y: np.ndarray, degree: int) -> np.ndarray:
    """y without its least-squares polynomial of `degree` (Legendre basis on the record)."""
    u = np.linspace(-1.0, 1.0, y.size)
    V = np.polynomial.legendre.legvander(u, degree)
    return y - V @ np.linalg.lstsq(V, y, rcond=None)[0]


def integrate(s: np.ndarray, dt: float, f_hp: float, times: int = 1) -> np.ndarray:
    """The drift-free `times`-fold integral of s (N,) (module docstring): integrate `times`
    times by the interpolating cubic spline's antiderivative (error O(dt^4); the cumulative trapezoid's gain
    at frequency f, 1 - (2 pi f dt)^2 / 12, biases a local cubic by its share of the force), remove the
    least-squares polynomial of degree `times` (the unknown initial values and what a sensor's bias integrates
    to), then the content below `f_hp`."""
    from scipy.interpolate import CubicSpline

    y = np.asarray(s, float)
    t = dt * np.arange(y.shape[0])
    for _ in range(times):
        y = CubicSpline(t, y).antiderivative()(t)
    return remove_drift(detrend(y, times), dt, f_hp)


def integrated_signals(t, v, a, base_acc, src: str):
    """(x, v or None when v was measured, info) from a recording's measured v or a (module
    docstring); info per DOF: the source, the cut-off used and the samples."""
    t = np.asarray(t, float)
    n = t.shape[0]
    source, s = ("v", v) if v is not None else ("a", a)
    s = np.asarray(s, float)
    if n < 16:
        raise GMRInputError(f"{src}: only {n} samples: too few to integrate '{source}' into a displacement")
    for key, val in ((source, s), ("base_acc", base_acc), ("t", t)):
        if val is not None and not np.all(np.isfinite(val)):
            bad = int(np.sum(~np.isfinite(val)))
            raise GMRInputError(f"{src}: '{key}' has {bad} NaN/inf value(s); remove or interpolate them "
                                f"before '{source}' can be integrated into a displacement")
    dt = float((t[-1] - t[0]) / (n - 1))
    if not dt > 0:
        raise GMRInputError(f"{src}: 't' is not increasing; cannot integrate '{source}'")
    times = 2 if source == "a" else 1
    if source == "a" and base_acc is not None:
        s = s - np.asarray(base_acc, float).reshape(-1)[:, None]
    cut = [highpass_cutoff(s[:, k], dt, times) for k in range(s.shape[1])]
    x = np.stack([integrate(s[:, k], dt, cut[k], times) for k in range(s.shape[1])], 1)
    # from a, v and x are each integrated from a: x is not the integral of the drift-removed v
    v_out = np.stack([integrate(s[:, k], dt, cut[k], 1) for k in range(s.shape[1])], 1) if times == 2 else None
    info = {"from": source, "f_highpass_hz": cut,
            "method": ("cubic-spline antiderivative, least-squares polynomial and cosine-transform content below a cut-off "
                       f"removed; cut-off {HP_FRACTION:.3g} x the low edge of the band where '{source}' stands "
                       f"{10 * times} dB above its noise floor" + (" (twice: a -> v -> x)" if times == 2 else "")),
            "coordinates": ("displacement of each mass relative to the base" if source == "a"
                            else "as v (cell deformations for a chain)"),
            # from a: the mass displacements until `Recording.complete` has applied a topology
            "topology": None}
    return x, v_out, info
