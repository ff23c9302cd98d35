"""The slow content of an integrated displacement, restored from the slow-band force balance.

A displacement integrated from a velocity or acceleration sensor (`_recordings/_integrate.py`)
has lost its content below the drift cut-off f_hp. Part of that content is real: about a well,
F(x_e + q) = k1 q + k2 q^2 + k3 q^3 + ..., and a vibration q(t) shifts the mean position by a slow
s(t) with

    k1 s + lowpass(k2 q^2 + k3 q^3 + ...) = 0

(the band below f_hp carries no inertia, no input and, for an oscillation symmetric in v, no
damping), a shift that follows the vibration's amplitude (a sweep: it changes over the record).
Without s, the local fit sees k2 q^2's slow part with no force to balance it and takes k2 too
small.

`restore_slow` fits the local law in the band above f_hp only (the target and every regressor
high-passed by the same cosine-transform filter as the drift removal: the equation holds in any
band, and the missing s barely touches that band), then adds s = -lowpass(k2 q^2) / k1 to x
where the band-limited fit resolves k2 (|t| >= `MIN_T`). The cubic is fitted, so that it does not
bias k2, but left out of s: the missing s enters the band above f_hp through 2 k2 q s, which a
cubic absorbs (k3 - 4 k2^2 / (3 k1) on a sine).

The restored s holds only the k2 q^2 part of the slow band, so `reconstruct` also fits without that
band: every local regression of such a DOF (`band_rows`: the library columns and the target lose
their content between 0 and the cut-off, the mean kept) and the joint regression's rows (`segments`,
`apply_band`). The slow band then only sets the mean (the static balance at the given equilibrium).
"""

from dataclasses import replace

import equinox as eqx
import numpy as np

from .._fit._library import STIFFNESS
from .._recordings._integrate import remove_drift
from .._recordings._recording import Recording
from ._filter_gain import _taps, cross_moment, filter_gain, matched_target

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


def band_rows(recs, groups, i: int, w: np.ndarray, targets, library, masses, topology, segs):
    """Per well of DOF `i`, the `BandRows` of its local regression: the library columns at the well's
    centre (the `w`-weighted mean of x, as `fit_local` takes it) and the target `targets[k][:, i]`,
    padded like the rows, where the records' accelerations were estimated or x integrated (`segs`,
    from `segments`); None where neither holds.

    Estimated accelerations (one Savitzky-Golay window for every DOF of a record, `_taps`): the
    target holds G[x''], G the filter's gain (`filter_gain`), so the columns pass through G too
    (q's as well) and the target's measured inputs (base acceleration, forces) as
    well; where x was measured, each well's `BandRows.cross` holds the noise its columns share with the
    target (`cross_moment`), which `fit_local` takes off the normal equations. On the raw columns the gain's
    shortfall on the harmonics of a nonlinear term reads as other terms.

    Integrated x: the columns and the target lose their record's slow band (between 0 and the drift
    cut-off, the mean kept: `remove_drift(..., keep_mean=True)`). The integration removed that band
    from x, and `restore_slow` puts back only its k2 q^2 part; a regression on all rows takes the
    curvature from it (q^2's slow part follows the envelope of a sweep)."""
    import jax.numpy as jnp

    from .._fit._local_fit import BandRows
    from .._topology import as_topology

    gains = [[_taps(recs[k]) for k in grp] for grp in groups]
    if segs is None and not any(gn is not None for row in gains for gn in row):
        return None
    from ._noise import _response

    topo, masses = as_topology(topology), np.asarray(masses, float)
    through = np.ones(library.n_terms, bool)
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
                th = filter_gain(th, taps, order, r.dt)
                yk = matched_target(r, yk, i, masses, topo, gains[g][m])
                c = None if order != 2 else cross_moment(r, i, r.x[:, i] - centre, wg[start:start + r.n_samples],
                                                         library, through, resp, taps)
                cross = cross if c is None else cross + c
            if segs is not None:
                _, _, dt, cut = segs[g][m]
                th, yk = remove_drift(th, dt, cut, keep_mean=True), remove_drift(yk, dt, cut, keep_mean=True)
            theta[start:start + r.n_samples], y[start:start + r.n_samples] = th, yk
            start += r.n_samples
        out.append(BandRows(theta=jnp.asarray(theta), y=jnp.asarray(y),
                            cross=jnp.asarray(cross) if np.any(cross != 0) else None))
    return out


#: an integrated x's local fits hand the coordination their terms up to this restoring order only (`curvature_only`)
INTEGRATED_MAX_ORDER = 2


def curvature_only(fits, library):
    """The local fits of a DOF whose x was integrated from v or a, with their restoring terms above the curvature
    (q^3 and up, `INTEGRATED_MAX_ORDER`) zeroed, with their covariance rows: the coordination's conditions are each
    well's F, F', F''. What the restored shift misses of x's slow band enters the band above the cut-off through
    2 k2 q s, which the local cubic absorbs (module docstring): a bias of up to 4 k2^2 / (3 k1) times the missed
    share, systematic, which the local standard errors do not carry. The terms stay in the local fits (left out
    there, they would bias F' and F'')."""
    high = np.array([phys == STIFFNESS and k > INTEGRATED_MAX_ORDER for phys, k in library.terms()])
    if not np.any(np.asarray(fits.coef)[:, high] != 0):
        return fits
    coef, cov = np.array(fits.coef, float), np.array(fits.covariance, float)
    coef[:, high] = 0.0
    cov[:, high, :] = 0.0
    cov[:, :, high] = 0.0
    return eqx.tree_at(lambda f: (f.coef, f.covariance), fits, (coef, cov))
