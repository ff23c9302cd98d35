"""Admissibility of a global model of one DOF over the span it is used on: a restoring force
that confines and has exactly the recorded wells, a damping law that dissipates."""

import numpy as np

#: Damping power D v below -this x its largest value on the check grid counts as feeding energy in
#: (a damping law that is zero at a point fits slightly negative there).
DISSIPATION_TOLERANCE = 1e-3
#: speeds of the dissipation check grid, evenly spaced in (0, bound]
DISSIPATION_SPEEDS = 40


def restoring_faults(stiffness, equilibria) -> list[str]:
    """Why a global restoring force of one DOF is not admissible, or []: it must confine (odd
    degree, positive leading coefficient: F -> +inf as x -> +inf, -inf as x -> -inf) and change
    sign exactly 2n - 1 times over the span it is used on, the equilibria widened by half their
    span on each side (its n wells and the saddles between them: no other well). Monomial
    coefficients in x, as `GlobalModel` holds them."""
    return [msg for _, msg in _restoring_faults(stiffness, equilibria)]


def _restoring_faults(stiffness, equilibria) -> list[tuple[tuple[str, int], str]]:
    eq = np.asarray(equilibria, float)
    lo, hi = float(eq.min()), float(eq.max())
    half = 0.5 * (hi - lo)
    x = np.linspace(lo - half, hi + half, 801)
    f = np.polynomial.polynomial.polyval(x, np.asarray(stiffness, float))
    out = []
    coef = np.trim_zeros(np.asarray(stiffness, float), "b")
    if coef.size % 2 == 1 and coef.size > 1:  # even degree: F has one sign at both ends
        out.append((("even", 1), f"its restoring force has even degree {coef.size - 1}, so it cannot confine on both "
                                 f"sides (F -> {'+' if coef[-1] > 0 else '-'}inf as x -> ±inf)"))
    elif coef.size > 1 and coef[-1] < 0:
        out.append((("outward", 1), f"its restoring force turns outward far out (leading term {coef[-1]:.4g} "
                                    f"x^{coef.size - 1}: F -> -inf as x -> +inf): a motion that leaves the recorded "
                                    f"range escapes"))
    pos = f >= 0
    changes = int(np.sum(pos[1:] != pos[:-1]))
    if changes != 2 * eq.size - 1:
        out.append((("sign", changes), f"its restoring force changes sign {changes} times on [{lo - half:.4g}, "
                                       f"{hi + half:.4g}] where {eq.size} wells and the saddles between them need "
                                       f"{2 * eq.size - 1}"))
    return out


def fall_speed(stiffness, wells, mass: float, lo: float, hi: float, n: int = 401) -> float:
    """The speed of a fall from the highest point of the potential V = int F dx on [lo, hi] (`n` points) to the
    lowest of `wells`, sqrt(2 (max V - min V_well) / m): the speeds a law of one DOF is used at without forcing
    (the bound `damping_faults` checks up to); 0 where no point lies above the wells."""
    antider = np.polynomial.polynomial.polyint(np.asarray(stiffness, float))
    drop = float(np.max(np.polynomial.polynomial.polyval(np.linspace(lo, hi, n), antider))
                 - np.min(np.polynomial.polynomial.polyval(np.asarray(wells, float), antider)))
    return float(np.sqrt(2.0 * max(drop, 0.0) / mass))


def damping_faults(velocity_damping, position_damping, equilibria, speed: float) -> list[str]:
    """Why a global damping law of one DOF is not admissible, or []: it must dissipate,
    D(x, v) v >= 0 (within `DISSIPATION_TOLERANCE`) and not identically 0, over the span of use
    (as `restoring_faults`) and |v| <= `speed`; a negative friction b_0 sgn(v) feeds energy in as v -> 0
    (below the check grid's lowest speed) wherever it is."""
    eq = np.asarray(equilibria, float)
    lo, hi = float(eq.min()), float(eq.max())
    half = 0.5 * (hi - lo)
    xx, vv = np.meshgrid(np.linspace(lo - half, hi + half, 41), np.linspace(0.0, speed, DISSIPATION_SPEEDS + 1)[1:], indexing="ij")
    b = np.asarray(velocity_damping, float)
    if b.size and b[0] < 0:  # D v -> b_0 |v| as v -> 0, below any grid's lowest speed
        return [f"its friction b_0 sgn(v) is negative ({b[0]:.4g}): it feeds energy in at low speed"]
    dv = np.polynomial.polynomial.polyval(xx, np.asarray(position_damping, float)) * vv**2
    dv = dv + sum(b[j] * vv ** (j + 1) for j in range(b.size))
    if not np.any(dv > 0):
        return ["it has no damping"]
    if np.min(dv) < -DISSIPATION_TOLERANCE * np.max(np.abs(dv)):
        i = np.unravel_index(np.argmin(dv), dv.shape)
        return [f"its damping feeds energy in (D v < 0) at x = {xx[i]:.4g}, v = {vv[i]:.4g}"]
    return []


def inadmissible(stiffness, velocity_damping, position_damping, equilibria, speed: float) -> list[str]:
    """Why a global model of one DOF is not admissible over the span it is used on, or []:
    `restoring_faults` and `damping_faults` together."""
    return restoring_faults(stiffness, equilibria) + damping_faults(velocity_damping, position_damping, equilibria,
                                                                    speed)
