"""Stable equilibria (wells) of each DOF of a model, for classifying final states."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import GMRInputError
from .._model._model import AbstractMechanicalModel, GlobalModel
from .._topology import Graph


def _check_range(x_range, d: int) -> np.ndarray:
    try:
        r = np.asarray(x_range, float)
    except (TypeError, ValueError):
        raise GMRInputError(f"x_range must be numbers: (lo, hi) or one (lo, hi) per DOF, got {x_range!r}") from None
    if r.shape == (2,):
        r = np.broadcast_to(r, (d, 2))
    if r.shape != (d, 2):
        raise GMRInputError(f"x_range must be (lo, hi) or ({d}, 2), one interval per DOF; got shape {r.shape}")
    for i, (lo, hi) in enumerate(r):
        if not (np.isfinite(lo) and np.isfinite(hi)) or lo >= hi:
            raise GMRInputError(f"x_range of DOF {i} is [{lo}, {hi}]: need finite lo < hi (is it inverted?)")
    return r


def pad_wells(roots: list[np.ndarray]) -> np.ndarray:
    """Per-DOF lists of wells -> (dof, max_wells) array, NaN-padded (at least one column)."""
    wells = np.full((len(roots), max(1, max(len(r) for r in roots))), np.nan)
    for i, r in enumerate(roots):
        wells[i, : len(r)] = r
    return wells


def polynomial_wells(model: GlobalModel, x_range=None) -> list[np.ndarray]:
    """Real stable zeros (F_i = 0, dF_i/dx > 0) of each DOF's restoring polynomial
    F_i(x) = sum_k stiffness[i, k] x^k (paper Eq. 1 at rest), by the polynomial's companion
    matrix and two Newton steps; only those inside `x_range` (dof, 2) when it is given."""
    k = np.asarray(model.stiffness, float)
    out = []
    for i in range(k.shape[0]):
        c = np.trim_zeros(k[i], "b")
        if c.size < 2:
            out.append(np.zeros(0))
            continue
        r = np.roots(c[::-1])
        scale = max(1.0, float(np.max(np.abs(r)))) if r.size else 1.0
        r = np.sort(r[np.abs(r.imag) <= 1e-7 * scale].real)
        dc = c[1:] * np.arange(1, c.size)
        for _ in range(2):  # polish on the polynomial itself
            fr, dfr = np.polyval(c[::-1], r), np.polyval(dc[::-1], r)
            r = np.where(dfr != 0, r - fr / np.where(dfr != 0, dfr, 1.0), r)
        stable = np.polyval(dc[::-1], r) > 0
        r = r[stable]
        if x_range is not None:
            r = r[(r >= x_range[i, 0]) & (r <= x_range[i, 1])]
        out.append(np.unique(r))
    return out


def stable_wells(model: AbstractMechanicalModel, x_range=None, n: int = 20001) -> np.ndarray:
    """Stable zeros of each DOF's restoring force, ordered by increasing deformation.

    `x_range`: (lo, hi) or (dof, 2) search interval per DOF. Without it the wells of a polynomial
    `GlobalModel` are the real stable roots of each DOF's restoring polynomial (every one: give an
    `x_range`, e.g. the span of the training data, to drop outer roots that lie outside it); other
    models need an `x_range`, searched on an `n`-point grid. Returns (dof, max_wells),
    NaN-padded. With no external load each cell of a chain is at rest only where its own
    F_i(x_i) = 0. On a `Graph` the cells are the elements (deformation intervals, (elements, 2))."""
    d = model.n_elements
    if x_range is None:
        if not isinstance(model, GlobalModel):
            raise GMRInputError(
                f"stable_wells: a {type(model).__name__} has no polynomial restoring force; give "
                "x_range=(lo, hi), the deformation interval in which to search for wells"
            )
        out = polynomial_wells(model)
    else:
        x_range = _check_range(x_range, d)
        if isinstance(model, GlobalModel):
            out = polynomial_wells(model, x_range)
        else:
            out = []
            for i in range(d):
                xs = np.linspace(*x_range[i], n)

                def f(x, i=i):
                    return model.restoring(jnp.zeros(d).at[i].set(x))[i]

                fx = np.asarray(jax.vmap(f)(jnp.asarray(xs)))
                idx = np.nonzero((fx[:-1] < 0) & (fx[1:] >= 0))[0]  # increasing crossing: stable
                roots = xs[idx] - fx[idx] * (xs[idx + 1] - xs[idx]) / (fx[idx + 1] - fx[idx])
                out.append(roots)
    return pad_wells(out)


def _balance(model: AbstractMechanicalModel, u):
    """The restoring forces at the coordinates u as the masses feel them: B' F(B u) on a `Graph`
    (B the incidence), each cell's own F_i(u_i) on a chain or independent DOFs."""
    topo = model.topology
    f = model.restoring(topo.deformations(u))
    return topo.node_forces(f) if isinstance(topo, Graph) else f


@eqx.filter_jit
def newton_equilibrium(model: AbstractMechanicalModel, u0):
    """40 Newton steps on the force balance `_balance(model, u) = 0` from `u0`: the coordinates, the
    balance's residual there and the eigenvalues of its Jacobian (the stiffness matrix: all
    positive at a stable equilibrium)."""
    def step(_, u):
        return u - jnp.linalg.solve(jax.jacfwd(lambda z: _balance(model, z))(u), _balance(model, u))

    u = jax.lax.fori_loop(0, 40, step, u0)
    return u, _balance(model, u), jnp.linalg.eigvalsh(jax.jacfwd(lambda z: _balance(model, z))(u))


def configuration(model: AbstractMechanicalModel, wells, pattern) -> np.ndarray:
    """The coordinates (node displacements on a `Graph`) of the stable equilibrium with cell
    (element) e in its well `pattern[e]`: `newton_equilibrium` from the least-squares u with each
    multi-well element at that well.

    **Arguments:** `model`; `wells` (cells, max_wells) from `stable_wells`; `pattern` (cells,)
    well indices (ignored for one-well cells). Raises `GMRInputError` when Newton does not end
    at a stable equilibrium (the pattern is not one of the model's configurations)."""
    topo = model.topology
    w = np.asarray(wells, float)
    pat = np.asarray(pattern, int)
    if pat.shape != (w.shape[0],) or np.any(pat < 0) or np.any(pat >= w.shape[1]):
        raise GMRInputError(f"pattern must be one well index per cell ({w.shape[0]} of them, 0..{w.shape[1] - 1}), got "
                            f"{pat.tolist()}")
    multi = np.sum(np.isfinite(w), axis=1) >= 2
    target = np.where(multi, w[np.arange(w.shape[0]), pat], 0.0)
    d = model.n_dof
    B = np.asarray(topo.deformations(np.eye(d))).T  # (cells, dof)
    u0, *_ = np.linalg.lstsq(B[multi], target[multi], rcond=None)
    u, res, eig = (np.asarray(a) for a in newton_equilibrium(model, jnp.asarray(u0, float)))
    cells = B @ u
    lo, hi = np.nanmin(w, axis=1), np.nanmax(w, axis=1)
    span = np.where(hi > lo, hi - lo, 1.0)
    near = np.abs(cells - target) < 0.25 * span
    if not (np.all(np.isfinite(u)) and np.max(np.abs(res)) < 1e-8 * (1.0 + np.max(np.abs(u)))
            and np.min(eig) > 0 and np.all(near[multi])):
        raise GMRInputError(f"no stable equilibrium with the cells in the wells {pat.tolist()} (force residual "
                            f"{np.max(np.abs(res)):.2e}, smallest stiffness eigenvalue {np.min(eig):.3g}): not a "
                            f"configuration of this model")
    return u
