"""The slow content of an integrated displacement, restored from the slow-band force balance.

A displacement integrated from a velocity or acceleration sensor (`_recordings/_integrate.py`)
has lost its content below the drift cut-off f_hp. Part of that content is real: about a well,
F(x_e + q) = k1 q + k2 q^2 + k3 q^3 + ..., and a vibration q(t) shifts the mean position by a slow
s(t) with

    k1 s + lowpass(k2 q^2 + k3 q^3 + ...) = 0

(the band below f_hp carries no inertia, no input and, for an oscillation symmetric in v, no
damping), a shift that follows the vibration's amplitude (a sweep: it changes over the record).
Without s, the local fit sees k2 q^2's slow part with no force to balance it and takes k2 too
small: shallow arch, velocity only, 0.45 % of the interwell distance, noise-free, F''/2 -17.6 and
13.6 where the truth has -23.85 and 23.72, and the global law 26 % off.

`restore_slow` fits the local law in the band above f_hp only (the target and every regressor
high-passed by the same cosine-transform filter as the drift removal: the equation holds in any
band, and the missing s barely touches that band), then adds s = -lowpass(k2 q^2) / k1 to x
where the band-limited fit resolves k2 (|t| >= `MIN_T`). The cubic is fitted, so that it does not
bias k2, but left out of s: the missing s enters the band above f_hp through 2 k2 q s, which a
cubic absorbs (k3 - 4 k2^2 / (3 k1) on a sine: the arch's -1.06 fitted as -78).

The restored s holds only the k2 q^2 part of the slow band, so `reconstruct` also fits without that
band: every local regression of such a DOF (`band_rows`: the library columns and the target lose
their content between 0 and the cut-off, the mean kept) and the joint regression's rows (`segments`,
`apply_band`). The slow band then only sets the mean (the static balance at the given equilibrium).
Shallow arch, velocity only, 0.45 %, noise-free: local F''/2 -26.6 and 22.1 (30 and 12 standard errors
off) -> -23.85 and 23.74, restoring error 6.95 -> 2.11 % (the curvature oracle 2.61 %; true x with the
same estimated accelerations 1.93 %).
"""

from dataclasses import replace

import numpy as np

from .._recordings._integrate import remove_drift
from .._recordings._recording import Recording

#: the curvature enters the restored shift only where the band-limited fit resolves it
MIN_T = 3.0
#: the first and last fraction of the record left out of the band-limited fit (integration edges)
EDGE = 0.05
#: band-limited fits and restorations (`slow_shift`)
PASSES = 3


def _band_fit(q, v, y, dt, f_hp):
    """The local law k1 q + k2 q^2 + k3 q^3 + c1 v + c2 v|v| fitted in the band above f_hp: its
    coefficients and t values."""
    cols = np.stack([q, q**2, q**3, v, v * np.abs(v)], axis=1)
    hp = remove_drift(cols, dt, f_hp)
    yh = remove_drift(y, dt, f_hp)
    n = q.size
    inner = slice(int(EDGE * n), n - int(EDGE * n))
    a, b = hp[inner], yh[inner]
    coef, *_ = np.linalg.lstsq(a, b, rcond=None)
    resid = b - a @ coef
    cov = np.linalg.pinv(a.T @ a) * float(resid @ resid) / max(a.shape[0] - a.shape[1], 1)
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return coef, np.where(se > 0, coef / np.where(se > 0, se, 1.0), 0.0)


def slow_shift(x: np.ndarray, v: np.ndarray, y: np.ndarray, dt: float, f_hp: float) -> tuple[np.ndarray, dict]:
    """The slow shift s (N,) of one DOF's integrated x (module docstring) from its target y (the
    force the DOF carries) and v, with the band-limited local fit's slope, curvature and cubic
    (`k`, `t`), the passes it took and the shift's RMS relative to the vibration's (`rms_ratio`).

    Iterated (`PASSES`): each pass refits the band-limited law on x + s, whose columns then carry
    the shift the previous pass restored."""
    x, v, y = (np.asarray(z, float) for z in (x, v, y))
    s = np.zeros_like(x)
    info: dict = {"passes": 0}
    for it in range(PASSES):
        q = x + s - np.mean(x + s)
        coef, t = _band_fit(q, v, y, dt, f_hp)
        k1, k2, k3 = (float(c) for c in coef[:3])
        info = {"k": [k1, k2, k3], "t": [float(z) for z in t[:3]], "passes": it + 1}
        if not (np.isfinite(k1) and k1 > 0 and abs(t[0]) >= MIN_T):  # no stable slope to balance with
            return np.zeros_like(x), info | {"rms_ratio": 0.0}
        nonlinear = k2 * q**2 if abs(t[1]) >= MIN_T else np.zeros_like(q)
        slow = nonlinear - remove_drift(nonlinear, dt, f_hp)  # its content below f_hp
        s = -slow / k1
    q = x - np.mean(x)
    return s, info | {"rms_ratio": float(np.std(s) / max(float(np.std(q)), 1e-300))}


def restore_slow(rec: Recording, targets: np.ndarray) -> Recording:
    """`rec` with the slow shift of every DOF's integrated x restored (module docstring) where x
    was integrated from v or a and the equilibrium was given; unchanged otherwise. `targets`
    (N, D): the force each DOF carries (`regression_targets`). Recorded in
    `rec.integration["slow_restored"]` (per DOF: the band-limited slope, curvature and cubic with
    their t, the passes, and the shift's RMS relative to the vibration's)."""
    info = rec.integration or {}
    if "x" not in rec.derived or not info.get("f_highpass_hz") or rec.equilibrium is None:
        return rec
    f_hp = float(np.max(info["f_highpass_hz"]))
    x = np.array(rec.x, float)
    report = []
    for i in range(x.shape[1]):
        s, how = slow_shift(x[:, i], rec.v[:, i], targets[:, i], rec.dt, f_hp)
        x[:, i] = x[:, i] + s
        report.append(how)
    return replace(rec, x=x, integration={**info, "slow_restored": report})


def integrated_cut(recs, groups, i: int) -> list[float] | None:
    """The drift cut-off (Hz) of DOF `i`'s integrated x in each recording of its wells (`groups`,
    in their order), or None unless every one of them had x integrated (`Recording.integration`)."""
    cuts = []
    for k in (k for grp in groups for k in grp):
        info = recs[k].integration or {}
        if "x" not in recs[k].derived or not info.get("f_highpass_hz"):
            return None
        f = np.asarray(info["f_highpass_hz"], float).reshape(-1)
        cuts.append(float(f[min(i, f.size - 1)]))
    return cuts


def segments(recs, groups, i: int) -> list[list[tuple[int, int, float, float]]] | None:
    """Per well of DOF `i`, its records' (start, stop, dt, cut-off) within the well's concatenated
    rows where x was integrated (`integrated_cut`), else None: the joint regression's slow band
    (`_coordination/_joint.joint_coordinate`'s `band`)."""
    cuts = integrated_cut(recs, groups, i)
    if cuts is None:
        return None
    out, j = [], 0
    for grp in groups:
        start, segs = 0, []
        for k in grp:
            n = recs[k].n_samples
            segs.append((start, start + n, float(recs[k].dt), cuts[j]))
            start, j = start + n, j + 1
        out.append(segs)
    return out


def edge_weights(recs, groups) -> list[np.ndarray]:
    """Per well, (samples,) weights 0 on the first and last `EDGE` of each record, 1 elsewhere
    (the integration's ends, as `_band_fit`), concatenated as the well's rows are."""
    out = []
    for grp in groups:
        parts = []
        for k in grp:
            n = recs[k].n_samples
            m, e = np.ones(n), int(EDGE * n)
            m[:e], m[n - e:] = 0.0, 0.0
            parts.append(m)
        out.append(np.concatenate(parts))
    return out


def apply_band(segs, a: np.ndarray) -> np.ndarray:
    """`a` (samples, ...) of one well with each record's slow band removed (`remove_drift` with the mean
    kept), padding left as it is."""
    out = np.array(a, float)
    for start, stop, dt, cut in segs:
        out[start:stop] = remove_drift(out[start:stop], dt, cut, keep_mean=True)
    return out


#: the rows of a local fit on estimated accelerations pass through the differentiation filter's own
#: gain (`filter_gain`, `band_rows`; False: the raw columns, as before)
MATCHED = True
#: ... the local stiffness's column q too (True: q raw, as at stop 40). G[q] carries the noise of x at every lag
#: of the filter, correlated with the target's, which `cross_moment` takes off (`CROSS`): shallow arch, x only,
#: 30 dB, `structured_noise`, local F' 24.80 and 14.91 through G without it for the truth's 24.32 and 14.44
#: (12-15 standard errors), 24.31 and 14.43 with it. Raw, q misses the filter's shortfall at the well's
#: frequency: single-tone arch, x only, 30 dB, seed 0, 2.68 % raw, 1.16 % through G; joint 10 Hz sine
#: records, x only, 60 dB, seeds 0-3: 0.09/0.58/0.03/0.57 % raw, 0.018/0.017/0.14/0.009 % through G
RAW_LINEAR = False


#: the joint regression's columns through the gain as well where the accelerations were estimated from x
#: (`gain_segments`; False: raw columns, as before). Not from v: single-tone arch, v only, 30 dB, seed 1,
#: 2.25 % on raw columns, 17.2 % through G (seed 0 and 50 dB within 0.05 points)
JOINT_GAIN = True


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


#: the local fits' normal equations lose the expected product of the columns' noise with the target's where
#: both hold the noise of a measured x (accelerations estimated from it: `cross_moment`; False: as before)
CROSS = True


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
                 resp: float) -> np.ndarray | None:
    """(terms,): sum over the samples of `weights` times the expected product of each library column's noise
    with the target's, to first order in the noise of x, where the record's accelerations were estimated from a
    measured x (None elsewhere). The target holds resp h * (x + n) (h the second-derivative taps); a column
    phi(q, v) (through G where `through`) moves by G[d phi / dq n + d phi / dv h1 * n] where v was estimated
    from x too (h1 its first-derivative taps), so E[dc(t) dy(t)] = resp s^2 (sum_l g(l) h(l) dphi/dq(t + l)
    + sum_l g(l) c1(l) dphi/dv(t + l)), c1(l) = sum_s h1(s) h(l + s), g = delta for a raw column. Raw q with
    the centre tap in (steady sines): s^2 h(0); through G the spread of G carries it at every lag."""
    import jax
    import jax.numpy as jnp

    from .._recordings._derivatives import savgol_taps
    from ._noise import channel_variance

    how = (rec.derivation or {}).get("a")
    tg = _taps(rec)
    if not CROSS or tg is None or how["from"] != "x" or "x" in rec.derived or tg[1] != 2:
        return None
    h, dt = tg[0], rec.dt
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
    if not MATCHED or how is None or how.get("order") not in (1, 2):
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
            tg = tg if tg is not None and tg[1] == 2 else None  # from x (module's JOINT_GAIN)
            segs.append(None if tg is None else (start, start + n, float(recs[k].dt), tg[0], tg[1]))
            any_gain |= tg is not None
            start += n
        out.append(segs)
    return out if any_gain else None


def apply_gain(segs, a: np.ndarray) -> np.ndarray:
    """`a` (samples, ...) of one well with each record's rows through its filter's gain (`filter_gain`;
    `segs` one well's list from `gain_segments`), padding and records without one left as they are."""
    out = np.array(a, float)
    for seg in segs:
        if seg is not None:
            start, stop, dt, taps, order = seg
            out[start:stop] = filter_gain(out[start:stop], taps, order, dt)
    return out


def _inputs(rec, i: int, masses, topology) -> np.ndarray:
    """The measured inputs (base acceleration, forces) in DOF `i`'s target (N,)."""
    b, f = rec.inputs()
    return np.asarray(topology.carried(f - masses[None, :] * topology.absolute(np.zeros_like(rec.x), b)))[:, i]


def matched_targets(recs, groups, i: int, targets, masses, topology, width: int) -> np.ndarray:
    """(wells, `width`) DOF `i`'s targets padded like the rows, the measured inputs of each record
    with estimated accelerations through its filter's gain (the target then holds G[x''] and G[u]:
    `band_rows`, and the joint regression with `gain_segments`)."""
    from .._topology import as_topology

    topo, masses = as_topology(topology), np.asarray(masses, float)
    out = np.zeros((len(groups), width))
    for g, grp in enumerate(groups):
        start = 0
        for k in grp:
            r, tg = recs[k], _taps(recs[k])
            yk = np.asarray(targets[k][:, i], float)
            if tg is not None:
                u = _inputs(r, i, masses, topo)
                yk = yk + filter_gain(u, tg[0], tg[1], r.dt) - u
            out[g, start:start + r.n_samples] = yk
            start += r.n_samples
    return out


def band_rows(recs, groups, i: int, w: np.ndarray, targets, library, masses, topology, segs):
    """Per well of DOF `i`, the `BandRows` of its local regression: the library columns at the well's
    centre (the `w`-weighted mean of x, as `fit_local` takes it) and the target `targets[k][:, i]`,
    padded like the rows, where the records' accelerations were estimated or x integrated (`segs`,
    from `segments`); None where neither holds.

    Estimated accelerations (one Savitzky-Golay window for every DOF of a record, `_taps`): the
    target holds G[x''], G the filter's gain (`filter_gain`), so the columns pass through G too
    (q's as well unless `RAW_LINEAR`) and the target's measured inputs (base acceleration, forces) as
    well; where x was measured, each well's `BandRows.cross` holds the noise its columns share with the
    target (`cross_moment`), which `fit_local` takes off the normal equations. On the raw columns the gain's shortfall on the harmonics of a nonlinear term
    reads as other terms: bistable joint, x only, noise-free 0.5 degree sweep, a [1, q, q^2, q^3, v,
    v^3] fit gives q^3 28000 for 1755, v 0.64 for 0 and v^3 9.66 for 10; through G 2236, 0.002 and
    9.999 (the rest from the estimated v); with the true v exact.

    Integrated x: the columns and the target lose their record's slow band (between 0 and the drift
    cut-off, the mean kept: `remove_drift(..., keep_mean=True)`). The integration removed that band
    from x, and `restore_slow` puts back only its k2 q^2 part; a regression on all rows takes the
    curvature from it (q^2's slow part follows the envelope of a sweep): shallow arch, velocity only,
    0.45 % of the interwell distance, noise-free, local F''/2 -26.6 and 22.1 (30 and 12 standard
    errors off) against the truth's -23.85 and 23.72; without the slow band -23.85 and 23.74 (within
    1 standard error)."""
    import jax.numpy as jnp

    from .._fit._library import STIFFNESS
    from .._fit._local_fit import BandRows
    from .._topology import as_topology

    gains = [[_taps(recs[k]) for k in grp] for grp in groups]
    if segs is None and not any(gn is not None for row in gains for gn in row):
        return None
    from ._noise import _response

    k1 = library.column(STIFFNESS, 1)
    topo, masses = as_topology(topology), np.asarray(masses, float)
    through = np.ones(library.n_terms, bool)
    through[k1] = not RAW_LINEAR
    resp = float(_response(topo, masses, recs[groups[0][0]].n_dof, i)[0][i])
    out = []
    for g, grp in enumerate(groups):
        n_g = sum(recs[k].n_samples for k in grp)
        xcat = np.concatenate([recs[k].x[:, i] for k in grp])
        wg = w[g, :n_g]
        centre = float(np.sum(wg * xcat) / np.sum(wg))
        theta = np.zeros((w.shape[1], library.n_terms))
        y = np.zeros(w.shape[1])
        cross, start = np.zeros(library.n_terms), 0
        for m, k in enumerate(grp):
            r = recs[k]
            th = np.asarray(library(jnp.asarray(r.x[:, i] - centre), jnp.asarray(r.v[:, i])), float)
            yk = np.asarray(targets[k][:, i], float)
            if gains[g][m] is not None:  # the columns through the target's filter, the inputs too
                taps, order = gains[g][m]
                u = _inputs(r, i, masses, topo)
                raw = th
                th = filter_gain(th, taps, order, r.dt)
                if RAW_LINEAR:
                    th[:, k1] = raw[:, k1]
                yk = yk + filter_gain(u, taps, order, r.dt) - u
                c = cross_moment(r, i, r.x[:, i] - centre, wg[start:start + r.n_samples], library, through, resp)
                cross = cross if c is None else cross + c
            if segs is not None:
                _, _, dt, cut = segs[g][m]
                th, yk = remove_drift(th, dt, cut, keep_mean=True), remove_drift(yk, dt, cut, keep_mean=True)
            theta[start:start + r.n_samples], y[start:start + r.n_samples] = th, yk
            start += r.n_samples
        out.append(BandRows(theta=jnp.asarray(theta), y=jnp.asarray(y),
                            cross=jnp.asarray(cross) if np.any(cross != 0) else None))
    return out
