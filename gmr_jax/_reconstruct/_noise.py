"""The noise of each well's regression target where the accelerations were estimated
(`_fit/_target_noise.py`): which differentiation filters it went through and how loud each
channel is."""

import jax.numpy as jnp
import numpy as np

from .._fit._target_noise import TargetNoise
from .._recordings._derivatives import savgol_taps


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


def _response(topology, masses: np.ndarray, d: int, i: int):
    """How the force carried by DOF `i` (the target) moves with a unit x'' of each column (D,),
    a unit base acceleration, and a unit force on each mass (D,)."""
    eye = np.eye(d)
    xdd = np.asarray(topology.carried(-np.asarray(topology.absolute(eye, np.zeros(d))) * masses[None, :]))[:, i]
    base = float(np.asarray(topology.carried(-np.asarray(topology.absolute(np.zeros((1, d)), np.ones(1)))
                                            * masses[None, :]))[0, i])
    force = np.asarray(topology.carried(eye))[:, i]
    return xdd, base, force


def well_noise(recs, group: list[int], i: int, masses: np.ndarray, topology) -> TargetNoise | None:
    """The `TargetNoise` of DOF `i`'s target at one well (the recordings `group`), or None where
    a recording of it carries measured accelerations (white noise: the ordinary covariance).

    Each differentiated column j contributes its Savitzky-Golay taps (as `complete` applied
    them) times the target's response to x''_j, on white noise of that channel's floor
    variance; the measured base acceleration and forces add white noise. Several recordings
    of one well: each with its share of the samples."""
    total = sum(recs[k].n_samples for k in group)
    d = recs[group[0]].n_dof
    resp_xdd, resp_b, resp_f = _response(topology, np.asarray(masses, float), d, i)
    taps, variances, white = [], [], 0.0
    for k in group:
        r = recs[k]
        how = (r.derivation or {}).get("a")
        if how is None:
            return None
        share, dt = r.n_samples / total, r.dt
        src = r.v if how["from"] == "v" else r.x
        for j in range(d):
            if resp_xdd[j] == 0.0 or how["windows"][j] is None:
                continue
            taps.append(resp_xdd[j] * savgol_taps(how["windows"][j], how["polyorder"], how["order"], dt,
                                                  how["exclude_center"]))
            variances.append(share * channel_variance(src[:, j], dt))
        if r.base_acc is not None and resp_b != 0.0:
            white += share * resp_b**2 * channel_variance(r.base_acc, dt)
        if r.force is not None:
            white += share * sum(resp_f[j] ** 2 * channel_variance(r.force[:, j], dt)
                                 for j in range(d) if resp_f[j] != 0.0 and np.ptp(r.force[:, j]) > 0)
    if not taps:
        return None
    width = max(t.size for t in taps)
    padded = np.stack([np.pad(t, ((width - t.size) // 2,) * 2) for t in taps])
    return TargetNoise(taps=jnp.asarray(padded), variances=jnp.asarray(variances, float),
                       white=jnp.asarray(white, float))


def _pooled_floor(recs, group: list[int], i: int, channel: str, usable) -> float | None:
    """The white floor (`white_floor`) of DOF `i`'s `channel` ("x" or "v") over the recordings `group`,
    pooled by samples; None where `usable(recording)` is False for any, or any floor is not white."""
    total, var = 0, 0.0
    for k in group:
        r = recs[k]
        if not usable(r):
            return None
        floor = white_floor(getattr(r, channel)[:, i], r.dt)
        if floor is None:
            return None
        total += r.n_samples
        var += r.n_samples * floor
    return var / total if total else None


def _a_from(r) -> str | None:
    """The channel a recording's accelerations were estimated from, None where measured."""
    how = (r.derivation or {}).get("a")
    return None if how is None else how["from"]


def x_noise_variance(recs, group: list[int], i: int) -> float | None:
    """The variance of the white noise on DOF `i`'s measured displacement at one well (the
    recordings `group`; each channel's Welch floor, `channel_variance`, pooled by samples), for
    the errors-in-variables correction of its local fit (`_fit/_errors_in_variables.py`). None
    where that correction does not hold: x estimated (integrated), or accelerations estimated
    from x (their noise is the noise of x, filtered: not independent of it)."""
    return _pooled_floor(recs, group, i, "x", lambda r: "x" not in r.derived and _a_from(r) != "x")


def v_noise_variance(recs, group: list[int], i: int) -> float | None:
    """The variance of the white noise on DOF `i`'s measured velocity at one well (as
    `x_noise_variance`), for the joint regression's velocity columns (`_joint._velocity_noise`).
    None where that correction does not hold: v estimated (from x, or integrated from a), x
    integrated from v, or accelerations estimated from v (their noise is the noise of v)."""
    return _pooled_floor(recs, group, i, "v", lambda r: r.v is not None and "v" not in r.derived
                         and "x" not in r.derived and _a_from(r) != "v")


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
