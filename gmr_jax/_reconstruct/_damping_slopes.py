"""The damping's slope at a well that does not resolve it, in the band (issue 15; beyond the paper).

A well whose local fit keeps no x v term fixes the damping C(x) at its equilibrium only: its value,
not its slope. The coordination (Eq. 18) then takes the slope as zero there and the calibrated band
(`_coordination/_discrepancy.py`) as known, for its embedded error compares interpolants of those
same conditions: two wells with one viscous value give a constant C and a band as narrow as the
values. Yet a slope the threshold dropped is not a zero slope. 5-cell Kresling chain, 0.3 mm sweeps,
50 dB, seed 0, tip cell (0.14-0.5 % of its interwell distance): the truth's C(x) = c0 + c2 ((x -
L/2) / (L/2))^2 halves between the wells (C' = -15 and +15 at them); the model's C was the wells'
constant with a band 0.17 % wide, 470-690 standard errors off mid-span (coverage 4.9 %).

Each such well is refitted with x v added to its support (`_local_rules._refit_with`, the other kept
terms exempt from the threshold): its coefficient c_k and standard error s_k are what the well's data
say of C'(x_k) (tip cell: about 3 standard errors at each well). The law the coordination chose and
the one with that slope differ by c_k H_k(x), H_k the Hermite basis polynomial of degree 2n - 1 on
the n wells with H_k(x_j) = 0 at every well, H_k'(x_j) = 1 at well k and 0 at the others; the band
holds that difference and the slope's noise, (c_k^2 + s_k^2) H_k H_k', for every such well (a
threshold's choice, as the joint route's degree choice, `joint_alternative`, enters its band). The
law's mean keeps the slope the coordination gave it. A well that kept x v adds nothing: its
covariance is already in the coordination's. Only on the paper route's damping (`reconstruct`): where
the joint regression fitted the damping (routes "joint", "gls + joint damping"), its candidates held
the position terms and its own degree choice is in its band.
"""

import numpy as np

from .._fit._library import POSITION_DAMPING, STIFFNESS, Library
from ._local_rules import _refit_with


def unresolved_slopes(fits, xs, vs, ys, w, library: Library, solver, noise=None, x_noise=None,
                      band=None) -> tuple[np.ndarray, np.ndarray]:
    """Per well, the x v coefficient (C'(x_k)) and its standard error refitted with x v in its support, where the
    support lacks it and keeps a damping term; 0 elsewhere (x v kept, no damping, no x v in the library, a failed
    refit). Arguments as `_local_rules._refit_with` takes them."""
    n = xs.shape[0]
    est, out = np.zeros(n), np.zeros(n)
    terms = library.terms()
    if (POSITION_DAMPING, 1) not in terms:
        return est, out
    j = terms.index((POSITION_DAMPING, 1))
    coef = np.asarray(fits.coef)
    damping = [i for i, (phys, _) in enumerate(terms) if phys != STIFFNESS]
    for k in range(n):
        if coef[k, j] != 0 or not any(coef[k, i] != 0 for i in damping):
            continue
        _, ok, c, var = _refit_with(xs, vs, ys, w, library, solver, fits, k, coef[k], j, noise, x_noise, band)
        if ok and np.isfinite(c) and np.isfinite(var) and var > 0:
            est[k], out[k] = c, np.sqrt(var)
    return est, out


def slope_vectors(equilibria, slope, slope_se) -> list[np.ndarray]:
    """(c_k^2 + s_k^2)^(1/2) H_k for every well with s_k > 0 (module docstring): ascending monomial coefficients
    of C, degree 2n - 1 for n wells."""
    eq = np.asarray(equilibria, float)
    n = eq.size
    powers = np.arange(2 * n)
    value = eq[:, None] ** powers[None, :]
    derivative = powers[None, :] * np.where(powers[None, :] > 0, eq[:, None] ** np.maximum(powers - 1, 0)[None, :],
                                            0.0)
    a = np.concatenate([value, derivative])
    out = []
    for k, (c, s) in enumerate(zip(np.asarray(slope, float), np.asarray(slope_se, float))):
        if s > 0:
            rhs = np.zeros(2 * n)
            rhs[n + k] = 1.0
            out.append(np.hypot(c, s) * np.linalg.solve(a, rhs))
    return out


def add_slope_vectors(covariance, n_stiffness: int, n_velocity: int, n_position: int, vectors) -> np.ndarray:
    """The flat covariance (stiffness, velocity damping, position damping blocks) plus the outer product of each
    vector on the damping polynomial's coefficients (C_0 = B_1, C_j of x^j v); vectors longer than the position
    block are left out (the model cannot hold them)."""
    cov = np.array(covariance, float)
    for d in vectors:
        if d.size > n_position or n_velocity < 2:
            continue
        full = np.zeros(cov.shape[0])
        full[n_stiffness + 1] = d[0]
        full[n_stiffness + n_velocity + 1 : n_stiffness + n_velocity + d.size] = d[1:]
        cov += np.outer(full, full)
    return cov
