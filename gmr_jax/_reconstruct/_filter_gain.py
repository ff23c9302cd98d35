"""The differentiation filter's gain and the noise it shares with the regression columns.

A Savitzky-Golay estimate of x'' (or of a from v) is G[x''], G = H(w) / (i w)^k of its taps: not 1 on the
harmonics of a nonlinear response. The local regressions (`_slow.band_rows`) pass their library columns and
the target's measured inputs through the same G, so the equation holds again (`filter_gain`); on steady
sines the joint regression's columns do too (`gain_segments`, `apply_gain`, `matched_targets`). Where x was
measured and the accelerations estimated from it, the filtered columns carry the noise of x that the target
carries, differentiated: `cross_moment` gives its expected product with the target's noise, which the local
fits take off their normal equations (`_fit/_errors_in_variables.shifted_qr`).
"""

import numpy as np

from .._recordings._derivatives import filter_gain


def impulse_response(taps: np.ndarray, order: int, dt: float) -> np.ndarray:
    """The taps g (odd length, as `taps`) of `filter_gain`'s filter: G[c](t) = sum_l g(l) c(t + l), l from
    -half to half. G = H / (i w)^k is the kernel h integrated k times, g(l) = dt^2 / 2 sum_m h(m) |l - m| for
    k = 2 and dt / 2 sum_m h(m) sgn(l - m) for k = 1 (the Green's functions of d^k/dt^k); the low moments of
    the Savitzky-Golay taps vanish, so g is zero outside their window."""
    half = taps.size // 2
    lag = np.arange(-half, half + 1)
    d = lag[:, None] - lag[None, :]
    green = 0.5 * dt**2 * np.abs(d) if order == 2 else -0.5 * dt * np.sign(d)
    return green @ np.asarray(taps, float)


def _correlate(a: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """sum_l kernel(l) a(t + l) along axis 0 (kernel centred, odd length; zeros beyond the ends)."""
    from scipy.signal import fftconvolve

    return fftconvolve(a, kernel[::-1].reshape((-1,) + (1,) * (a.ndim - 1)), mode="same", axes=0)


def cross_moment(rec, i: int, q: np.ndarray, weights: np.ndarray, library, through: np.ndarray,
                 resp: float, h: np.ndarray) -> np.ndarray | None:
    """(terms,): sum over the samples of `weights` times the expected product of each library column's noise
    with the target's, to first order in the noise of x, where the record's accelerations were estimated from a
    measured x (None elsewhere). The target holds resp h * (x + n) (h the second-derivative taps); a column
    phi(q, v) (through G where `through`) moves by G[d phi / dq n + d phi / dv h1 * n] where v was estimated
    from x too (h1 its first-derivative taps), so E[dc(t) dy(t)] = resp s^2 (sum_l g(l) h(l) dphi/dq(t + l)
    + sum_l g(l) c1(l) dphi/dv(t + l)), c1(l) = sum_s h1(s) h(l + s), g = delta for a raw column. Raw q with
    the centre tap in (steady sines): s^2 h(0); through G the spread of G carries it at every lag. `h`: the
    record's second-derivative taps (`_taps`)."""
    import jax
    import jax.numpy as jnp

    from .._recordings._derivatives import savgol_taps
    from ._noise import channel_variance

    how = (rec.derivation or {}).get("a")
    if how is None or how["from"] != "x" or "x" in rec.derived:
        return None
    dt = rec.dt
    half = h.size // 2
    s2 = channel_variance(rec.x[:, i], dt)
    v = jnp.asarray(rec.v[:, i])
    qj = jnp.asarray(q)
    dq = np.asarray(jax.jvp(lambda z: library(z, v), (qj,), (jnp.ones_like(qj),))[1], float)
    g = impulse_response(h, 2, dt)
    kq = np.where(through[None, :], (g * h)[:, None], 0.0)
    kq[half] = np.where(through, g[half] * h[half], h[half])
    out = np.sum(weights[:, None] * np.stack([_correlate(dq[:, k], kq[:, k]) for k in range(dq.shape[1])], 1), 0)
    if "v" in rec.derived:
        h1 = savgol_taps(how["windows"][i], how["polyorder"], 1, dt)
        dv = np.asarray(jax.jvp(lambda z: library(qj, z), (v,), (jnp.ones_like(v),))[1], float)
        c1 = np.array([np.dot(h1[max(0, -l):h1.size - max(0, l)], h[max(0, l):h.size - max(0, -l)])
                       for l in range(-half, half + 1)])
        kv = g * c1  # raw columns: c1(0) = 0 (h1 odd, h even)
        out = out + np.sum(weights[:, None] * np.stack(
            [_correlate(dv[:, k], kv) if through[k] else np.zeros_like(dv[:, k]) for k in range(dv.shape[1])], 1), 0)
    return resp * s2 * out


def _taps(rec):
    """(taps, order) of the recording's estimated accelerations where every DOF went through one
    Savitzky-Golay window (the target then holds one filter), else None."""
    from .._recordings._derivatives import savgol_taps

    how = (rec.derivation or {}).get("a")
    if how is None or how.get("order") not in (1, 2):
        return None
    windows = {w for w in how["windows"] if w}
    if len(windows) != 1:
        return None
    return savgol_taps(windows.pop(), how["polyorder"], how["order"], rec.dt, how["exclude_center"]), how["order"]


def gain_segments(recs, groups) -> list[list[tuple]] | None:
    """Per well, its records' (start, stop, dt, taps, order) within the well's concatenated rows
    where the record's accelerations were estimated through one Savitzky-Golay window (`_taps`), None
    in the list where not; None where no record of any well was: the joint regression's columns
    pass through that gain (`_coordination/_joint.joint_coordinate`'s `gain`, `apply_gain`)."""
    out, any_gain = [], False
    for grp in groups:
        start, segs = 0, []
        for k in grp:
            n, tg = recs[k].n_samples, _taps(recs[k])
            tg = tg if tg is not None and tg[1] == 2 else None  # from x only
            segs.append(None if tg is None else (start, start + n, float(recs[k].dt), tg[0], tg[1]))
            any_gain |= tg is not None
            start += n
        out.append(segs)
    return out if any_gain else None


def _inputs(rec, i: int, masses, topology) -> np.ndarray:
    """The measured inputs (base acceleration, forces) in DOF `i`'s target (N,)."""
    b, f = rec.inputs()
    return np.asarray(topology.carried(f - masses[None, :] * topology.absolute(np.zeros_like(rec.x), b)))[:, i]


def matched_target(rec, y: np.ndarray, i: int, masses, topology, tg=None) -> np.ndarray:
    """DOF `i`'s target `y` (N,) of one record with its measured inputs through the filter's gain where the
    record's accelerations were estimated (`tg`: its `_taps`, computed where not given): the target then
    holds G[x''] and G[u] (`band_rows`, and the joint regression with `gain_segments`)."""
    from .._topology import as_topology

    y = np.asarray(y, float)
    tg = _taps(rec) if tg is None else tg
    if tg is None:
        return y
    u = _inputs(rec, i, np.asarray(masses, float), as_topology(topology))
    return y + filter_gain(u, tg[0], tg[1], rec.dt) - u
