"""Cells of one design share their law between the wells (issue 15; after `_shape_prior`, which
shares the local Taylor ratios at the wells).

The ratios a weakly excited cell borrows fix its law at its wells; between them its coordination
interpolates, and its band is widest there (torque-free 5-cell Kresling, 1 mm, seed 4, cell 3:
4.7 % off, rms standard deviation 2 % of F'(w_0) L between the wells). The other cells of the
design measured that same shape: the base cell, whose records cross between the wells, to 0.06 %.
With one design, F_j(x) = s_j G((x - w_j0) / L_j): w_j0 the first stable well of cell j's law,
L_j the distance to its last, s_j = F_j'(w_j0) L_j. So each cell's normalised law at interior
nodes u_k, g_j(u_k) = F_j(w_j0 + u_k L_j) / s_j, observes G(u_k) with the covariance its
calibrated band gives (`GlobalModel.covariance`).

The rule (`pool_design_laws`):

1. Members: the DOFs whose laws have the same number of stable wells at the same relative
   positions (`_shape_prior.POSITION_TOL`).
2. The design spread: the relative scatter of the members' node values beyond their noise (a
   pooled DerSimonian-Laird moment estimate, as `_shape_prior._tau`). Above `TAU_MAX` nothing is
   pooled. The spread used is max(tau, `TAU_FLOOR`): each cell deviates from G by a smooth random
   function of that relative size (squared-exponential in u, length `LENGTH`), so that nodes
   close together do not count as independent evidence.
3. For each member, the others' node values combine (generalised least squares, each with its
   own covariance plus the spread) into a prior on its own, which then carries the spread once
   more (its own deviation from G). A cell whose values reject that prior (chi-squared over the
   nodes, p < `P_CONFLICT`) leaves the design, the worst first.
4. Each member's law is conditioned on its prior (the Gaussian conditional of its coefficients,
   damping included through their covariance): the law moves within its own covariance, so what
   its data fix (at and near its wells) stays, and the band narrows where the prior is tighter.
   The mean moves on the law's own terms only (its nonzero coefficients: it keeps its degree),
   and a law the update would make inadmissible (`_joint.restoring_faults`) is left as it was.
   The priors are all computed from the laws before any update.

Reported per DOF in `dofs[i].stats["shared_design"]["law"]`: the members, tau, the chi-squared of
its values against the prior and the rms standard deviation over the nodes before and after.
"""

import jax.scipy.special as jsp
import numpy as np

from .._coordination._joint import restoring_fault_details, restoring_fault_kinds
from ._shape_prior import P_CONFLICT, POSITION_TOL, TAU_FLOOR, TAU_MAX, relative_tau

#: Interior (and just-outside) nodes in u = (x - w_0) / L where the laws are compared and pooled.
NODES = np.array([-0.15, 0.1, 0.3, 0.5, 0.7, 0.9, 1.15])
#: Correlation length, in u, of a cell's smooth deviation from the design.
LENGTH = 0.25


def stable_wells(stiffness: np.ndarray, region) -> np.ndarray:
    """The stable real zeros of the restoring polynomial (ascending coefficients) within `region`
    (the fitted equilibria, or the recorded range, as values) widened by half its span on each side,
    ascending."""
    p = np.polynomial.Polynomial(np.trim_zeros(np.asarray(stiffness, float), "b") if np.any(stiffness) else [0.0])
    eq = np.asarray(region, float)
    span = float(eq.max() - eq.min()) if eq.size > 1 else 1.0
    if p.degree() < 1:
        return np.zeros(0)
    r = p.roots()
    r = np.real(r[np.abs(np.imag(r)) <= 1e-9 * max(span, 1e-300)])
    r = r[(r >= eq.min() - 0.5 * span) & (r <= eq.max() + 0.5 * span)]
    return np.sort(r[p.deriv()(r) > 0])


def _normalised(stiffness, cov_r, wells):
    """Node values g = F(w_0 + u L) / s, their covariance, and the map from the restoring
    coefficients to them (the normalisation's own uncertainty left out: wells and slope are the
    best-determined quantities of a law)."""
    a = np.asarray(stiffness, float)
    w0, length = float(wells[0]), float(wells[-1] - wells[0])
    scale = float(np.polynomial.Polynomial(a).deriv()(w0)) * length
    v = np.vander(w0 + NODES * length, a.size, increasing=True) / scale
    return v @ a, v @ cov_r @ v.T, v


def _spread(tau: float, level: float) -> np.ndarray:
    """Covariance of a cell's smooth relative deviation from the design over the nodes."""
    du = NODES[:, None] - NODES[None, :]
    return (tau * level) ** 2 * (np.exp(-0.5 * (du / LENGTH) ** 2) + 1e-9 * np.eye(NODES.size))


def _tau(values: dict) -> float | None:
    """Pooled relative spread of the members' node values beyond their noise (`relative_tau` over
    the nodes); None for fewer than 2 members."""
    if len(values) < 2:
        return None
    return relative_tau([(g[k], c[k, k]) for g, c in values.values()] for k in range(NODES.size))


def _prior(values: dict, j: int, members: list, tau: float, level: float):
    """The others' node values combined into a prior on member j's (GLS), with the spread of
    j's own deviation added."""
    t = _spread(tau, level)
    prec, rhs = 0.0, 0.0
    for i in members:
        if i == j:
            continue
        g, c = values[i]
        inv = np.linalg.inv(c + t)
        prec, rhs = prec + inv, rhs + inv @ g
    cov = np.linalg.inv(prec)
    return cov @ rhs, cov + t


def _chi2_p(values, j, members, tau, level):
    mean, cov = _prior(values, j, members, tau, level)
    g, c = values[j]
    r = g - mean
    chi2 = float(r @ np.linalg.solve(c + cov, r))
    return chi2, float(jsp.gammaincc(NODES.size / 2, chi2 / 2))


def pool_design_laws(flats: list, n_restoring: list, covariances: list, regions: list, noise: list | None = None):
    """The rule of the module docstring for the DOFs of one chain.

    **Arguments:** per DOF, its flat coefficients (`GlobalCoefficients.flat`: the restoring
    polynomial's ascending monomials first, `n_restoring` of them, then the damping), their
    calibrated covariance, and where its wells are looked for (`stable_wells`: the recorded range
    of x, which a record that crosses between the wells widens past its mean).

    `noise`: per DOF, its covariance less the part that is systematic (its restoring law's embedded error,
    `_reconstruct._systematic`; None: all of it counts). Cells of one design interpolated alike from the same
    Taylor orders err alike, so their agreement says nothing of that error: the pooled covariance keeps it whole
    and conditions the rest on the others' prior (audit: a 3-cell chain of tanh-law cells, 60 dB; two cells' laws
    17 and 28 % off agreed with each other to 0.2 %, and pooled on their whole covariances the bands fell from
    +-54 / 109 % to +-3.5 %, the truth inside on 16-30 % of the span). The means move as before.

    **Returns:** `(flats, covariances, summary)`: the updated lists (unchanged where a DOF was not
    pooled; the damping moves only through its covariance with the restoring law) and `summary`
    (`members`, `tau`, `excluded` {dof: reason}, `per_dof` {dof: {"chi2", "nodes", "p",
    "sd_before", "sd_after"}}; sd: rms standard deviation of the node values, relative to
    s = F'(w_0) L).
    """
    d = len(flats)
    summary = {"members": [], "tau": None, "excluded": {}, "per_dof": {}}
    flats = [np.asarray(a, float) for a in flats]
    stiffness = [f[:n] for f, n in zip(flats, n_restoring)]
    covariances = [np.asarray(c, float) for c in covariances]
    if d < 2:
        return flats, covariances, summary
    wells = [stable_wells(a, e) for a, e in zip(stiffness, regions)]
    n_wells = max((w.size for w in wells), key=lambda n: sum(w.size == n for w in wells))
    values, maps, ref = {}, {}, None
    for j in range(d):
        w, ns = wells[j], stiffness[j].size
        if w.size != n_wells or n_wells < 2 or not np.all(np.isfinite(covariances[j][:ns, :ns])):
            summary["excluded"][j] = f"its law has {w.size} stable wells (the others {n_wells})"
            continue
        u = (w - w[0]) / (w[-1] - w[0])
        if ref is None:
            ref = u
        elif np.max(np.abs(u - ref)) > POSITION_TOL:
            summary["excluded"][j] = "its wells lie at other relative positions"
            continue
        g, c, v = _normalised(stiffness[j], covariances[j][:ns, :ns], w)
        if not (np.all(np.isfinite(g)) and np.all(np.isfinite(c))):
            summary["excluded"][j] = "its law is not finite at the nodes"
            continue
        values[j], maps[j] = (g, c), v
    members = sorted(values)
    if len(members) < 2:
        return flats, covariances, summary
    level = float(np.sqrt(np.mean(np.concatenate([values[j][0] for j in members]) ** 2)))
    while len(members) >= 3:  # a cell whose law rejects the others' leaves (the worst first)
        tau = max(_tau({j: values[j] for j in members}) or 0.0, TAU_FLOOR)
        ps = {j: _chi2_p(values, j, members, tau, level)[1] for j in members}
        worst = min(ps, key=ps.get)
        if ps[worst] >= P_CONFLICT:
            break
        summary["excluded"][worst] = f"its law between the wells disagrees with the others' (p = {ps[worst]:.2g})"
        members.remove(worst)
    tau_est = _tau({j: values[j] for j in members})
    summary["tau"], summary["members"] = tau_est, members
    if tau_est is None or tau_est > TAU_MAX:
        why = "no spread estimate" if tau_est is None else f"the cells' laws differ by {100 * tau_est:.3g} %"
        for j in members:
            summary["excluded"].setdefault(j, why)
        summary["members"] = []
        return flats, covariances, summary
    tau = max(tau_est, TAU_FLOOR)
    if len(members) == 2:  # no third cell to arbitrate: the pair must agree
        chi2, p = _chi2_p(values, members[0], members, tau, level)
        if p < P_CONFLICT:
            for j in members:
                summary["excluded"][j] = f"the two cells' laws disagree between the wells (p = {p:.2g})"
            summary["members"] = []
            return flats, covariances, summary
    priors = {j: _prior(values, j, members, tau, level) for j in members}
    out_f, out_c = list(flats), list(covariances)
    for j in members:
        mean, cov_p = priors[j]
        g, c = values[j]
        ns = stiffness[j].size
        # the update acts on the law's own terms (its nonzero coefficients): the law keeps its
        # degree and its terms, while its covariance is conditioned whole (the band narrows)
        own = flats[j] != 0
        # every restoring power up to the highest odd one that is the law's or has a variance
        free = np.nonzero((flats[j][:ns] != 0) | (np.diag(covariances[j])[:ns] > 0))[0]
        odd = [k for k in free if k % 2 == 1]
        if odd:
            own[: max(odd) + 1] = True
        h = np.zeros((NODES.size, covariances[j].shape[0]))
        h[:, :ns] = maps[j]
        h[:, ~own] = 0.0
        innov = covariances[j] @ h.T
        s = h @ innov + cov_p
        gain = np.linalg.solve(s, innov.T).T
        resid = mean - g
        new = flats[j] + np.where(own, gain @ resid, 0.0)
        nz = None if noise is None or noise[j] is None else np.asarray(noise[j], float)
        if nz is None or nz.shape != covariances[j].shape:
            new_cov = covariances[j] - gain @ innov.T
        else:  # the systematic part kept whole, the rest conditioned on the same prior
            innov_n = nz @ h.T
            new_cov = covariances[j] - np.linalg.solve(h @ innov_n + cov_p, innov_n.T).T @ innov_n.T
        new_cov = 0.5 * (new_cov + new_cov.T)
        chi2 = float(resid @ np.linalg.solve(s, resid))
        # the pooled law must not lose admissibility it had (a leading term's sign, a sign change): compared
        # by kind, not by message (a law that already turned outward keeps its own, other, leading term)
        before, after_k = restoring_fault_kinds(flats[j][:ns], wells[j]), restoring_fault_kinds(new[:ns], wells[j])
        need = 2 * wells[j].size - 1
        lost = [k for k, n in after_k.items()
                if k not in before or (k == "sign" and abs(n - need) > abs(before[k] - need))]
        if lost:
            summary["excluded"][j] = "pooled, its law would not be admissible: " + "; ".join(
                m for k, _, m in restoring_fault_details(new[:ns], wells[j]) if k in lost)
            continue
        out_f[j] = new
        out_c[j] = new_cov
        after = maps[j] @ new_cov[:ns, :ns] @ maps[j].T
        summary["per_dof"][j] = {"chi2": chi2, "nodes": int(NODES.size),
                                 "p": float(jsp.gammaincc(NODES.size / 2, chi2 / 2)),
                                 "sd_before": float(np.sqrt(np.mean(np.diag(c)))),
                                 "sd_after": float(np.sqrt(np.mean(np.clip(np.diag(after), 0.0, None))))}
    return out_f, out_c, summary


__all__ = ["pool_design_laws", "stable_wells"]
