"""Calibration of the global model's covariance: what the local data do not fix between the
wells (issue 15; beyond the paper).

The coordination's covariance (`coordinate`) propagates the local fits' noise exactly, but it
takes the global law's form as known: the Hermite interpolant of degree K (Eq. 18) is exact for
a polynomial truth of degree <= K and says nothing about a truth that is not one (a truss, a
magnet), whose error between the wells can be far larger than the noise. Two terms calibrate it:

- **Residual scale** (Birge ratio): where the weighted coordination has redundant local
  conditions (`hermite_gls`, chi-squared with `dof` > 0), the noise covariance is scaled by
  max(1, chi2 / dof): local covariances that the conditions' scatter shows too small are
  widened by the factor the data demand, never narrowed.
- **Model discrepancy from the degree choice** (the embedded error estimate of interpolation,
  as in an embedded Runge-Kutta pair): the error of an interpolant is estimated by its
  difference from the next one in the sequence. For the exact interpolant (no redundant
  condition), the sequence is the interpolants with one condition fewer: dropping well i's
  highest-order condition gives P_i, and P - P_i = A_K omega(x) / (x - x_i) (A_K the leading
  coefficient, omega(x) = prod_k (x - x_k)^(r_k + 1)): the Hermite remainder
  F^(K+1)(xi) / (K+1)! omega(x) with its unknown derivative replaced by the last one the data
  gave. The vectors d_i = P - P_i enter as sum_i d_i d_i' (rank n, a Gaussian on the
  coefficients, so files, bands and samples carry it): zero at the wells to the order the data
  fix there, widest between and beyond them, where no datum is. For a weighted fit of degree
  K' < K (the data accept a lower degree), the next fit of degree K' + 1 gives one d (one
  parity: an odd error between three wells escapes an even next term; `NEXT_DEGREES`).

Both terms are statistics of the local data, not constants tuned to a study. The joint route's
posterior covariance sigma^2 A^-1 already holds its smoothness prior (wide where the data are
silent); the paper route's discrepancy is added to it (`add_discrepancy`): what the wells'
local data leave open between them does not depend on the estimator.
"""

import numpy as np

from .._fit._local_fit import LocalFit
from .._trace_cache import disk_traced
from .._fit._library import Library
from ._coordinate import DAMPING_MIN_DEGREE, _taylor_blocks, _taylor_covariances, with_dropped
from ._gls import hermite_gls, weighted_fit, weighted_system
from ._hermite import hermite_interpolate, highest_order, monomial_map

# Called outside any jit (once per DOF after the coordination): each as one compiled program,
# not dozens of eager operations (~20 ms apiece to trace, lower and load in a new process);
# each keeps its traced program on disk (`_trace_cache`, the CLI's warm start).
_interpolate = disk_traced(hermite_interpolate)
_gls = disk_traced(hermite_gls)
_system = disk_traced(weighted_system)
_wfit = disk_traced(weighted_fit)


#: the weighted fit's embedded error: its differences from the fits this many degrees above it. 1: the next degree
#: only, of one parity. 2 (both parities) holds an odd error between three wells that the next even term misses (a
#: sin tri-stable law at 40 dB: coverage 42 -> 100 %, band ±11 % for a 4 % error) but the fit two degrees up is
#: often the exact interpolant through noisy high-order conditions, and its difference is noise: the 3-cell Kresling
#: stress case at the advised amplitude went from a ±73 % band to ±4800 % (error 1.7 %). Weighed by the share of
#: it above its own noise, it held the audit's realization (weight 0.56, 100 %) but not another of the same law
#: (weight 0: the degree-11 interpolant is within noise of the degree-9 fit, and both miss the truth; 13 %): the
#: error there is beyond degree 11, not in the other parity. Left at 1 (tests/test_uncertainty.py, strict xfail)
NEXT_DEGREES = 1


def _chosen_and_vectors(nodes, taylor, order, cov, method: str, alpha: float, confining: bool = False,
                        max_degree=None, min_degree=None):
    """The coordination's polynomial (as `coordinate` picks it), its embedded-error vectors
    (m, size) and the Birge ratio of its weighted fit (1 without redundancy)."""
    exact, k_herm, _ = _interpolate(nodes, taylor, order)
    k_herm = int(k_herm)
    size = taylor.shape[0] * taylor.shape[1]
    if method == "gls":
        coef, degree, _, stats = _gls(nodes, taylor, order, cov, alpha, confining=confining, max_degree=max_degree,
                                      min_degree=min_degree)
        degree = int(degree)
    else:
        coef, degree, stats = exact, k_herm, {}
    if degree < k_herm:
        a_w, b_w, c, h, _ = _system(nodes, taylor, order, cov)
        to_monomials = monomial_map(float(c), float(h), size)
        # the next fit of each parity: an error of the other parity (odd between symmetric wells) is not in the
        # next degree's term alone (audit: a sin law's odd error between three wells, band 2-3 x too narrow)
        vectors = [to_monomials @ np.asarray(_wfit(a_w, b_w, k)[0]) - np.asarray(coef)
                   for k in range(degree + 1, min(degree + NEXT_DEGREES, k_herm) + 1)]
        dof = float(stats["dof"])
        birge = max(1.0, float(stats["chi2"]) / dof) if dof > 0 else 1.0
        return vectors, birge
    vectors, valued = [], False
    for i in range(taylor.shape[0]):
        if int(order[i]) < 1:  # its one condition is the value its data fix (`_remainder`)
            valued = True
            continue
        fewer = np.array(order)
        fewer[i] -= 1
        lower, _, _ = _interpolate(nodes, taylor, fewer)
        vectors.append(np.asarray(exact) - np.asarray(lower))
    if valued:
        vectors.append(_remainder(np.asarray(exact), k_herm, np.asarray(nodes), np.asarray(order), size))
    return vectors, 1.0


def _remainder(exact, k_herm: int, nodes, order, size: int) -> np.ndarray:
    """The Hermite remainder A_K omega(x) per unit of the nodes' span (A_K the interpolant's leading
    coefficient standing in for the unknown next derivative, omega(x) = prod_k (x - x_k)^(r_k + 1)): zero at
    every well to the order its data fix. It replaces the embedded-error vector of a well whose only condition
    is its value (order 0): the interpolant without that condition misses the value the well measured, and its
    difference put the whole spread between the wells' values into the band at the well (audit D F8, damping
    (0.2 + 1400 x^2) v, 30 dB, the viscous values 0.4062 / 0.2014 / 0.5199 +- 0.003-0.004 at the three wells:
    the 95 % band at each well -0.58 .. 1.39, every well's damping possibly negative)."""
    omega = np.array([1.0])
    for x_k, r_k in zip(nodes, order):
        for _ in range(int(r_k) + 1):
            omega = np.convolve(omega, [-float(x_k), 1.0])  # ascending coefficients
    span = float(np.ptp(nodes))
    out = np.zeros(max(size, omega.size))
    out[: omega.size] = exact[k_herm] * omega / (span if span > 0 else 1.0)
    return out[:size] if not np.any(out[size:]) else out


def discrepancy(fits: LocalFit, library: Library, *, method: str = "gls", alpha: float = 0.05,
                confining: bool = False, max_degree=None):
    """The embedded-error vectors and Birge ratios of one DOF's paper route (module docstring):
    `{"restoring": (vectors, birge), "damping": (vectors, birge)}`, each vector the monomial
    coefficients of a polynomial (the restoring force F, the damping polynomial C of
    `coordinate`: C_0 is the viscous B_1, C_j the x^j v coefficients)."""
    a, c, _ = _taylor_blocks(fits.coef, library)
    cov_a, cov_c = _taylor_covariances(np.asarray(with_dropped(fits)), library)  # as `coordinate` weighs them
    x = fits.equilibrium
    out = {"restoring": _chosen_and_vectors(x, a, highest_order(a != 0), cov_a, method, alpha, confining, max_degree)}
    out["damping"] = (_chosen_and_vectors(x, c, highest_order(c != 0), cov_c, method, alpha,
                                          min_degree=DAMPING_MIN_DEGREE)
                      if c.shape[1] > 0 else ([], 1.0))
    return out


def calibrate_covariance(fits: LocalFit, library: Library, covariance, *, method: str = "gls",
                         alpha: float = 0.05, restoring: bool = True, damping: bool = True,
                         confining: bool = False, max_degree=None) -> np.ndarray:
    """The calibrated covariance of one DOF's global coefficients from the paper's route
    (`coordinate` with `method`, `alpha`; flat layout of `GlobalCoefficients.flat`):
    `covariance` (the propagated one, `coordinate`'s aux) with its restoring and damping blocks
    scaled by their Birge ratios, plus the embedded-error discrepancy of each (module
    docstring). `restoring` / `damping` False leaves that block as given (a block another
    route produced, e.g. the joint damping of "gls + joint damping"); `confining` as
    `coordinate`'s."""
    cov = np.array(covariance, float)
    a, c, _ = _taylor_blocks(fits.coef, library)
    ns = a.shape[0] * a.shape[1]
    nv = library.damping_order + 1
    disc = discrepancy(fits, library, method=method, alpha=alpha, confining=confining, max_degree=max_degree)
    scale = np.ones(cov.shape[0])
    extra = np.zeros_like(cov)
    blocks = []
    if restoring:
        blocks.append((np.arange(ns), disc["restoring"]))
    if damping and c.shape[1] > 0 and cov.shape[0] > ns + nv:
        idx = np.concatenate([[ns + 1], ns + nv + np.arange(1, c.shape[0] * c.shape[1])])  # B_1 = C_0, C_j
        blocks.append((idx, disc["damping"]))
    for idx, (vectors, birge) in blocks:
        scale[idx] = np.sqrt(birge)
        for d in vectors:
            full = np.zeros(cov.shape[0])
            full[idx] = d[: idx.size]
            extra += np.outer(full, full)
    return scale[:, None] * cov * scale[None, :] + extra


def add_discrepancy(stiffness, velocity_damping, position_damping, covariance, fits: LocalFit, library: Library,
                    *, method: str = "gls", alpha: float = 0.05):
    """A global law of one DOF fitted by another route (the joint regression) with the paper
    route's embedded-error discrepancy added to its covariance: what the wells' local data fix
    between the wells does not depend on the estimator that fits them. The coefficient blocks
    are zero-padded where a discrepancy polynomial is longer. Returns the (padded) blocks and
    the covariance in their flat layout."""
    disc = discrepancy(fits, library, method=method, alpha=alpha)
    vr, vc = disc["restoring"][0], disc["damping"][0]
    s, b, p = (np.asarray(a, float) for a in (stiffness, velocity_damping, position_damping))
    ns = max([s.size] + [d.size for d in vr])
    npd = max([p.size] + [d.size for d in vc])
    nv = max(b.size, 2)
    old = np.concatenate([np.arange(s.size), ns + np.arange(b.size), ns + nv + np.arange(p.size)])
    size = ns + nv + npd
    cov = np.zeros((size, size))
    cov[np.ix_(old, old)] = np.asarray(covariance, float)
    for d in vr:
        full = np.zeros(size)
        full[: d.size] = d
        cov += np.outer(full, full)
    for d in vc:
        full = np.zeros(size)
        full[ns + 1] = d[0]
        full[ns + nv + 1 : ns + nv + d.size] = d[1:]
        cov += np.outer(full, full)
    pad = lambda a, n: np.pad(a, (0, n - a.size))  # noqa: E731
    return pad(s, ns), pad(b, nv), pad(p, npd), cov


__all__ = ["add_discrepancy", "calibrate_covariance", "discrepancy"]
