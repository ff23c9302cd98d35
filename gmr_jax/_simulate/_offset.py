"""The unobservable equilibrium of a velocity- or acceleration-only recording, placed by the model.

x integrated from v or a has zero mean (`_recordings._integrate`): where the structure sat while
it vibrated is not in the data. Unless the recording gives it (`equilibrium`), `discover` and `free_run` place
it with the model under test: per DOF, the offset c that makes the model's force balance hold on
average over the record,

    mean_t [ F_i(x_i + c, v_i) ] = mean_t [ y_i ],     y_i the force the DOF carries (contracts),

a polynomial equation in c (F is polynomial in x). The root where the force restores (dF/dc > 0)
is taken; a model with several such roots (a multi-stable one) cannot say which well the record
was in, and the user is asked for `equilibrium`. A constant force (preload) is then not separable
from the offset: for a linear spring k the two trade as k c against P, so `preload` is never a
finding on such a DOF (listed under `not_separable`). Each model is given its own offset when its
holdout error is measured.
"""

from dataclasses import replace

import numpy as np
from numpy.polynomial import polynomial as P
from math import comb

from .._errors import GMRInputError
from .._recordings._integrate import detrend, remove_drift
from .._recordings._recording import regression_targets


def _balance(model, dof: int, x: np.ndarray, v: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Coefficients (in c, increasing order) of mean_t F_dof(x + c, v) - mean_t y, for the
    DOF's x, v and carried force y."""
    g = np.zeros(1)
    g[0] = -float(np.mean(y))
    for t in model.terms():
        if t["dof"] != dof:
            continue
        k, c0 = int(t["order"]), float(t["coefficient"])
        if t["physics"] == "velocity_damping":
            g = P.polyadd(g, [c0 * float(np.mean(np.sign(v) * np.abs(v) ** k))])
            continue
        w = v if t["physics"] == "position_damping" else np.ones_like(v)
        # (x + c)^k w = sum_j C(k, j) c^j x^(k-j) w
        g = P.polyadd(g, [c0 * comb(k, j) * float(np.mean(x ** (k - j) * w)) for j in range(k + 1)])
    return P.polytrim(g, 0.0) if np.any(g) else np.zeros(1)


def offset(model, rec, dof: int, x: np.ndarray, y: np.ndarray) -> tuple[float, str]:
    """The offset c placing DOF `dof` of an unobserved recording (module docstring), and how;
    `x` the DOF's zero-mean integrated displacement, `y` the force it carries."""
    g = _balance(model, dof, x, rec.v[:, dof], y)
    if g.size < 2:
        return 0.0, "no position-dependent force on this DOF: the offset does not enter the model"
    dg = P.polyder(g)
    roots = P.polyroots(g)
    scale = max(float(np.ptp(x)), 1e-300)
    real = [float(r.real) for r in roots if abs(r.imag) <= 1e-8 * max(1.0, abs(r.real), scale)]
    stable = sorted({round(r, 15) for r in real if P.polyval(r, dg) > 0})
    if not stable:
        raise GMRInputError(
            f"{rec.name}: x was integrated from {rec.integration['from']} and its equilibrium is unobservable; "
            f"the model has no restoring equilibrium that balances this record's mean force on DOF {dof}: "
            f"give the recording's 'equilibrium' (the static displacement it vibrated about)")
    if len(stable) > 1:
        raise GMRInputError(
            f"{rec.name}: x was integrated from {rec.integration['from']} and its equilibrium is unobservable; "
            f"the model has {len(stable)} stable equilibria that could hold this record on DOF {dof} (offsets "
            f"{', '.join(f'{s:.4g}' for s in stable)}): give the recording's 'equilibrium' (the static "
            f"displacement it vibrated about) to say which")
    return stable[0], "the model's force balance averaged over the record (one stable root)"


def place(model, recs: list) -> tuple[list, list]:
    """Recordings with every unobserved equilibrium placed by `model` (x shifted, the offset in
    `integration["offset"]`), and one entry per recording for the report."""
    out, notes = [], []
    for r in recs:
        if r.equilibrium_observed:
            out.append(r)
            continue
        x0 = r.x - r.integration.get("offset", np.zeros(r.n_dof))[None, :]  # as integrated
        y = regression_targets(r, np.asarray(model.masses), model.topology)
        cs, how = zip(*(offset(model, r, i, x0[:, i], y[:, i]) for i in range(r.n_dof)))
        cs = np.asarray(cs, float)
        info = {**r.integration, "offset": cs, "equilibrium": f"estimated from the model: {how[0]}"}
        out.append(replace(r, x=x0 + cs[None, :], integration=info))
        notes.append({"recording": r.name, "offset": cs.tolist(), "how": list(how)})
    return out, notes


def comparable(rec, z: np.ndarray) -> np.ndarray:
    """A simulated x as the integrated one was made: without what the integration removes
    (polynomial and content below the cut-off), mean kept. Measured x passes through unchanged
    in substance (the operation is a projection)."""
    info = rec.integration
    times = 2 if info["from"] == "a" else 1
    cut = max(info["f_highpass_hz"])
    cols = [remove_drift(detrend(z[:, k], times), rec.dt, cut) + z[:, k].mean() for k in range(z.shape[1])]
    return np.stack(cols, 1)
