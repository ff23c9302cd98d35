"""Rule 14d: a damping law chosen from velocities differentiated from x, checked against the
differentiation's window.

Where v (and a) are Savitzky-Golay derivatives of a measured x, the damping law's nonlinear
terms rest on the harmonics the filter passes, and its systematic error is in no score: the
evidence can be decisive for a wrong law. Single-tone arch (`studies/single_tone_budget.py`), x
only, 60 dB, 2.5x the base amplitude, both seeds: v + 0.06 v^3 for the truth's 0.18 v + 0.05 v|v|
(the v|v| law 17.9 worse, no rule-14 warning on seed 0), a one-period NRMSE of the cross-well
record of 39-41 %; at 0.7 of the automatic window the right law (0.048 v|v|, 1.8-2.1 %); at 2x
the amplitude the law is the same at 0.7, 1 and 1.5 of the window. The check refits with every
derived record differentiated at `WINDOW_SCALE` of its automatic window and warns where the
velocity terms differ. `reconstruct` runs it where a record is a steady sine (`_steady_sines`: its
law speaks through a few harmonics near the filter's edge, the case measured) and the chosen law
has a term beyond the viscous one; it costs a second fit. Not checked: swept records (their band
edge is the sweep's top) and a viscous-only choice (rule 14 speaks there).
"""

import contextvars
import warnings

import numpy as np

from .._fit._library import POSITION_DAMPING, VELOCITY_DAMPING, term_name

#: the refit differentiates x at this share of each column's automatic window
WINDOW_SCALE = 0.7
_ACTIVE = contextvars.ContextVar("gmr_window_check", default=False)


def _from_x(rec) -> bool:
    """Whether the recording's v will be differentiated from its measured x."""
    return rec.v is None and rec.x is not None and rec.integration is None


def derived_from_x(recordings) -> bool:
    """Whether some recording's v will be differentiated from its measured x."""
    return any(_from_x(r) for r in recordings)


def support(model, i: int) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """The velocity-damping orders j (B_j of sgn(v)|v|^j) and position-damping orders (C_j of x^j v) of DOF i
    with a nonzero coefficient (a pruned term is an exact 0)."""
    b, c = np.asarray(model.velocity_damping[i], float), np.asarray(model.position_damping[i], float)
    return tuple(np.flatnonzero(b).tolist()), tuple(np.flatnonzero(c).tolist())


def nonlinear(model) -> bool:
    """Whether some DOF's damping holds a term other than the viscous v."""
    return any(set(support(model, i)[0]) - {1} or support(model, i)[1] for i in range(model.n_dof))


def damping_text(model, i: int) -> str:
    b, c = np.asarray(model.velocity_damping[i], float), np.asarray(model.position_damping[i], float)
    parts = [f"{b[j]:.3g} {term_name(VELOCITY_DAMPING, j)}" for j in support(model, i)[0]]
    parts += [f"{c[j]:.3g} {term_name(POSITION_DAMPING, j)}" for j in support(model, i)[1]]
    return (" + ".join(parts) or "no damping").replace("+ -", "- ")


def rewindowed(recordings, topology, exclude_center: bool, scale: float = WINDOW_SCALE):
    """The recordings with v and a differentiated from x at `scale` of each column's automatic window (validated
    first, as `reconstruct` does: time stamps put on their grid before anything is differentiated)."""
    from .._recordings._recording import validate

    return [validate(r, r.name).complete(topology, exclude_center=exclude_center, window_scale=scale)
            if _from_x(r) else r for r in recordings]


def check(fit, recordings, model, topology, exclude_center: bool, say=None) -> tuple[list[str], dict]:
    """Rule 14d (module docstring): `fit(recordings)` is `reconstruct` with the caller's arguments; its
    warnings are not the caller's; `say`: the caller's progress, told when the refit runs. Returns (warnings,
    stats: per DOF the refit's damping and whether it differs)."""
    if _ACTIVE.get() or not derived_from_x(recordings) or not nonlinear(model):
        return [], {}
    if say is not None:
        say("damping law against the derivative window")
    token = _ACTIVE.set(True)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            other = fit(rewindowed(recordings, topology, exclude_center)).value
    finally:
        _ACTIVE.reset(token)
    out, stats = [], {}
    for i in range(model.n_dof):
        same = support(model, i) == support(other, i)
        stats[i] = {"window_scale": WINDOW_SCALE, "damping": damping_text(other, i), "same_terms": same}
        if same or not np.all(np.isfinite(np.asarray(other.velocity_damping[i]))):
            continue
        out.append(f"DOF {i}: the damping law rests on how x was differentiated (v and a are not measured): "
                   f"with the automatic Savitzky-Golay window it is {damping_text(model, i)}, with {WINDOW_SCALE:g} "
                   f"of that window {damping_text(other, i)}; the data's evidence for either holds the filter's "
                   f"error at the harmonics, so neither law is decided beyond the recorded speeds. Measure v (a "
                   f"laser vibrometer) or a (an accelerometer) to decide it")
    return out, stats
