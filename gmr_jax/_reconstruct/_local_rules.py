"""The local fits' refit rules between STLS and the coordination (Algorithm 1, steps 2-3; issue 15).

STLS judges each term by its share of the local force, and the paper's coordination takes every kept local
coefficient as exact (Eq. 18). Between the two, `reconstruct` runs these rules on each DOF's wells, all on
the host (NumPy bookkeeping around the jitted `fit_local`):

- `_screen`: the t-test on each kept term (`screen_sigma`), the restoring series screened from the top;
- `_one_of_a_group`: a well whose damping terms the screen zeroed all at once keeps the best one of them;
- `_extend_restoring`: the local restoring order raised while the next Taylor term is resolved;
- `_share_velocity_damping`: one set of position-independent damping terms for every well (Eq. 21).
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._fit._library import POSITION_DAMPING, STIFFNESS, VELOCITY_DAMPING, Library
from .._fit._local_fit import LocalFit, fit_local, with_constant
from .._solution import RESULTS


def _screen(fits: LocalFit, n_sigma: float, library: Library | None = None, exempt=None) -> LocalFit:
    """Local coefficients under `n_sigma` standard errors set to zero (and their covariance rows);
    NumPy in, NumPy out (the bookkeeping after the jitted fits dispatches no JAX operation).

    With `library`, the restoring Taylor series is screened from the top only: a fitted q^m below
    a kept higher order stays (with its covariance). The coordination takes a zero below a well's
    highest order as a known zero (Eq. 18), and an unresolved q^3 under a resolved q^4 is not known
    to be zero (shallow arch, 30 dB, seed 2: the third derivative set to 0 at the second well,
    restoring error 1.33 -> 3.54 % where the correction for the noise on x moved q^3 below 3
    standard errors). A coefficient STLS set to zero stays zero, as in the paper, and one the screen
    zeroes joins it: both weigh in the coordination as the variance they would have had kept
    (`LocalFit.dropped`; here the standard error squared), not as exact zeros. `exempt`: a mask
    (terms,) or (wells, terms) of terms kept whatever their t."""
    coef, cov = np.asarray(fits.coef), np.asarray(fits.covariance)
    se = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0.0, None))
    keep = np.abs(coef) >= n_sigma * se
    if exempt is not None:
        keep = keep | np.asarray(exempt, bool)
    if library is not None:
        idx = library.indices(STIFFNESS)  # q^0 .. q^r
        kept = keep[:, idx] & (coef[:, idx] != 0)
        top = np.max(np.where(kept, np.arange(idx.size), -1), axis=1)  # highest kept order per well
        below = np.arange(idx.size)[None, :] <= top[:, None]
        keep[:, idx] = kept | (below & (coef[:, idx] != 0))
    zeroed = ~keep & (coef != 0)
    cov = np.where(keep[:, :, None] & keep[:, None, :], cov, 0.0)
    if fits.dropped is None:
        return eqx.tree_at(lambda f: (f.coef, f.covariance), fits, (np.where(keep, coef, 0.0), cov))
    # a term the screen zeroed weighs in the coordination as the variance it had when fitted (its
    # standard error squared: the variance it would have kept), as a term STLS removed does
    # (`LocalFit.dropped`), not as an exact zero
    dropped = np.where(zeroed, se**2, np.asarray(fits.dropped))
    return eqx.tree_at(lambda f: (f.coef, f.covariance, f.dropped), fits,
                       (np.where(keep, coef, 0.0), cov, dropped))


def _under_top_order(coef: np.ndarray, library: Library) -> np.ndarray:
    """(wells, terms): the restoring orders under each well's highest nonzero one (`_screen` keeps
    them whatever their t)."""
    idx = library.indices(STIFFNESS)
    c = np.asarray(coef)[:, idx] != 0
    top = np.max(np.where(c, np.arange(idx.size), -1), axis=1)
    out = np.zeros(np.asarray(coef).shape, bool)
    out[:, idx] = np.arange(idx.size)[None, :] < top[:, None]
    return out


def _set_well(fits: LocalFit, k: int, new: LocalFit) -> LocalFit:
    """`fits` (stacked over wells, NumPy leaves) with well `k` replaced by `new` (stacked, one well)."""
    def put(a, b):
        a = np.array(a)  # a copy: the caller's fits are not changed
        a[k] = np.asarray(b)[0]
        return a

    return jax.tree.map(put, fits, new)


def _as_well(value) -> LocalFit:
    """One well's `fit_local` value as fits stacked over one well (NumPy leaves), as `_set_well` takes them."""
    return jax.tree.map(lambda a: np.asarray(a)[None], value)


def _summed_bic(fits: LocalFit) -> float:
    """The BIC summed over the wells, sum of n log(rss / n) + p log n (p: the well's nonzero terms)."""
    rss, n = np.asarray(fits.rss, float), np.asarray(fits.n_samples, float)
    return float(np.sum(n * np.log(np.maximum(rss, 1e-300) / np.maximum(n, 1.0))
                        + np.count_nonzero(np.asarray(fits.coef), axis=1) * np.log(np.maximum(n, 2.0))))


def low_order_terms(library: Library, restoring_order: int = 1) -> np.ndarray:
    """Mask of the local terms exempt from the STLS threshold: the restoring Taylor terms
    x^0 .. x^`restoring_order` and the damping polynomial's v and x v (value and slope)."""
    keep = {(STIFFNESS, k) for k in range(restoring_order + 1)}
    keep |= {(VELOCITY_DAMPING, 1), (POSITION_DAMPING, 1)}
    return np.array([t in keep for t in library.terms()])


def _fit_wells(xs, vs, ys, w, library, solver, select, keep=None, noise=None, x_noise=None, band=None):
    # One jitted fit per well (same shapes: compiled once), stacked. A vmap over wells with
    # batched weights and the CV threshold sweep stalled in XLA:CPU (jax 0.10), so loop here.
    noise, x_noise = noise or [None] * xs.shape[0], x_noise or [None] * xs.shape[0]
    band = band or [None] * xs.shape[0]
    sols = [fit_local(xs[k], vs[k], ys[k], library, solver, select, weights=w[k], keep=keep, noise=noise[k],
                      x_noise=x_noise[k], band=band[k], throw=False) for k in range(xs.shape[0])]
    return _stack(_same_stats(sols))


def _same_stats(sols):
    """The fits with one set of `stats` keys: a key only some wells report (`noise_ratio`, where a well's target
    holds a differentiated signal and another's a measured a: one file x only, the other x, v, a) is NaN (False for
    a flag) at the others, so that the wells stack."""
    keys = {}
    for s in sols:
        keys.update({k: v for k, v in s.stats.items() if k not in keys})
    if all(set(s.stats) == set(keys) for s in sols):
        return sols

    def blank(v):
        v = jnp.asarray(v)
        return jnp.zeros_like(v) if v.dtype == bool else jnp.full_like(v, jnp.nan, dtype=jnp.result_type(v, float))

    return [eqx.tree_at(lambda t: t.stats, s, {k: s.stats[k] if k in s.stats else blank(v) for k, v in keys.items()})
            for s in sols]


@eqx.filter_jit
def _stack(trees):
    """The trees stacked leaf by leaf (one compiled program, not one eager stack per leaf)."""
    return jax.tree_util.tree_map(lambda *a: jnp.stack(a), *trees)


def _shared_law_terms(library: Library) -> np.ndarray:
    """Mask of the position-independent damping terms sgn(v)|v|^j, j != 1 (one law for every well, Eq. 21;
    j = 1 is the damping polynomial's C(0) v)."""
    return np.array([phys == VELOCITY_DAMPING and k != 1 for phys, k in library.terms()])


def velocity_terms_not_shared(coef: np.ndarray, library: Library) -> np.ndarray:
    """Mask of the position-independent damping terms sgn(v)|v|^j, j != 1, that some wells'
    local fits selected and others did not (`coef`: (wells, terms))."""
    nonzero = coef != 0
    return _shared_law_terms(library) & np.any(nonzero, axis=0) & ~np.all(nonzero, axis=0)


def _share_velocity_damping(fits, xs, vs, ys, w, library, solver, keep, screen_sigma, dof, failure, noise=None,
                            x_noise=None, band=None):
    """One set of position-independent damping terms for every well (Eq. 21). Where the wells'
    fits selected different sets, each well is refitted (its own other terms, at its own threshold)
    with each candidate set: every well's own selection, their union, their intersection, none and
    each term of the union alone; the candidate's terms are exempt from the threshold (the t-screen judges
    them). Terms a refit leaves unshared are dropped and the wells
    that had them refitted, until every remaining term is shared; the candidate whose shared outcome has the
    least summed BIC over the wells wins (sum of n log(rss / n) + p log n). Returns the fits and the dropped
    orders j.

    Scoring the candidates before the wells agree picked a set whose partners then fell away: bistable joint,
    10 Hz sines, x only, 30 dB, seeds 1-2: the union won, its collinear terms fell to the t-screen beside v at
    one well, the drop cascaded, and both wells ended at v alone, the stand-in of the truth's 10 v^3 on the
    fundamental, F' 4374 (13) for 4488 and the law 2.3 % off; now v^4 and v^5 (one seed) or v and v|v| (the
    other) at both wells, F' within 0.3 % and the law 0.22/0.17 % off.

    The intersection alone (the rule before) dropped a well's correct law where the other well's fit
    had taken a collinear stand-in: bistable joint, x only, 40 dB, 0.5 degree sweeps, seed 4 with
    `structured_noise`: v^3 at one well, v at the other; both dropped, the damping fitted as 18.7 v,
    97 % off over the box."""
    dropped, noise, x_noise = [], noise or [None] * xs.shape[0], x_noise or [None] * xs.shape[0]
    band = band or [None] * xs.shape[0]
    coef0 = np.asarray(fits.coef)
    vd = _shared_law_terms(library)

    def refit(k, support, thr, tried=None):
        """Well k refitted on `support` and t-screened; refitted once more on what the screen kept (a
        term the screen zeroes without a refit leaves the others as they were beside it). `tried`: terms
        exempt from the threshold as the low orders are (the candidate set: the t-screen judges it)."""
        slv = eqx.tree_at(lambda s: s.threshold, solver, thr)
        exempt = keep if tried is None else kept | tried
        for _ in range(2):
            sol = fit_local(xs[k], vs[k], ys[k], library, slv, None, weights=w[k], keep=exempt,
                            support=jnp.asarray(support), noise=noise[k], x_noise=x_noise[k], band=band[k],
                            throw=False)
            if sol.result != RESULTS.successful:
                failure.note(sol.result, f"DOF {dof}, well {k}: refit with the shared damping terms")
            new = _as_well(sol.value)
            if screen_sigma is None:
                return new
            screened = _screen(new, screen_sigma, library)
            kept_now = with_constant(np.asarray(screened.coef[0]) != 0, library)
            if np.array_equal(kept_now, with_constant(np.asarray(new.coef[0]) != 0, library)):
                return screened
            support = kept_now
        return screened

    kept = np.zeros(vd.size, bool) if keep is None else np.asarray(keep, bool)  # the low orders (v, x v, ...)

    def shared(fits):
        """Terms some wells kept and others not dropped where kept, those wells refitted, until all agree."""
        gone = []
        while np.any(drop := velocity_terms_not_shared(coef := np.asarray(fits.coef), library)):
            for k in np.nonzero(np.any((coef != 0) & drop[None, :], axis=1))[0]:
                fits = _set_well(fits, k, refit(k, (with_constant(coef[k] != 0, library) | kept) & ~drop,
                                                fits.threshold[k]))
            gone += [k for (_, k), d in zip(library.terms(), drop) if d]
        return fits, gone

    if np.any(velocity_terms_not_shared(coef0, library)):
        union = np.any(coef0 != 0, axis=0) & vd
        masks = [(c != 0) & vd for c in coef0] + [union, np.all(coef0 != 0, axis=0) & vd, np.zeros_like(vd)]
        masks += [np.arange(vd.size) == j for j in np.nonzero(union)[0]]  # one term alone
        sets = {tuple(bool(b) for b in m) for m in masks}
        best = None
        for cand in sorted(sets):
            cand = np.array(cand)
            new_fits = fits
            for k in range(coef0.shape[0]):
                support = with_constant((coef0[k] != 0) & ~vd, library) | cand | kept
                new_fits = _set_well(new_fits, k, refit(k, support, fits.threshold[k], cand))
            new_fits, gone = shared(new_fits)  # each candidate scored on what it leaves once the wells agree
            score = _summed_bic(new_fits)
            if np.isfinite(score) and (best is None or score < best[0]):
                best = (score, new_fits, cand, gone)
        if best is not None:
            fits = best[1]
            dropped += [k for (_, k), d in zip(library.terms(), union & ~best[2]) if d] + best[3]
    fits, gone = shared(fits)
    dropped += gone
    return fits, sorted(set(dropped))


def _refit_on(xs, vs, ys, w, library, solver, fits, k: int, mask, noise=None, x_noise=None, band=None):
    """Well `k` refitted on the support `mask` (at its own threshold, every term of `mask` exempt from it):
    the `fit_local` Solution on the host. `noise`, `x_noise`, `band`: per-well lists, as `_fit_wells` takes
    (None: none at any well)."""
    slv = eqx.tree_at(lambda s: s.threshold, solver, fits.threshold[k])
    at = lambda a: None if a is None else a[k]
    return jax.device_get(fit_local(xs[k], vs[k], ys[k], library, slv, None, weights=w[k], keep=mask, support=mask,
                                    noise=at(noise), x_noise=at(x_noise), band=at(band), throw=False))


def _refit_with(xs, vs, ys, w, library, solver, fits, k: int, support, j: int, noise=None, x_noise=None, band=None,
                fitted=None):
    """Well `k` refitted on the nonzero terms of `support` (a coefficient row) plus term `j` (`_refit_on`): the
    Solution, whether it succeeded, and term j's coefficient and variance. `fitted`: the fits before the t-screen
    (`_screen`), whose restoring terms at well k the refit holds too, for the caller to screen again: the screen
    zeroes a term without a refit, so the others keep the values fitted beside it, and a refit without it moves
    them by its omission (bistable joint, 50 x^2 v, 1 degree, 60 dB, seed 0: q^3 at t < 3 zeroed; refitted
    without it, F' 3.8 of its then standard errors high, the restoring error 0.0024 -> 0.010 %)."""
    mask = with_constant(np.asarray(support) != 0, library)
    mask[j] = True
    if fitted is not None:
        mask |= np.array([phys == STIFFNESS for phys, _ in library.terms()]) & (np.asarray(fitted.coef[k]) != 0)
    sol = _refit_on(xs, vs, ys, w, library, solver, fits, k, mask, noise, x_noise, band)
    ok = int(sol.result._value) == int(RESULTS.successful._value)
    return sol, ok, float(np.asarray(sol.value.coef)[j]), float(np.asarray(sol.value.covariance)[j, j])


def _refit_screened_damping(fits, screened, xs, vs, ys, w, library, solver, n_sigma, dof, failure, noise=None,
                            x_noise=None, band=None, rounds: int = 3):
    """A well where the t-screen zeroed some damping terms and kept others: the kept ones still hold the values
    fitted beside the zeroed ones, which shared the dissipation with them (collinear powers of v), so the law
    left is not the one the data fit. The well is refitted on its screened damping terms and its restoring terms
    as fitted (`_refit_with(fitted=)`: a refit without the restoring terms the screen zeroed moves the others by
    their omission) and screened again, until no damping term falls (at most `rounds` refits). Audit D F8
    (tri-stable quintic, (0.2 + 1400 x^2) v + 2 v^3, 40 dB): the +15 mm well's fit kept v .. v^5 and x v, the
    screen left v at 0.559 +- 0.023 as fitted beside v^2 .. v^5; refitted, 0.5150 +- 0.0013 (truth 0.5150)."""
    damping = np.array([phys != STIFFNESS for phys, _ in library.terms()])
    before = np.asarray(fits.coef)
    for k in range(before.shape[0]):
        after = np.asarray(screened.coef)[k]
        kept = damping & (after != 0)
        if not np.any(damping & (before[k] != 0) & (after == 0)) or not np.any(kept):
            continue
        for _ in range(rounds):
            # the refit's support: `after`'s terms (j is one of them, as `_refit_with` takes it) and the restoring
            # terms as fitted
            j = int(np.flatnonzero(kept)[0])
            sol, ok, _, _ = _refit_with(xs, vs, ys, w, library, solver, fits, k, after, j, noise, x_noise, band,
                                        fitted=fits)
            if not ok:
                failure.note(sol.result, f"DOF {dof}, well {k}: refit on its screened damping terms")
                break
            new = _screen(_as_well(sol.value), n_sigma, library)
            now = damping & (np.asarray(new.coef)[0] != 0)
            if not np.any(now):
                break  # the refit resolves none of them: the screened well as it was
            screened = _set_well(screened, k, new)
            if np.array_equal(now, kept):
                break  # no damping term fell: done
            after, kept = np.asarray(new.coef)[0], now
    return screened


def _one_of_a_group(fits, screened, xs, vs, ys, w, library, solver, n_sigma, dof, failure, noise=None, x_noise=None,
                    band=None):
    """A well whose damping terms the t-screen zeroed all at once, though its fit had some: collinear terms (on a
    single tone every power of v is the fundamental's stand-in) share the dissipation, none alone at `n_sigma`.
    The screen zeroes them without a refit, so the well has no damping and keeps the other coefficients as fitted
    beside them. Each of those terms alone is refitted (the well's other kept terms, exempt from the threshold) and
    the one that leaves the least residual is kept where the refit resolves it; where none does, the screened well
    as it was."""
    damping = np.array([phys != STIFFNESS for phys, _ in library.terms()])
    before, after = np.asarray(fits.coef), np.asarray(screened.coef)
    for k in range(before.shape[0]):
        had = np.nonzero(damping & (before[k] != 0))[0]
        if had.size == 0 or np.any(damping & (after[k] != 0)):
            continue
        best = None
        for j in had:
            sol, ok, c, var = _refit_with(xs, vs, ys, w, library, solver, fits, k, after[k], j, noise, x_noise, band)
            if not ok:
                failure.note(sol.result, f"DOF {dof}, well {k}: refit with one of its damping terms")
                continue
            if var > 0 and abs(c) >= n_sigma * np.sqrt(var) and (best is None or float(sol.value.rss) < best[0]):
                best = (float(sol.value.rss), sol.value)
        if best is not None:
            screened = _set_well(screened, k, _screen(_as_well(best[1]), n_sigma,
                                                      library))
    return screened


def _extend_restoring(fits, xs, vs, ys, w, library, solver, n_sigma, dof, failure, noise=None, x_noise=None,
                      upto: int | None = None, band=None, fill: bool = False):
    """Raise each well's local restoring order while the next Taylor term is significant.

    STLS judges a term by its share of the local force, so a restoring q^(r+1) that the data
    resolve (|t| >= `n_sigma`) can be a tiny share of it and be thresholded away; its omission
    then biases the kept q^(r-1) (q^4 and q^2, q^5 and q^3 are correlated about a well), and the
    coordination takes that bias as exact. Torque-free Kresling chain, deployed well of cell 2,
    1 mm, seed 3: q^4 at t = 59 dropped, q^3 biased by +2.1 % (35 standard errors), restoring
    error 2.75 % against the exact-Taylor oracle's 1.68 %. Each well is refitted on its support plus
    q^(r+1) (at its own threshold, the support kept); the term stays if the refit resolves it,
    and the next order is tried, up to q^`upto` (default: the library's restoring order). `fill`: each order up to
    q^`upto` is added whatever its t (the refit's other terms still screened at `n_sigma`): where the accelerations
    were estimated, each well takes F'' with its estimate and standard error whether or not it resolves it (the
    coordination weighs it by its covariance; a hard zero is a condition the data did not give).
    Returns the fits and, per well, the orders added."""
    idx = library.indices(STIFFNESS)  # q^0 .. q^r, in order
    added = [[] for _ in range(xs.shape[0])]
    for k in range(xs.shape[0]):
        while True:
            coef = np.asarray(fits.coef[k])
            top = max([j for j, c in enumerate(coef[idx]) if c != 0], default=0)
            if top >= (library.restoring_order if upto is None else min(upto, library.restoring_order)):
                break
            sol, ok, c, var = _refit_with(xs, vs, ys, w, library, solver, fits, k, coef, idx[top + 1], noise, x_noise,
                                          band)
            if not ok or not (fill or abs(c) >= n_sigma * np.sqrt(max(var, 0.0))):
                break
            new = _screen(_as_well(sol.value), n_sigma, library, exempt=(np.arange(coef.size) == idx[top + 1]) & fill)
            if float(new.coef[0, idx[top + 1]]) == 0.0:
                break
            fits = _set_well(fits, k, new)
            added[k].append(top + 1)
    return fits, added


def _dissipative_at_rest(fits, xs, vs, ys, w, library, solver, n_sigma, dof, failure, noise=None, x_noise=None,
                         band=None, shared: bool = False):
    """A Coulomb term c_0 sgn(v) with c_0 < 0 feeds energy in at low speed whatever the well's other terms (its
    damping power D v -> c_0 |v| as v -> 0), at every position: no structure's friction does that. A fit that
    selects one has it stand in for what it lacks (an amplitude dependence of the damping it does not resolve):
    bistable joint, damping 50 x^2 v, 1 degree sweeps, 40 dB, seed 1: -0.25 sgn(v) at both wells (t = 7) beside a
    viscous term 1.5-2.3 % high (the q^2 v it stands in for is at t = 1.2-1.8); the global damping was 3.3
    standard errors off at the saddle and its band covered the truth on 0.1 % of the span. Each such well is
    refitted without it (its other kept terms exempt from the threshold, `_refit_on`) and t-screened.
    `shared`: after `_share_velocity_damping` the term is one law for every well, dropped at all of them where it
    is negative at any. Returns the fits and the wells refitted."""
    terms = library.terms()
    if (VELOCITY_DAMPING, 0) not in terms:
        return fits, []
    j = terms.index((VELOCITY_DAMPING, 0))
    coef = np.asarray(fits.coef)
    negative = coef[:, j] < 0
    wells = np.nonzero((coef[:, j] != 0) if shared and negative.any() else negative)[0]
    for k in wells:
        mask = with_constant(coef[k] != 0, library)
        mask[j] = False
        sol = _refit_on(xs, vs, ys, w, library, solver, fits, k, mask, noise, x_noise, band)
        if int(sol.result._value) != int(RESULTS.successful._value):
            failure.note(sol.result, f"DOF {dof}, well {k}: refit without a negative friction term")
            continue
        new = _as_well(sol.value)
        fits = _set_well(fits, k, new if n_sigma is None else _screen(new, n_sigma, library))
    return fits, [int(k) for k in wells]


#: `_extend_damping` keeps a term only where it lowers the summed BIC by more than this ("very strong" evidence on Kass and
#: Raftery's scale). 10 Hz sines, x only, 30 dB, seed 3: v|v| beside the v^3 of both wells, resolved at each but
#: 7.2 better only, a stand-in on one tone (2.49 v|v| + 8.59 v^3 for the truth's 10 v^3, the law 0.17 -> 0.19 %);
#: the shallow arch's v|v| was 186 (30 dB) and 1677 (40 dB) better
EXTEND_DAMPING_EVIDENCE = 10.0


def _extend_damping(fits, xs, vs, ys, w, library, solver, n_sigma, dof, failure, noise=None, x_noise=None,
                    band=None):
    """A position-independent damping term sgn(v)|v|^j (j != 1) that no well selected, yet every well resolves.

    STLS judges a term by its share of the local force, and an amplitude dependence of the damping is a tiny
    share of it at small vibrations, so the threshold drops it; `keep_low_orders` exempts only v and x v. Each
    such term is tried at every well (refitted on the well's support plus the term, `_refit_on`, and t-screened);
    it is a candidate where every well resolves it with the dissipative sign (coefficient >= `n_sigma` standard
    errors above 0), and the candidate that lowers the BIC summed over the wells most (n log(rss / n) + p log n),
    by more than `EXTEND_DAMPING_EVIDENCE`, is kept at all of them (one law for every well, Eq. 21). Shallow
    arch (0.18 v + 0.05 v|v|), 0.05 sweeps, 40 dB, seed 1: v|v| at t = 35 / 24 at the wells, dropped; kept, 0.181 v
    + 0.0488 v|v| and the damping band's coverage 53 -> 100 % (30 dB: 35 -> 100 %); v^3 and higher powers also
    resolve, 64 worse. On single tones the
    powers of v are collinear: a term that resolves there stands in for another unless the evidence is strong.
    Returns the fits and the orders j added."""
    terms = library.terms()
    coef0 = np.asarray(fits.coef)
    best = (_summed_bic(fits) - EXTEND_DAMPING_EVIDENCE, None, None)
    for j, (phys, order) in enumerate(terms):
        if phys != VELOCITY_DAMPING or order == 1 or np.any(coef0[:, j] != 0):
            continue
        new_fits = fits
        for k in range(coef0.shape[0]):
            sol, ok, c, var = _refit_with(xs, vs, ys, w, library, solver, fits, k, coef0[k], j, noise, x_noise, band)
            if not ok or not (var > 0 and c >= n_sigma * np.sqrt(var)):
                new_fits = None
                break
            new = _screen(_as_well(sol.value), n_sigma, library)
            if float(new.coef[0, j]) == 0.0:
                new_fits = None
                break
            new_fits = _set_well(new_fits, k, new)
        if new_fits is not None and (score := _summed_bic(new_fits)) < best[0]:
            best = (score, new_fits, order)
    if best[1] is None:
        return fits, []
    return best[1], [int(best[2])]


def _extend_position_damping(fits, xs, vs, ys, w, library, solver, n_sigma, dof, failure, noise=None, x_noise=None,
                             band=None, fitted=None):
    """Raise each well's position-damping order (q^j v) while the next term is significant, as `_extend_restoring`
    does the restoring order.

    STLS judges a term by its share of the local force, and the damping's curvature q^2 v is a tiny share of it
    at small vibrations, so the threshold drops it; its omission biases the kept v (about E[q^2] times it), which
    the coordination takes as the damping's value at the well. 3-cell Kresling chain, 0.3 mm sweeps, 60 dB, seed
    0, cell 2: q^2 v at t = 10.5 and 13.3 at the wells, dropped; the viscous value 6e-5 (8 standard errors) high
    at both, and the damping band held the truth on 85 % of the span. The next order q^(j+1) v is tried at every
    well that keeps a damping term (refitted on its support plus the term, `_refit_with`, beside the restoring
    terms the t-screen zeroed, `fitted`; the support kept) and kept where every such well resolves it (|t| >=
    `n_sigma`), as `_extend_damping` keeps a velocity term; then the next order, up to the library's damping
    order. At all wells or none: a damping curvature at one well only made the interpolant of the others' value
    and slope a quartic (5-cell Kresling, 1 mm, 60 dB, seed 4, cell 3: 14 % off mid-span, basin agreement 98.7 ->
    90.9 %). Returns the fits and, per well, the orders added."""
    terms = library.terms()
    idx = [terms.index((POSITION_DAMPING, j)) if (POSITION_DAMPING, j) in terms else None
           for j in range(1, library.damping_order + 1)]
    damping = np.array([phys != STIFFNESS for phys, _ in terms])
    added = [[] for _ in range(xs.shape[0])]
    if n_sigma is None or not idx or idx[0] is None:
        return fits, added
    while True:
        coef = np.asarray(fits.coef)
        wells = [k for k in range(coef.shape[0]) if np.any(coef[k, damping] != 0)]
        if not wells:
            break
        tops = {k: max([j + 1 for j, i in enumerate(idx) if i is not None and coef[k, i] != 0], default=0)
                for k in wells}
        order = min(tops.values())  # the next order (0-based index into idx) the wells that lack it try
        if order >= len(idx) or idx[order] is None:
            break
        new_fits, tried = fits, []
        for k in wells:
            if tops[k] > order:
                continue
            kept = with_constant(coef[k] != 0, library)
            kept[idx[order]] = True
            sol, ok, c, var = _refit_with(xs, vs, ys, w, library, solver, fits, k, coef[k], idx[order], noise,
                                          x_noise, band, fitted)
            if not ok or not (var > 0 and abs(c) >= n_sigma * np.sqrt(var)):
                new_fits = None
                break
            new_fits = _set_well(new_fits, k, _screen(_as_well(sol.value), n_sigma, library, exempt=kept))
            tried.append(k)
        if new_fits is None:
            break
        fits = new_fits
        for k in tried:
            added[k].append(order + 1)
    return fits, added
