"""The paper route's damping under a noisy measured v (issue 15; beyond the paper).

The local fits (Eq. 4) take the measured v as exact, so white noise on it attenuates a v^3 term and leaks its
share into v. The damping-only joint regression corrects for that noise (`_coordination._joint`'s
`_velocity_noise`) and reports how far the noise would move its law left uncorrected
(`joint_velocity_noise_shift`). Where that move exceeds `V_NOISE_DAMPING` standard errors, `reconstruct`'s auto
route hands the damping to the corrected joint law ("gls + joint damping"). This module holds the gate: whether
the move is worth measuring (`worth_measuring`) and its size (`moved`).
"""

import numpy as np

from .._coordination._coordinate import GlobalCoefficients
from .._fit._library import POSITION_DAMPING, VELOCITY_DAMPING, Library, damping_columns
from .._fit._local_fit import LocalFit
from .._solution import Solution

#: the paper route's damping gives way to the joint regression's (the restoring force kept) where v is measured
#: with white noise at every well (`_noise.v_noise_variance`) and that noise moves the damping law by more than
#: this many of its standard errors (`moved`; 0: off): the local fits take v as exact, so the noise
#: attenuates their v^3 and leaks into their v, where the joint regression corrects for it (`_joint._velocity_noise`).
#: Bistable joint, 10 v^3, 5 degrees, 30 dB, seed 1: the paper route's damping band held the truth on 64 % of the
#: wells' span x v_range, the corrected joint damping's on 100 %
V_NOISE_DAMPING = 1.0


def recorded_speed(vs, w) -> float:
    """The largest recorded |v| of one DOF (padded per-well arrays, `w` 0 on padding)."""
    return float(np.max(np.abs(np.asarray(vs)) * (np.asarray(w) > 0)))


def damping_force_rows(g: GlobalCoefficients, x, v) -> np.ndarray:
    """Rows that map the flat coefficients (stiffness, velocity damping, position damping) to the damping force
    at the points (x, v) (`_fit._library.damping_columns`; zeros on the stiffness)."""
    ns, nv, npd = (np.asarray(a).shape[0] for a in (g.stiffness, g.velocity_damping, g.position_damping))
    x, v = np.asarray(x, float), np.asarray(v, float)
    return np.concatenate([np.zeros((x.size, ns)), damping_columns(x, v, nv, npd)], axis=1)


def negligible(fits: LocalFit, v_noise, vs, w, library: Library) -> bool:
    """Whether the noise of v cannot move the damping by a tenth of `V_NOISE_DAMPING` standard errors, without the
    regression that measures it (`moved`), on a heuristic bound: where every damping term the local fits kept
    is linear in v (c v, c x^j v), that noise only attenuates them, by s^2 / <v^2> of themselves, so their largest
    |t| times the largest such ratio over the wells bounds the move (taken twice); a term nonlinear in v (Coulomb,
    v|v|, v^3) also leaks into the others, by up to 50 x that product (bistable joint, 10 v^3, 30 dB, seed 1:
    0.091, moved by 4.6 standard errors), and is always measured. 5-cell Kresling, viscous, 60 dB: products
    0.005-0.007 (measured moves 0.002-0.003), skipped."""
    terms = library.terms()
    damping = np.array([phys in (VELOCITY_DAMPING, POSITION_DAMPING) for phys, _ in terms])
    nonlinear = np.array([phys == VELOCITY_DAMPING and k != 1 for phys, k in terms])
    coef, cov = np.asarray(fits.coef), np.asarray(fits.covariance)
    if np.any(coef[:, nonlinear] != 0):
        return False
    var = np.diagonal(cov, axis1=1, axis2=2)
    t = np.where(damping[None, :] & (var > 0), np.abs(coef) / np.sqrt(np.where(var > 0, var, 1.0)), 0.0)
    vs, w = np.asarray(vs), np.asarray(w)
    power = np.array([np.sum(w[k] * vs[k] ** 2) / max(np.sum(w[k]), 1e-300) for k in range(vs.shape[0])])
    ratio = np.max(np.asarray(v_noise, float) / np.where(power > 0, power, np.inf))
    return bool(2.0 * ratio * float(t.max(initial=0.0)) < 0.1 * V_NOISE_DAMPING)


def worth_measuring(fits: LocalFit, v_noise, vs, w, library: Library, gain) -> bool:
    """Whether to run the corrected damping-only joint regression beside the paper route: the gate is on, v is
    measured with white noise at every well (`v_noise`, per well, None where not), the columns pass no filter
    gain (the joint regression does not correct for the noise there) and the move is not `negligible`."""
    return bool(V_NOISE_DAMPING and v_noise is not None and gain is None and all(v is not None for v in v_noise)
                and not negligible(fits, v_noise, vs, w, library))


def moved(corrected: Solution, fits: LocalFit, vs, w) -> float:
    """RMS over the wells' span x the recorded speeds (21 x 20 points) of what the noise of v moves the joint
    regression's damping force by, uncorrected (`_joint`'s `joint_velocity_noise_shift`), in its standard errors
    (`V_NOISE_DAMPING`); 0 where the correction did not apply."""
    g = corrected.value
    n_damp = np.asarray(g.velocity_damping).shape[0] + np.asarray(g.position_damping).shape[0]
    shift = np.asarray(corrected.stats.get("joint_velocity_noise_shift", []), float)[-n_damp:]
    eq = np.asarray(fits.equilibrium)
    top = recorded_speed(vs, w)
    if not corrected.stats.get("joint_velocity_noise", False) or shift.size != n_damp or top <= 0:
        return 0.0
    xx, vv = (a.ravel() for a in np.meshgrid(np.linspace(eq.min(), eq.max(), 21),
                                             np.linspace(-top, top, 20), indexing="ij"))
    rows = damping_force_rows(g, xx, vv)
    ns = rows.shape[1] - n_damp
    diff = rows[:, ns:] @ shift
    se = np.sqrt(np.maximum(np.einsum("ip,pq,iq->i", rows, np.asarray(corrected.aux), rows), 0.0))
    ok = se > 0
    return float(np.sqrt(np.mean((diff[ok] / se[ok]) ** 2))) if ok.any() else 0.0
