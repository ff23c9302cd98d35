"""Cells of one design: the well-excited cells of a chain lend their curvature to the weakly
excited ones (issue 15; beyond the paper's per-DOF coordination, Eqs. 15-18).

In a base-excited chain the cells far from the drive barely move: their local fits resolve F
and F' at each well, sometimes F'', rarely F'''. The coordination (Eq. 18) then builds a
low-degree interpolant that cannot follow the force between the wells (5-cell Kresling chain,
torque-free twist: the tip cell's quintic from F, F', F'' is 33 % off; with F''' at both wells
the interpolant is 1.7 % off). Yet the cells of a chain are often one design: one pattern and
geometry, scaled in stiffness. Then their restoring forces have one shape,

    F_j(x) ≈ s_j G((x - x_j0) / L_j),   L_j = span of cell j's wells,

and the dimensionless Taylor ratios at each well, rho_jkm = a_jkm L_j^(m-1) / a_jk1 (a_jkm the
local q^m coefficient of cell j at well k), and the stiffness ratios between wells,
kappa_jk = a_jk1 / a_j01, are the same for every cell.

The rule (`share_curvature`), all from the local fits:

1. Comparable cells: two or more wells each, the same number, at the same relative positions.
2. How far the cells are one design: every ratio that two or more cells resolve (each cell's
   kappa, each rho it resolves) is compared across cells; the relative spread beyond the noise
   (a pooled DerSimonian-Laird moment estimate, `tau`) is the cell-to-cell difference of
   design. Cells whose own ratios disagree with the others' (chi-squared, p < `P_CONFLICT`)
   neither lend nor borrow.
3. Where `tau` <= `TAU_MAX`, every well of every cell takes the orders 2, 3, ... that other
   cells resolve there (contiguous, up to the library's) as a Gaussian prior on its own
   regression, a_km - rho_km a_k1 / L^(m-1) = 0: rho_km the other cells' random-effects mean,
   its standard deviation from their standard errors and max(tau, `TAU_FLOOR`). The well is
   refitted on its own raw data with that prior (`refit_with_prior`): where it resolves a term
   itself, its estimate and the prior combine by their precisions; its value and slope stay its
   own; the covariance carries the prior's uncertainty into the coordination and the model's
   band. The coordination of a cell that borrowed takes odd degrees only (`hermite_gls`,
   confining): borrowed orders 4 and 5 made exact interpolants of even degree 10, 8-19 % off.

The report (per DOF) says which orders were borrowed at which well, from which cells, the
estimated `tau`, and the cells left out with the reason.
"""

import jax.numpy as jnp
import jax.scipy.special as jsp
import numpy as np

from .._fit._errors_in_variables import compressed_problem
from .._fit._stls import compress
from .._fit._library import STIFFNESS, Library
from .._fit._local_fit import with_constant
from .._trace_cache import disk_traced

_compressed = disk_traced(compressed_problem)  # called outside jit: one compiled program

#: Wells at the same relative position: |u_jk - u_0k| below this (u = (x - x_0) / L).
POSITION_TOL = 0.05
#: Share only while the cells' designs differ by at most this (relative, `tau`).
TAU_MAX = 0.10
#: The prior's relative standard deviation is at least this (a design tolerance the comparisons
#: cannot exclude at their noise).
TAU_FLOOR = 0.02
#: A cell whose resolved ratios reject the others' at this level neither lends nor borrows.
P_CONFLICT = 1e-3


def _ratios(coef, cov, eq, idx, n_sigma):
    """Per well: {order m: (rho, var)} for the resolved q^m, m >= 2, and the stiffness ratio
    kappa_k = a_k1 / a_01 with its variance, by the delta method."""
    n = coef.shape[0]
    span = float(eq[-1] - eq[0])
    out = []
    for k in range(n):
        c1, v1 = coef[k, idx[1]], cov[k, idx[1], idx[1]]
        row = {}
        if c1 == 0 or not np.isfinite(c1):
            out.append(row)
            continue
        for m in range(2, len(idx)):
            cm = coef[k, idx[m]]
            if cm == 0:
                break
            vm, cmv = cov[k, idx[m], idx[m]], cov[k, idx[m], idx[1]]
            scale = span ** (m - 1)
            rho = cm * scale / c1
            var = scale**2 * (vm / c1**2 + cm**2 * v1 / c1**4 - 2 * cm * cmv / c1**3)
            if abs(cm) >= n_sigma * np.sqrt(max(vm, 0.0)):
                row[m] = (float(rho), float(max(var, 0.0)))
        out.append(row)
    kappa = []
    c01, v01 = coef[0, idx[1]], cov[0, idx[1], idx[1]]
    for k in range(1, n):
        ck, vk = coef[k, idx[1]], cov[k, idx[1], idx[1]]
        if c01 == 0 or ck == 0:
            kappa.append(None)
            continue
        r = ck / c01
        kappa.append((float(r), float(vk / c01**2 + ck**2 * v01 / c01**4)))  # independent wells
    return out, kappa


def _pooled(values, tau_rel: float = 0.0):
    """Random-effects mean of [(value, var)]: weights 1 / (var + (tau_rel mu)²), mu the fixed-
    effect mean. Returns (mean, its variance, Cochran's Q, df, c, mu): Q of the fixed-effect
    weights, its degrees of freedom and the DerSimonian-Laird normaliser c = sum w - sum w² / sum w.

    (Tried, not kept: a trend in the square of each cell's vibration amplitude, for the
    truncation bias of a strongly excited cell's effective coefficients (Kresling torque-free,
    deployed well, F''/F' of the base cell 2.1 % high at 8 % of L). Read at a weak cell's
    amplitude, it was worse on 5 of 8 Kresling runs: the precise cells' residuals from the
    trend then rejected them as other designs.)"""
    v = np.array([x[0] for x in values])
    var = np.maximum(np.array([x[1] for x in values]), 1e-300)
    w0 = 1.0 / var
    mu = float(np.sum(w0 * v) / np.sum(w0))
    q = float(np.sum(w0 * (v - mu) ** 2))
    c = float(np.sum(w0) - np.sum(w0**2) / np.sum(w0))
    w = 1.0 / (var + (tau_rel * mu) ** 2)
    mean = float(np.sum(w * v) / np.sum(w))
    return mean, float(1.0 / np.sum(w)), q, v.size - 1, c, mu


def _quantities(per_dof):
    """{key: {dof: (value, var)}} of every ratio, key ("kappa", k) or ("rho", k, m)."""
    out = {}
    for j, (rows, kappa) in per_dof.items():
        for k, kv in enumerate(kappa):
            if kv is not None:
                out.setdefault(("kappa", k + 1), {})[j] = kv
        for k, row in enumerate(rows):
            for m, rv in row.items():
                out.setdefault(("rho", k, m), {})[j] = rv
    return out


def relative_tau(groups) -> float | None:
    """Pooled relative heterogeneity beyond the noise of several groups of [(value, var)] (the
    DerSimonian-Laird moment estimate, pooled over the groups, in units of each group's mean);
    groups of fewer than 2 are skipped; None where no group informs it. Both design gates use it:
    the cells' Taylor ratios (`_tau`) and their laws' node values (`_design_law`)."""
    num = den = 0.0
    for sub in groups:
        if len(sub) < 2:
            continue
        _, _, q, df, c, mu = _pooled(sub)
        if mu == 0 or c <= 0 or df <= 0:
            continue
        num += q - df
        den += c * mu**2
    if den <= 0:
        return None
    return float(np.sqrt(max(num, 0.0) / den))


def _tau(quantities, members):
    """Pooled relative heterogeneity of the ratios among `members` beyond their noise
    (`relative_tau`)."""
    return relative_tau([vals[j] for j in members if j in vals] for vals in quantities.values())


def _conflict_p(quantities, j, members, tau):
    """p-value of cell j's ratios against the others' random-effects means (chi-squared, the
    design spread tau included)."""
    chi2, df = 0.0, 0
    for vals in quantities.values():
        if j not in vals:
            continue
        others = [vals[i] for i in members if i != j and i in vals]
        if not others:
            continue
        pred, vp, *_, mu = _pooled(others, tau)
        x, vx = vals[j]
        chi2 += (x - pred) ** 2 / (vx + vp + (tau * mu) ** 2)
        df += 1
    return (float(jsp.gammaincc(df / 2, chi2 / 2)) if df else 1.0), df


def share_curvature(fits_per_dof, library: Library, n_sigma: float):
    """The borrowing plan of the module docstring.

    **Arguments:** `fits_per_dof`: per DOF, the `LocalFit` stacked over its wells (NumPy leaves,
    wells in increasing x, after the screen); `library`; `n_sigma`: the t-value a local
    coefficient needs to count as resolved.

    **Returns:** `(plan, summary)`: `plan[j]` None or, per well, {order m: (rho, sd)} to borrow
    (the prior a_m = rho a_1 / L^(m-1), standard deviation sd); `summary` a dict (`tau`,
    `members`, `excluded` {dof: reason}, `comparisons`).
    """
    idx = library.indices(STIFFNESS)  # q^0 .. q^r, in order
    d = len(fits_per_dof)
    summary = {"tau": None, "members": [], "excluded": {}, "comparisons": 0}
    plan = [None] * d
    if d < 2 or library.restoring_order < 2:
        summary["excluded"] = {j: "a single DOF" for j in range(d)} if d < 2 else {}
        return plan, summary
    eqs = [np.asarray(f.equilibrium, float) for f in fits_per_dof]
    n_wells = max((e.size for e in eqs), key=lambda n: sum(e.size == n for e in eqs))
    ref = None
    per_dof = {}
    for j, (f, e) in enumerate(zip(fits_per_dof, eqs)):
        if e.size != n_wells or n_wells < 2 or not e[-1] > e[0]:
            summary["excluded"][j] = f"{e.size} wells (the others {n_wells})"
            continue
        u = (e - e[0]) / (e[-1] - e[0])
        if ref is None:
            ref = u
        elif np.max(np.abs(u - ref)) > POSITION_TOL:
            summary["excluded"][j] = "wells at other relative positions"
            continue
        per_dof[j] = _ratios(np.asarray(f.coef, float), np.asarray(f.covariance, float), e, idx, n_sigma)
    members = sorted(per_dof)
    quantities = _quantities(per_dof)
    summary["comparisons"] = sum(1 for v in quantities.values() if len(v) >= 2)
    # cells that contradict the others leave (one at a time, the worst first)
    while len(members) >= 2:
        tau = _tau(quantities, members) or 0.0
        ps = {j: _conflict_p(quantities, j, members, tau)[0] for j in members}
        worst = min(ps, key=ps.get)
        if ps[worst] >= P_CONFLICT:
            break
        summary["excluded"][worst] = f"its ratios disagree with the other cells' (p = {ps[worst]:.2g})"
        members.remove(worst)
    tau = _tau(quantities, members) if len(members) >= 2 else None
    summary["tau"], summary["members"] = tau, members
    if tau is None or tau > TAU_MAX:
        why = "no ratio resolved at two cells" if tau is None else f"the cells differ by {100 * tau:.3g} %"
        for j in members:
            summary["excluded"].setdefault(j, why)
        return plan, summary
    spread = max(tau, TAU_FLOOR)
    for j in members:
        wells = []
        for k in range(n_wells):
            # every order the others resolve, from F'' up: where the cell resolves it too, the
            # prior and its own estimate combine by their precisions (a q^3 at t = 4 is +-25 %)
            borrow = {}
            for m in range(2, len(idx)):
                vals = quantities.get(("rho", k, m), {})
                donors = [vals[i] for i in members if i != j and i in vals]
                if not donors:
                    break
                # random effects: each donor carries the design spread too, so that the most
                # excited cell (tightest, but biased by the terms its local polynomial truncates)
                # does not decide alone
                rho, var, *_, mu = _pooled(donors, spread)
                borrow[m] = (rho, float(np.sqrt(var + (spread * mu) ** 2)))
            wells.append(borrow)
        if any(wells):
            plan[j] = wells
    return plan, summary


def refit_with_prior(q, v, y, w, library: Library, coef, rss, n_samples, span, borrow, x_noise=None, band=None):
    """One well's local fit refitted on its own data with the borrowed orders as a Gaussian
    prior (`share_curvature`): support = the fit's own plus the borrowed q^m; the data rows
    weighted by the fit's residual variance, one prior row per borrowed order,
    (a_m - rho a_1 / L^(m-1)) / (sd |a_1| / L^(m-1)). The data enter compressed (R, z of the
    library's QR), corrected for the noise on x where `x_noise` (its variance) is given, as the
    local fit was (`_errors_in_variables`), or as the rows above an integrated x's drift cut-off where
    `band` (`BandRows`) is given. Returns (coef, covariance): the posterior mean and
    covariance (NumPy)."""
    idx = library.indices(STIFFNESS)  # q^0 .. q^r, in order
    support = with_constant(np.asarray(coef) != 0, library)  # the force at the mean moves with the curvature
    for m in borrow:
        support[idx[m]] = True
    cols = np.nonzero(support)[0]
    if band is not None:
        qr = compress(band.theta, band.y, jnp.asarray(w, float))
    else:
        qr = _compressed(*(jnp.asarray(a, float) for a in (q, v, y, w)), library,
                         None if x_noise is None else jnp.asarray(x_noise, float))
    theta, y = np.asarray(qr.r, float)[:, cols], np.asarray(qr.z, float)
    n_data = int(np.sum(np.asarray(coef) != 0))
    sigma = np.sqrt(max(float(rss), 1e-300) / max(float(n_samples) - n_data, 1.0))
    a1 = float(coef[idx[1]])
    rows, rhs = [theta / sigma], [y / sigma]
    pos = {c: i for i, c in enumerate(cols)}
    for m, (rho, sd) in borrow.items():
        scale = span ** (m - 1)
        r = np.zeros(cols.size)
        r[pos[idx[m]]] = 1.0
        r[pos[idx[1]]] -= rho / scale
        rows.append(r[None, :] / (sd * abs(a1) / scale))
        rhs.append(np.zeros(1))
    mat, b = np.concatenate(rows), np.concatenate(rhs)
    norms = np.linalg.norm(mat, axis=0)
    norms = np.where(norms > 0, norms, 1.0)
    u, s, vt = np.linalg.svd(mat / norms, full_matrices=False)
    sol = (vt.T @ ((u.T @ b) / s)) / norms
    cov_s = (vt.T / s**2) @ vt / np.outer(norms, norms)
    new = np.zeros_like(np.asarray(coef, float))
    new[cols] = sol
    cov = np.zeros((new.size, new.size))
    cov[np.ix_(cols, cols)] = cov_s
    return new, cov
