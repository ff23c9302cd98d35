"""How one DOF's global restoring degree is chosen beyond the chi-squared test of `hermite_gls`
(issue 15): an even paper-route degree gives way to an odd one (`odd_degree`), a borrowed law
that turns outward within the energy bound is lowered (`confine_borrowed`), and a borrowed law
is averaged with the lower odd degree of least estimated risk over the span (`least_risk_degree`). Rules of
`_reconstruct`'s auto coordination; NumPy on `coordinate` Solutions."""

import jax
import jax.numpy as jnp
import numpy as np

from .._coordination._coordinate import coordinate
from .._coordination._joint import restoring_faults
from .._fit._library import Library
from .._fit._local_fit import LocalFit
from .._solution import RESULTS, Solution
from . import _sanity


def redundancy(coord: Solution) -> int:
    """How many local Taylor conditions the paper route's restoring law does not need (the
    chi-squared test's degrees of freedom of `hermite_gls`): 0 for the exact interpolant, whose
    shape away from the wells no datum tests."""
    return int(np.asarray(coord.stats.get("dof_r", 0)))


def degree(stiffness) -> int:
    """The degree of a restoring law (ascending coefficients, trailing zeros dropped); -1 for 0."""
    return np.trim_zeros(np.asarray(stiffness, float), "b").size - 1


def odd_gls(fits: LocalFit, library: Library, max_degree: int | None = None) -> Solution | None:
    """The GLS coordination restricted to odd restoring degrees (`coordinate` with `confining=True`,
    at most `max_degree`), or None where it failed or is not finite."""
    bound = None if max_degree is None else jnp.asarray(max_degree)
    alt = jax.device_get(coordinate(fits, library, method="gls", confining=True, max_degree=bound, throw=False))
    if alt.result != RESULTS.successful or not np.all(np.isfinite(np.asarray(alt.value.flat()))):
        return None
    return alt


def admissible(stiffness, equilibria, energy: float) -> bool:
    """No spurious sign change over the span (`restoring_faults`) and no escape within the energy
    bound (`_sanity.reachable_escapes`): what a replacement degree must satisfy."""
    stiffness, equilibria = np.asarray(stiffness, float), np.asarray(equilibria)
    return not (any("changes sign" in f for f in restoring_faults(stiffness, equilibria))
                or _sanity.reachable_escapes(stiffness, equilibria, energy))


#: `odd_degree`: the odd-degree GLS replaces an even paper route unless its local conditions reject it
#: at this level (bistable joint, 1 degree, 40 dB, seed 1: a spurious q^5 at one well, p = 1e-4, the joint
#: regression 0.0004 %, the quintic 3 %; Kresling 1 mm seed 3 cell 4: p = 0.0096, the quintic 1.29 %,
#: the joint 5.9 %).
ODD_DEGREE_MIN_P = 1e-3


def odd_degree(paper: Solution, fits: LocalFit, library: Library, energy: float) -> Solution | None:
    """Where the paper route's restoring law has even degree (a term resolved at some wells only:
    its exact interpolant cannot confine), the GLS restricted to odd degrees (`coordinate` with
    `confining=True`: the highest odd degree below it, fitted to all the local conditions) if that
    one has no spurious sign change over the span, no escape within the model's energy bound
    `energy` (the criterion on which the paper route itself is kept) and its local conditions do
    not reject it (chi-squared p >= `ODD_DEGREE_MIN_P`); else None (the joint regression decides). Kresling chain, 1 mm, seed 3, cell 4 (F''' resolved at the
    deployed well only): the exact sextic 6.55 % off, the quintic 1.29 %."""
    k = degree(paper.value.stiffness)
    if k % 2 == 1 or k < 1:
        return None
    alt = odd_gls(fits, library)
    if alt is None or not admissible(alt.value.stiffness, fits.equilibrium, energy):
        return None
    if float(alt.stats["dof_r"]) > 0 and not float(alt.stats["p_r"]) >= ODD_DEGREE_MIN_P:
        return None
    return alt


def confine_borrowed(coord: Solution, fits: LocalFit, library: Library, energy: float):
    """A DOF whose local fits borrowed orders (`_shape_prior`) and whose restoring law turns
    outward within the model's energy bound `energy` (an escape with a lower barrier): the next
    lower odd degree, fitted to all the local conditions (`coordinate(max_degree=...)`), until one
    confines within that bound; if none does, the law as it was. Torque-free Kresling chain, 0.5 mm,
    seed 0: the nonics of cells 1-4 turned outward 0.3-0.43 spans below the folded well (barriers
    below the energy differences inside the range); the septics confine and are 0.6-1.6 % off the
    truth, against 1.0-2.3 % for the nonics. Returns `(coord, notes)`; a lowered law carries its
    bound in `stats["max_degree_r"]` (the covariance calibration uses the same choice)."""
    eq = np.asarray(fits.equilibrium)
    first, notes = coord, []
    reach = _sanity.reachable_escapes(coord.value.stiffness, eq, energy)
    while reach and int(coord.stats["K_r"]) > 2 * eq.size - 1:
        deg = int(coord.stats["K_r"])
        cap = deg - 1 if deg % 2 == 0 else deg - 2
        alt = odd_gls(fits, library, cap)
        if alt is None:
            break
        notes.append(f"the borrowed law of degree {deg} turns outward at x = {reach[0]['x']:.4g} with a barrier "
                     f"({reach[0]['barrier']:.3g}) within the energy bound ({energy:.3g}): degree "
                     f"{int(alt.stats['K_r'])} fitted to all the local conditions instead")
        alt.stats["max_degree_r"] = cap
        coord = alt
        reach = _sanity.reachable_escapes(coord.value.stiffness, eq, energy)
    if reach:  # no lower degree confines: the law as it was (its warning follows)
        return first, []
    return coord, notes


def span_curve(sol: Solution, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A restoring law's values on `x` and their variance from its propagated covariance (`aux`)."""
    stiff = np.asarray(sol.value.stiffness, float)
    basis = x[:, None] ** np.arange(stiff.size)
    cov = np.asarray(sol.aux, float)[: stiff.size, : stiff.size]
    return basis @ stiff, np.einsum("ij,jk,ik->i", basis, cov, basis)


#: `least_risk_degree`: a weight this close to 0 or 1 takes one law (the average would move it by less
#: than this share of the two laws' difference).
MIN_WEIGHT = 0.01


def least_risk_degree(coord: Solution, fits: LocalFit, library: Library, energy: float):
    """A DOF that borrowed orders (`_shape_prior`): its restoring law averaged with the lower
    odd-degree GLS law of least estimated risk over the span (the wells widened by a tenth of
    their span), the weight minimising the estimated risk of the average (Mallows model
    averaging, Hansen 2007), not the highest degree the chi-squared test accepts. Part of the
    local conditions are then a prior whose error is the donors', and the exact interpolant
    amplifies it: torque-free Kresling chain, 1 mm, seed 4, the donors' q^4 at the deployed well
    is 3.6 % off the truth (two of its standard errors: noise, not truncation; continuing the
    donors' series with the true q^6.. moves it by < 0.1 %) and the exact nonics of cells 3-5
    are 2.5-7.1 % off, while the septics the test rejects (p = 6e-5..2e-3) are 0.5-1.2 % off.

    The lower degree k is the GLS projection of the chosen law K onto degree k, so over the span
    E[(F_k - F_K)^2] = bias_k^2 + var F_K - var F_k, bias_k^2 + var F_k (its risk) is estimated
    without bias by (F_k - F_K)^2 - var F_K + 2 var F_k (Mallows' C_p on the law's values) and
    F_K's risk is var F_K; cov(F_k, F_K) = var F_k (the identity of nested GLS laws, exact: the
    weights are the conditions' inverse covariance). The average (1 - w) F_K + w F_k has
    the estimated risk (1 - w)^2 var F_K + 2 w (1 - w) var F_k + w^2 C_p(k), least at
    w = (var F_K - var F_k) / mean (F_k - F_K)^2, clipped to [0, 1] (within `MIN_WEIGHT` of 0 or
    1: one law). Picking the least C_p instead
    decides by chance where two estimates lie within their noise (seed 4 cell 4: nonic 0.93 %,
    septic 0.98 % of the force scale, standard error 4.4e-3). Candidates and the average must be
    admissible as `confine_borrowed` demands (`admissible`); an inadmissible average gives the
    least-C_p law. Returns `(coord, notes)`: a lower law carries its bound in
    `stats["max_degree_r"]`; an average carries `stats["averaged_weight"]` (w) and
    `stats["averaged_degree"]` (k), and as `aux` the mixture covariance (`averaged_parts`)."""
    eq = np.asarray(fits.equilibrium, float)
    span = float(eq.max() - eq.min())
    x = np.linspace(eq.min() - 0.1 * span, eq.max() + 0.1 * span, 201)
    f_top, v_top = span_curve(coord, x)
    top_risk = float(np.mean(v_top))
    low, low_risk, low_curve = None, np.inf, None
    top = int(coord.stats["K_r"])
    for k in range(top - 2, 2 * eq.size - 2, -2):
        alt = odd_gls(fits, library, k)
        if alt is None or not admissible(alt.value.stiffness, eq, energy):
            continue
        f_k, v_k = span_curve(alt, x)
        risk = float(np.mean((f_k - f_top) ** 2 + 2.0 * v_k - v_top))
        if risk < low_risk:
            alt.stats["max_degree_r"] = k
            low, low_risk, low_curve = alt, risk, (f_k, v_k)
    if low is None:
        return coord, []
    d2 = float(np.mean((low_curve[0] - f_top) ** 2))
    weight = float(np.clip((top_risk - float(np.mean(low_curve[1]))) / d2, 0.0, 1.0)) if d2 > 0 else 1.0
    scale = float(np.max(np.abs(f_top)))

    def pct(risk):  # the unbiased estimate can fall below 0
        return f"{100 * np.sqrt(risk) / scale:.2g} %" if risk > 0 else "within the estimate's noise of 0"

    k = int(low.stats["K_r"])
    if weight >= 1.0 - MIN_WEIGHT or weight <= MIN_WEIGHT:
        best, best_risk = (low, low_risk) if weight > 0.5 else (coord, top_risk)
    else:
        best = average(coord, low, weight)
        best_risk = ((1 - weight) ** 2 * top_risk + 2 * weight * (1 - weight) * float(np.mean(low_curve[1]))
                     + weight**2 * low_risk)
        if not admissible(best.value.stiffness, eq, energy):  # the least-C_p law instead
            best, best_risk = (low, low_risk) if low_risk < top_risk else (coord, top_risk)
    if best is coord:
        return coord, []
    if best is low:
        note = f"degree {k} instead of {top}"
    else:
        note = f"degree {top} averaged with degree {k} (weight {weight:.2f} on degree {k})"
    why = (f"{note}: its estimated rms error over the span is lower ({pct(best_risk)} against {pct(top_risk)} "
           f"of the force scale: the exact degree {top} passes the borrowed orders' error on, amplified)")
    return best, [why]


def average(top: Solution, low: Solution, weight: float) -> Solution:
    """(1 - w) `top` + w `low` (`least_risk_degree`): the coefficients averaged and, as `aux`, the
    mixture covariance of the two nested GLS laws
    (1 - w)^2 C_top + (1 - (1 - w)^2) C_low + w (1 - w) d d', d the difference of their
    coefficients (the spread between the two laws, a discrepancy of the degree choice). It takes
    cov(low, top) = C_low, the identity of nested GLS laws, which holds exactly for a fixed degree
    (`test_the_average_of_two_nested_laws_has_the_mixture_covariance` checks it from the laws'
    Jacobians), so the propagated part is the average's covariance."""
    w = float(weight)
    value = jax.tree.map(lambda a, b: (1 - w) * np.asarray(a) + w * np.asarray(b), top.value, low.value)
    stats = dict(top.stats) | {"averaged_weight": w, "averaged_degree": int(low.stats["K_r"])}
    return Solution(value=value, result=top.result, stats=stats, aux=mixture(top, low, w))


def mixture(top: Solution, low: Solution, weight: float, covariances=None) -> np.ndarray:
    """The covariance of `average`'s law from its parts' `covariances` (C_top, C_low): their
    propagated ones (`aux`, the default) or calibrated ones."""
    w = float(weight)
    c_top, c_low = (np.asarray(c, float) for c in (covariances or (top.aux, low.aux)))
    diff = np.asarray(low.value.flat(), float) - np.asarray(top.value.flat(), float)
    return (1 - w) ** 2 * c_top + (1 - (1 - w) ** 2) * c_low + w * (1 - w) * np.outer(diff, diff)


def averaged_parts(coord: Solution, fits: LocalFit, library: Library):
    """The two laws of an average (`least_risk_degree`), recomputed: `[(top, cap), (low, cap)]`,
    each with the degree bound its calibration takes (`calibrate_covariance(max_degree=...)`)."""
    cap = coord.stats.get("max_degree_r")
    k = int(coord.stats["averaged_degree"])
    top, low = odd_gls(fits, library, None if cap is None else int(cap)), odd_gls(fits, library, k)
    if top is None or low is None:
        return None
    return [(top, cap), (low, k)]
