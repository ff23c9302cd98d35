"""How one DOF's global restoring degree is chosen beyond the chi-squared test of `hermite_gls`
(issue 15): an even paper-route degree gives way to an odd one (`odd_degree`), a borrowed law
that turns outward within the energy bound is lowered (`confine_borrowed`), and a borrowed law
takes the odd degree of least estimated risk over the span (`least_risk_degree`). Rules of
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


def least_risk_degree(coord: Solution, fits: LocalFit, library: Library, energy: float):
    """A DOF that borrowed orders (`_shape_prior`): among its odd-degree GLS laws, the one of least
    estimated mean squared error over the span (the wells widened by a tenth of their span), not
    the lowest degree the chi-squared test accepts. Part of the local conditions are then a prior
    whose error is the donors' (truncation bias included), and the exact interpolant amplifies
    it: torque-free Kresling chain, 1 mm, seed 4, the borrowed q^4 is 3-4 % off the truth and the
    exact nonics of cells 3-5 are 2.5-7.1 % off, while the septics the test rejects
    (p = 6e-5..2e-3) are 0.5-1.2 % off.

    The lower degree k is the GLS projection of the chosen law K onto degree k, so over the span
    E[(F_k - F_K)^2] = bias_k^2 + var F_K - var F_k, and bias_k^2 + var F_k (its risk) is
    estimated without bias by (F_k - F_K)^2 - var F_K + 2 var F_k (Mallows' C_p on the law's
    values); F_K's risk is var F_K. Candidates must be admissible as `confine_borrowed` demands
    (`admissible`). Returns `(coord, notes)`;
    a lower law carries its bound in `stats["max_degree_r"]`."""
    eq = np.asarray(fits.equilibrium, float)
    span = float(eq.max() - eq.min())
    x = np.linspace(eq.min() - 0.1 * span, eq.max() + 0.1 * span, 201)
    f_top, v_top = span_curve(coord, x)
    best, best_risk, notes = coord, float(np.mean(v_top)), []
    top = int(coord.stats["K_r"])
    for k in range(top - 2, 2 * eq.size - 2, -2):
        alt = odd_gls(fits, library, k)
        if alt is None or not admissible(alt.value.stiffness, eq, energy):
            continue
        f_k, v_k = span_curve(alt, x)
        risk = float(np.mean((f_k - f_top) ** 2 + 2.0 * v_k - v_top))
        if risk < best_risk:
            alt.stats["max_degree_r"] = k
            best, best_risk = alt, risk
    if best is not coord:
        scale = float(np.max(np.abs(f_top)))
        low = (f"{100 * np.sqrt(best_risk) / scale:.2g} %" if best_risk > 0
               else "within the estimate's noise of 0")  # the unbiased estimate can fall below 0
        notes.append(f"degree {int(best.stats['K_r'])} instead of {top}: its estimated rms error over the span is "
                     f"lower ({low} against {100 * np.sqrt(float(np.mean(v_top))) / scale:.2g} % of the force "
                     f"scale: the exact degree {top} passes the borrowed orders' error on, amplified)")
    return best, notes
