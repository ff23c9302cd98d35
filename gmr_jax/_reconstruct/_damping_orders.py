"""Velocity terms no well kept, in the damping band at the speeds the model is used at (issue 15; beyond the paper).

Small vibrations reach a fraction of the speeds of a well-to-well crossing, and a damping term that grows faster
than v (quadratic drag v|v|, cubic v^3) is a small share of the damping there: the threshold drops it at every
well, the coordination then takes its coefficient as exactly zero, and the band at crossing speeds is as narrow as
the viscous coefficient's (audit, a tri-stable quintic with (0.2 + 1400 x^2) v + 2 v^3 damping, x v a at 60 dB,
records at |v| <= 0.04: the damping at |v| = 0.4 2.6 x too low, the truth ~500 band half-widths away, no warning).

Each well that keeps a damping term is refitted with the dropped order j added to its support, or in place of the
velocity powers above 1 it kept where those stay within `SWAP_T` standard errors of 0 beside it (collinear
stand-ins at small speeds; `_local_rules._refit_on`, the other kept terms exempt from the threshold). The wells'
velocity laws (one law, shared by the wells) are pooled with inverse-variance weights of B_j = c_j +- s_j. The band
holds that alternative law's difference from the model's and s_j^2 on B_j (a threshold's choice, as
`_damping_slopes` enters the slope a well left open); the model's mean is unchanged. `reconstruct` warns (rule 14b,
`_sanity.check_unresolved_damping`) where the alternative parts from the model's damping by more than
`_sanity.DAMPING_SPREAD` below the speed of a fall from the highest barrier (`_sanity.crossing_speed`). Only on the
paper route's damping: the joint regression's candidates hold these orders and its own choice enters its band
(rule 14).
"""

import numpy as np

from .._fit._library import STIFFNESS, VELOCITY_DAMPING, Library
from .._solution import RESULTS
from ._local_rules import _refit_on, with_constant

#: the velocity orders `unresolved_orders` tests (sgn(v)|v|^j): quadratic drag and cubic damping, the laws a
#: structure's joints and air give; higher powers have no physical reading here and their extrapolation, v^5 at
#: 10 x the recorded speed, would make every band at crossing speeds unbounded
ORDERS = (2, 3)
#: a kept velocity order above 1 that stays within this many standard errors of 0 beside the tested one is its
#: stand-in, and the alternative law replaces it (the local screens' 3 sigma)
SWAP_T = 3.0


def unresolved_orders(fits, xs, vs, ys, w, library: Library, solver, velocity_damping, noise=None, x_noise=None,
                      band=None) -> dict[int, tuple[float, float, int, np.ndarray, tuple]]:
    """{order j: (c_j, s_j, wells, delta, replaced)} for each of `ORDERS` in the library that no well kept (module
    docstring). Each well with a damping term is refitted with sgn(v)|v|^j added to its support, and where none of
    the velocity orders above 1 it kept stays within `SWAP_T` standard errors of 0 beside it, with sgn(v)|v|^j in
    their place (`replaced`: on a few percent of the crossing speeds every power of v is the others' stand-in: a
    kept 411 sgn(v)|v|^4 for the truth's 5 v^3 damps 2.6 x too hard at a crossing; the joint's kept 10 v^3 stays,
    t > 100 beside v|v|); the wells' velocity laws are pooled with inverse-variance weights of their c_j: `c_j`
    +- `s_j`, and `delta` the pooled change of the wells' velocity laws, on the model's `velocity_damping` block
    (the alternative the band holds). Wells without a damping term, or whose refit failed, give none. Other
    arguments as `_local_rules._refit_on` takes them."""
    terms = library.terms()
    coef = np.asarray(fits.coef)
    damping = np.array([phys != STIFFNESS for phys, _ in terms])
    vel = {j: terms.index((VELOCITY_DAMPING, j)) for phys, j in terms if phys == VELOCITY_DAMPING}
    n_model = np.asarray(velocity_damping).shape[0]
    out = {}

    def refit(k, mask):
        sol = _refit_on(xs, vs, ys, w, library, solver, fits, k, mask, noise, x_noise, band)
        ok = int(sol.result._value) == int(RESULTS.successful._value)
        return ok, np.asarray(sol.value.coef), np.asarray(sol.value.covariance)

    base = {}

    def kept_law(k):  # the kept support refitted as the alternatives are (the fits come from other stages)
        if k not in base:
            ok, row, _ = refit(k, with_constant(coef[k] != 0, library))
            base[k] = row if ok else None
        return base[k]

    for j in ORDERS:
        if j not in vel or np.any(coef[:, vel[j]] != 0):
            continue  # not in the library, or kept somewhere: the coordination's covariance holds it
        laws, est, var, replaced = [], [], [], set()
        for k in range(coef.shape[0]):
            if not np.any(damping & (coef[k] != 0)):
                continue
            mask = with_constant(coef[k] != 0, library)
            mask[vel[j]] = True
            ok, row, cv = refit(k, mask)  # the kept law with sgn(v)|v|^j added
            kept = [o for o, col in vel.items() if o >= 2 and coef[k, col] != 0]
            if ok and kept and all(abs(row[vel[o]]) < SWAP_T * np.sqrt(max(cv[vel[o], vel[o]], 0.0)) for o in kept):
                for o in kept:  # none of them is needed beside it: the law with it in their place
                    mask[vel[o]] = False
                ok, row, cv = refit(k, mask)
                replaced.update(kept)
            c, v = float(row[vel[j]]), float(cv[vel[j], vel[j]])
            row0 = kept_law(k)
            if ok and row0 is not None and np.isfinite(c) and np.isfinite(v) and v > 0:
                laws.append(np.array([row[vel[o]] - row0[vel[o]] for o in sorted(vel)]))  # the change
                est.append(c)
                var.append(v)
        if est:
            wt = 1.0 / np.asarray(var)
            change = np.sum(wt[:, None] * np.asarray(laws), axis=0) / np.sum(wt)
            n = min(change.size, n_model)
            delta = np.zeros(n_model)
            delta[:n] = change[:n]
            out[j] = (float(np.sum(wt * np.asarray(est)) / np.sum(wt)), float(np.sqrt(1.0 / np.sum(wt))), len(est),
                      delta, tuple(sorted(replaced)))
    return out


def add_order_vectors(covariance, n_stiffness: int, n_velocity: int, found: dict) -> np.ndarray:
    """The flat covariance (stiffness, velocity damping, position damping blocks) plus, for each found order
    (`unresolved_orders`), the outer product of its alternative law's difference `delta` on the velocity block and
    its coefficient's variance s_j^2 on B_j; orders beyond the velocity block are left out."""
    cov = np.array(covariance, float)
    for j, (_, s, _, delta, *_) in found.items():
        if j >= n_velocity:
            continue
        full = np.zeros(cov.shape[0])
        full[n_stiffness:n_stiffness + n_velocity] = delta[:n_velocity]
        cov += np.outer(full, full)
        cov[n_stiffness + j, n_stiffness + j] += s * s
    return cov
