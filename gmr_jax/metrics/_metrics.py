"""Accuracy metrics of a reconstructed model against a truth model (paper Sec. 2.3, Eq. 22).

On a `Graph` the metrics read one element's law: `dof` is the element index, x its deformation."""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._errors import GMRInputError
from .._model._model import AbstractMechanicalModel
from .._model._uncertainty import PARTS, force_band


def _grid_forces(model: AbstractMechanicalModel, dof: int, xs, vs, which: str):
    d = model.n_elements

    def one(x, v):
        xx = jnp.zeros(d).at[dof].set(x)
        vv = jnp.zeros(d).at[dof].set(v)
        if which == "restoring":
            return model.restoring(xx)[dof]
        return model.damping(xx, vv)[dof]

    return np.asarray(jax.vmap(jax.vmap(one, (None, 0)), (0, None))(jnp.asarray(xs), jnp.asarray(vs)))


def restoring_error(model, truth, dof: int, x_range, n: int = 401) -> float:
    """Relative L2 error of the restoring force of `dof` over `x_range`:
    ||F_r - F_r,true|| / ||F_r,true|| on a uniform grid."""
    xs = np.linspace(*x_range, n)
    f = _grid_forces(model, dof, xs, np.zeros(1), "restoring")[:, 0]
    g = _grid_forces(truth, dof, xs, np.zeros(1), "restoring")[:, 0]
    return float(np.linalg.norm(f - g) / np.linalg.norm(g))


def damping_error_map(model, truth, dof: int, x_range, v_range, n: int = 101):
    """Eq. (22): e_d = log10|F_d - F_d,true| on an (x, v) grid; returns (xs, vs, e_d, F_d,true)."""
    xs = np.linspace(*x_range, n)
    vs = np.linspace(*v_range, n)
    f = _grid_forces(model, dof, xs, vs, "damping")
    g = _grid_forces(truth, dof, xs, vs, "damping")
    return xs, vs, np.log10(np.abs(f - g) + 1e-300), g


def damping_error(model, truth, dof: int, x_range, v_range, n: int = 101) -> float:
    """Relative L2 error of the damping force over the (x, v) box."""
    xs = np.linspace(*x_range, n)
    vs = np.linspace(*v_range, n)
    f = _grid_forces(model, dof, xs, vs, "damping")
    g = _grid_forces(truth, dof, xs, vs, "damping")
    return float(np.linalg.norm(f - g) / np.linalg.norm(g))


def equilibria(model, dof: int, x_range, n: int = 4001):
    """Zeros of the restoring force of `dof` in `x_range`, with stability (dF/dx > 0).

    Returns a list of (x, stable) sorted by x.

    Examples:
        The bistable joint's restoring force -2244 x + 1755 x^3: two wells and a saddle.

        >>> import gmr_jax as gmr
        >>> model = gmr.from_terms([1.0], [
        ...     {"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -2244.0},
        ...     {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1755.0}])
        >>> [(round(x, 4), stable) for x, stable in gmr.metrics.equilibria(model, 0, (-2.0, 2.0))]
        [(-1.1308, True), (0.0, False), (1.1308, True)]
        >>> [(round(x, 4), round(e, 1)) for x, e in gmr.metrics.energy_barriers(model, 0, (-2.0, 2.0))]
        [(-1.1308, 717.3), (1.1308, 717.3)]
    """
    xs = np.linspace(*x_range, n)
    f = _grid_forces(model, dof, xs, np.zeros(1), "restoring")[:, 0]
    out = []
    sf = np.sign(f)
    for k in range(n - 1):
        if sf[k] == 0:
            slope = f[min(k + 1, n - 1)] - f[max(k - 1, 0)]
            out.append((float(xs[k]), bool(slope > 0)))
        elif sf[k] * sf[k + 1] < 0:
            x0 = xs[k] - f[k] * (xs[k + 1] - xs[k]) / (f[k + 1] - f[k])
            out.append((float(x0), bool(f[k + 1] > f[k])))
    return out


def energy_barriers(model, dof: int, x_range, n: int = 4001):
    """Energy to climb from each stable well of `dof` to the neighbouring saddle(s):
    the integral of the restoring force from the well to the saddle (trapezoid on `n` points).

    Returns a list of (well x, barrier) for the stable zeros in `x_range` that have a saddle
    beside them (the lower of the two climbs when there are saddles on both sides)."""
    xs = np.linspace(*x_range, n)
    f = _grid_forces(model, dof, xs, np.zeros(1), "restoring")[:, 0]
    energy = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(xs))])
    zeros = equilibria(model, dof, x_range, n)
    e_at = lambda x: float(np.interp(x, xs, energy))  # noqa: E731
    out = []
    for k, (x, stable) in enumerate(zeros):
        if not stable:
            continue
        climbs = [e_at(zeros[j][0]) - e_at(x) for j in (k - 1, k + 1)
                  if 0 <= j < len(zeros) and not zeros[j][1]]
        if climbs:
            out.append((x, min(climbs)))
    return out


class BandCoverage(NamedTuple):
    """What `band_coverage` measures: `share`, the fraction of the grid where the band holds the truth's force;
    `width`, the band's median full width (upper - lower) relative to the largest |truth| on the grid; `max_error`,
    the largest |model - truth| relative to the same scale."""

    share: float
    width: float
    max_error: float


def band_coverage(model, truth, dof: int, x_range, v_range=None, *, part: str = "restoring", level: float = 0.95,
                  n: int = 401, n_v: int = 41) -> BandCoverage:
    """How well the `level` band of a reconstructed model's force (`gmr.force_band`, from
    `GlobalModel.covariance`) holds a known truth's, on DOF `dof` (the other DOFs at 0): the restoring force on
    `n` points over `x_range`, or (`part="damping"`) the damping force on an `n` x `n_v` grid over
    `x_range` x `v_range`, the points with v = 0 left out (the band and the truth are both 0 there).

    Examples:
        A model 10 % stiff in its cubic term: with a standard error of 0.1 on that term, its 95 % band
        (+- 0.196 |x|^3) holds the truth (off by 0.1 |x|^3) everywhere; with 0.04, only at x = 0 (1 point of 401).

        >>> import gmr_jax as gmr
        >>> terms = [{"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -1.0},
        ...          {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1.0}]
        >>> truth = gmr.from_terms([1.0], terms)
        >>> def model(se):
        ...     return gmr.from_terms([1.0], terms[:1] + [dict(terms[1], coefficient=1.1)], covariance=[
        ...         {"dof": 0, "terms": [["stiffness", 3]], "matrix": [[se**2]]}])
        >>> band = gmr.metrics.band_coverage(model(0.1), truth, 0, (-1.5, 1.5))
        >>> band.share, round(band.max_error, 2)
        (1.0, 0.18)
        >>> round(gmr.metrics.band_coverage(model(0.04), truth, 0, (-1.5, 1.5)).share * 401)
        1
    """
    if part not in PARTS[:2]:
        raise GMRInputError(f"band_coverage: part must be 'restoring' or 'damping', got {part!r}")
    if part == "damping" and v_range is None:
        raise GMRInputError("band_coverage(part='damping') needs v_range, the speeds to measure the damping band on "
                            "(e.g. system.v_range[dof])")
    d = model.n_elements
    xs = np.linspace(*x_range, n)
    if part == "damping":
        vs = np.linspace(*v_range, n_v)
        xs, vs = (a.ravel() for a in np.meshgrid(xs, vs[vs != 0], indexing="ij"))
    else:
        vs = np.zeros_like(xs)
    x = jnp.zeros((xs.size, d)).at[:, dof].set(jnp.asarray(xs))
    v = jnp.zeros((vs.size, d)).at[:, dof].set(jnp.asarray(vs))
    band = jax.vmap(lambda p, q: force_band(model, p, q, part=part, level=level))(x, v)
    f = np.asarray(jax.vmap(truth.restoring)(x) if part == "restoring" else jax.vmap(truth.damping)(x, v))[:, dof]
    low, up, mean = (np.asarray(a)[:, dof] for a in (band.lower, band.upper, band.mean))
    scale = float(np.max(np.abs(f)))
    return BandCoverage(float(np.mean((f >= low) & (f <= up))), float(np.median(up - low)) / scale,
                        float(np.max(np.abs(mean - f))) / scale)
