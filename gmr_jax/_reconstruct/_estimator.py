"""The reconstruction as one statistical model, stage by stage.

1. Validate the recordings, settle masses and topology, fill missing signals (`_resolve`).
2. Group each DOF's recordings into wells by their mean deformation (`_wells`).
3. Per DOF, weak-form rows of the force balance on every record (`_bayes.weak_rows`).
4. Per DOF, the evidence-optimal posterior of the global law (`_bayes.posterior`).
5. The posterior mapped to the model's monomial coefficients: the law, its standard errors and
   its band from one covariance.
6. Diagnostics that read the final posterior (warnings); they change nothing.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._coordination import _bayes
from .._custom_types import Array, Bool, Float, Int
from .._errors import GMRInputError
from .._fit._library import POSITION_DAMPING, STIFFNESS, VELOCITY_DAMPING
from .._model._model import GlobalModel
from .._recordings._derivatives import band_edge
from .._solution import RESULTS
from . import _sanity


class ReconstructSettings(eqx.Module):
    """Every option of the reconstruction.

    **Arguments:**

    - `degree`: highest Chebyshev order of the restoring law; every degree K = 1..`degree` is
      fitted and weighted by its evidence p(K | rows).
    - `damping_order`: highest power d of both damping families.
    - `well_tol`: recordings whose mean deformation differs by less than this fraction of the
      DOF's spread of means are one well.
    - `width`: samples per test-function window; None: one period of the record's band edge
      (the frequency below which 99.5 % of the response's power lies above the noise floor).
    - `tests`: test functions per window (a bump times Legendre polynomials, `_bayes.test_functions`),
      each with its own noise variance per well. One keeps a window's mean balance; more keep the
      shape of the motion inside it (a steady tone's harmonics) but let noise in x and v into the
      regressors at higher frequencies.
    """

    degree: int = eqx.field(static=True, default=13)
    damping_order: int = eqx.field(static=True, default=5)
    well_tol: float = eqx.field(static=True, default=0.1)
    width: int | None = eqx.field(static=True, default=None)
    tests: int = eqx.field(static=True, default=1)


def balances(r, masses, topology) -> tuple[np.ndarray, np.ndarray]:
    """Per mass of recording `r` (N, D each): the pointwise target p and the displacement s whose
    second derivative completes it, y = p + s''. With a measured absolute acceleration a,
    p = force - m a and s = 0; otherwise p = force - m base_acc and s = -m (mass displacement)."""
    b, f = r.inputs()
    if r.a is not None and "a" not in r.derived:
        return f - r.a * masses[None, :], np.zeros_like(r.x)
    return f - b[:, None] * masses[None, :], -topology.displacements(r.x) * masses[None, :]


def _dof_arrays(recs, i: int, masses, topology):
    """Per record of DOF `i`: x, v and the carried `balances` p, s, padded to one length with a
    mask."""
    xs, vs, ps, ss = [], [], [], []
    for r in recs:
        p, s = balances(r, masses, topology)
        xs.append(r.x[:, i]), vs.append(r.v[:, i])
        ps.append(topology.carried(p)[:, i]), ss.append(topology.carried(s)[:, i])
    n = max(len(a) for a in xs)
    pad = lambda arrs: np.stack([np.pad(a, (0, n - len(a))) for a in arrs])  # noqa: E731
    mask = np.stack([np.arange(n) < len(a) for a in xs])
    return pad(xs), pad(vs), pad(ps), pad(ss), mask


def window(signals, dt, n: int, settings: ReconstructSettings) -> int:
    """Samples per test-function window: `settings.width`, else one period of the slowest of
    `signals`' band edges, clipped to [9, n / 16] (n: the shortest record's samples)."""
    if settings.width is not None:
        return int(settings.width)
    edge = min(band_edge(sig, dt) for sig in signals)
    return int(np.clip(round(1.0 / (max(edge, 1e-12) * dt)), 9, max(9, n // 16)))


def reconstruct_arrays(
    x: Float[Array, "records samples"],
    v: Float[Array, "records samples"],
    p: Float[Array, "records samples"],
    s: Float[Array, "records samples"],
    mask: Bool[Array, "records samples"],
    well: Int[Array, " records"],
    *,
    n_wells: int,
    width: int,
    dt: float,
    settings: ReconstructSettings = ReconstructSettings(),
    throw: bool = True,
):
    """The reconstruction of one DOF as a pure function of arrays: weak-form rows, the
    evidence-optimal posterior, and its map to the model's monomial coefficients.

    The force balance y = p + s'' = F(x) + B(v) + C(x) v (see `reconstruct`); for a measured
    absolute acceleration a, p = force - m a and s = 0; where a is not measured, p = force -
    m base_acc and s = -m x (chains: both carried, `AbstractTopology.carried`).

    **Arguments:**

    - `x`, `v`, `p`, `s`, `mask`: (records, samples), records padded to one length, `mask`
      False on the padding.
    - `well`: (records,) the well index of each record, 0..`n_wells` - 1.
    - `n_wells`, `width` (samples per test-function window), `settings`: static.
    - `dt`: the sampling interval.

    **Returns:** `(coef, covariance, solution)`: the monomial coefficients (Q,) in the order
    stiffness x^0..x^K, velocity damping sgn(v)|v|^0..d, position damping x^0..x^d v; their
    covariance (Q, Q); the scaled posterior's `Solution` (its `result` a `RESULTS` code).
    Jittable, vmappable over datasets, differentiable in both modes with respect to the data."""
    basis, geometry, stats = _prepare(x, v, p, s, mask, well, n_wells, width, dt, settings)
    sol = _bayes.posterior(stats, basis, throw=throw)
    M = _bayes.to_monomials(basis, *geometry)
    post = sol.value
    return M @ post.mean, M @ post.covariance @ M.T, sol


def _basis(settings: ReconstructSettings, n_wells: int) -> _bayes.Basis:
    return _bayes.Basis(settings.degree, settings.damping_order, min(2 * n_wells - 1, settings.degree))


def _prepare(x, v, p, s, mask, well, n_wells, width, dt, settings):
    """Stage 3: the basis, the geometry (centre, half-span, speed, target scale) and the wells'
    statistics of the weak-form rows."""
    basis = _basis(settings, n_wells)
    m = mask.astype(x.dtype)
    lo = jnp.min(jnp.where(mask, x, jnp.inf))
    hi = jnp.max(jnp.where(mask, x, -jnp.inf))
    centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    speed = jnp.max(jnp.abs(v) * m)
    t = settings.tests
    rows, target, valid = _bayes.weak_rows(x, v, p, s, mask, centre, half, speed, basis, width, dt, t)
    scale = jnp.sqrt(jnp.sum(valid * target**2) / jnp.maximum(jnp.sum(valid), 1.0))
    group = (well[:, None] * t + jnp.arange(t)[None, :]).reshape(-1)  # (well, test function)
    stats = _bayes.well_factors(rows, target / scale, valid, group, n_wells * t)
    return basis, (centre, half, speed, scale), stats


@eqx.filter_jit
def _fit(x, v, p, s, mask, well, n_wells, settings, width, dt):
    basis, geometry, stats = _prepare(x, v, p, s, mask, well, n_wells, width, dt, settings)
    return geometry, stats, _bayes.posterior(stats, basis, throw=False)


@eqx.filter_jit
def _design(stats, geometry, wells, slope, hyper, basis):
    """The members' posterior under one shared law: the design coordinate u = (x - m_j) / (k l_j)
    puts each member's outer wells at -1/k and 1/k (m_j their midpoint, l_j half their distance),
    k the smallest factor that brings every member's records into [-1, 1]; each law is normalised
    by its slope at its first well (F'(w_0) l_j)."""
    centre, half, _, scale = geometry
    mid, l = 0.5 * (wells[:, 0] + wells[:, 1]), 0.5 * (wells[:, 1] - wells[:, 0])
    k = jnp.max((half + jnp.abs(centre - mid)) / l)
    shift = jax.vmap(lambda a, b: _bayes.chebyshev_shift(a, b, basis.degree))(half / (k * l), (centre - mid) / (k * l))
    maps = (slope * l / scale)[:, None, None] * shift
    last = jax.tree_util.tree_map(lambda a: a[:, -1], hyper)  # each member's hyperparameters at the top degree
    damping_sd = jax.vmap(lambda h: _bayes.prior_sd(h, basis))(last)[:, basis.degree + 1:]
    return _bayes.design_posterior(stats, maps, damping_sd, last.log_noise, basis, throw=False)


def estimate(recs, masses, topology, settings: ReconstructSettings, wells, say, failure, design_labels=None):
    """Stages 3-5 for every DOF of completed recordings (DOFs with one of `design_labels` share a
    law). Returns the model's blocks, per-DOF covariances and per-DOF stats."""
    d = recs[0].n_dof
    k, dd = settings.degree, settings.damping_order
    fits, stats = [], []
    for i in range(d):
        _, labels, groups = wells[i]
        say(f"{f'DOF {i} ({i + 1}/{d}): ' if d > 1 else ''}posterior of the global law")
        width = window([r.x[:, i] for r in recs], recs[0].dt, min(r.n_samples for r in recs), settings)
        x, v, p, s, mask = _dof_arrays(recs, i, masses, topology)
        geometry, wstats, sol = _fit(jnp.asarray(x), jnp.asarray(v), jnp.asarray(p), jnp.asarray(s),
                                     jnp.asarray(mask), jnp.asarray(labels), len(groups), settings, width, recs[0].dt)
        if sol.result != RESULTS.successful:
            failure.note(sol.result, f"DOF {i}: evidence maximisation")
        post, h = sol.value, sol.value.hyper
        fits.append([geometry, wstats, post.mean, post.covariance, h])
        sd = np.sqrt(np.clip(np.diag(np.asarray(post.covariance)), 0, None))
        stats.append({
            "coordination": "evidence",
            "width": width,
            "degree_weight": np.asarray(post.weight).tolist(),
            "degree": (degree := int(np.argmax(np.asarray(post.weight))) + 1),
            "K_r": degree,
            "K_d": int(settings.damping_order),
            "prior_scale": np.exp(np.asarray(h.log_scale)).tolist(),
            "prior_decay": np.asarray(jax.nn.sigmoid(h.logit_decay)).tolist(),
            "damping_prior_sd": np.exp(np.asarray(h.log_ard)).tolist(),
            "noise_sd": np.exp(0.5 * np.asarray(h.log_noise)).reshape(-1, len(groups), settings.tests).tolist(),
            "resolution": (np.abs(np.asarray(post.mean)) / np.maximum(sd, 1e-300)).tolist(),
        })
    maps = [np.asarray(_bayes.to_monomials(_basis(settings, len(wells[i][2])), *fits[i][0])) for i in range(d)]
    for members in designs(design_labels, wells):
        say(f"DOFs {', '.join(map(str, members))}: one design")
        eq = np.stack([equilibria(recs, i, wells[i][2])[[0, -1]] for i in members])
        slope = np.array([np.polynomial.polynomial.polyval(eq[j, 0], np.polynomial.polynomial.polyder(
            (maps[i] @ np.asarray(fits[i][2]))[: k + 1])) for j, i in enumerate(members)])
        stack = lambda *a: jnp.stack(a)  # noqa: E731
        sol = _design(jax.tree_util.tree_map(stack, *[fits[i][1] for i in members]),
                      jax.tree_util.tree_map(stack, *[fits[i][0] for i in members]), jnp.asarray(eq),
                      jnp.asarray(slope), jax.tree_util.tree_map(stack, *[fits[i][4] for i in members]),
                      _basis(settings, len(wells[members[0]][2])))
        if sol.result != RESULTS.successful:
            failure.note(sol.result, f"DOFs {members}: evidence maximisation of the shared law")
        means, covs_, dh = sol.value
        spread = np.exp(np.asarray(dh.log_spread) - np.asarray(dh.log_scale))
        for j, i in enumerate(members):
            fits[i][2], fits[i][3] = means[j], covs_[j]
            stats[i] |= {"design": members, "design_spread": float(spread[j])}
    blocks, covs = [], []
    for i in range(d):
        coef = maps[i] @ np.asarray(fits[i][2])
        blocks.append((coef[: k + 1], coef[k + 1: k + dd + 2], coef[k + dd + 2:]))
        covs.append(maps[i] @ np.asarray(fits[i][3]) @ maps[i].T)
    return blocks, covs, stats


def designs(labels, wells) -> list[list[int]]:
    """The groups of DOFs that share one design: DOFs with one label in `labels` (one per DOF;
    None: none), in groups of two or more. How far each member follows the shared law is the
    evidence's. Members must have the same number (two or more) of wells."""
    if labels is None:
        return []
    by = {}
    for i, lab in enumerate(labels):
        by.setdefault(int(lab), []).append(i)
    out = [m for m in by.values() if len(m) >= 2]
    for m in out:
        counts = {i: len(wells[i][2]) for i in m}
        if len(set(counts.values())) != 1 or min(counts.values()) < 2:
            raise GMRInputError(
                f"designs: DOFs {', '.join(map(str, m))} are labelled one design but have "
                f"{', '.join(f'{n} well(s)' for n in counts.values())} in the recordings; a design's members need the same "
                f"number (two or more) of wells: give them different labels")
    return out


def stack_padded(rows) -> np.ndarray:
    """Stack per-DOF coefficient vectors of different lengths, zero-padded to the longest."""
    n = max(np.asarray(r).shape[0] for r in rows)
    return np.stack([np.pad(np.asarray(r, float), (0, n - np.asarray(r).shape[0])) for r in rows])


def stack_covariances(covs, blocks) -> np.ndarray:
    """Per-DOF covariances of (stiffness, velocity_damping, position_damping) concatenated at
    each DOF's own widths, placed into the padded layout of `GlobalModel.covariance`."""
    widths = [[np.asarray(b).shape[0] for b in block] for block in blocks]
    top = np.max(np.array(widths), axis=0)
    out = np.zeros((len(covs), int(top.sum()), int(top.sum())))
    for i, (c, w) in enumerate(zip(covs, widths)):
        idx = np.concatenate([off + np.arange(n) for off, n in zip(np.cumsum([0, *top[:-1]]), w)])
        out[i][np.ix_(idx, idx)] = np.asarray(c, float)
    return out


def model_from(masses, topology, blocks, covs=None) -> GlobalModel:
    """The `GlobalModel` of per-DOF `blocks` (stiffness, velocity damping, position damping),
    padded to one width; with `covs` (per DOF, over its own blocks), its covariance and the
    standard errors from that covariance's diagonal."""
    stiff, vel, pos = (stack_padded([b[j] for b in blocks]) for j in range(3))
    stderr = cov = None
    if covs is not None:
        cov = stack_covariances(covs, blocks)
        se = np.sqrt(np.clip(np.diagonal(cov, axis1=1, axis2=2), 0.0, None))
        k, dv = stiff.shape[1], vel.shape[1]
        stderr = {STIFFNESS: jnp.asarray(se[:, :k]), VELOCITY_DAMPING: jnp.asarray(se[:, k: k + dv]),
                  POSITION_DAMPING: jnp.asarray(se[:, k + dv:])}
    return GlobalModel(masses=jnp.asarray(masses), stiffness=jnp.asarray(stiff), velocity_damping=jnp.asarray(vel),
                       position_damping=jnp.asarray(pos), topology=topology, stderr=stderr,
                       covariance=None if cov is None else jnp.asarray(cov))


def equilibria(recs, i: int, groups) -> np.ndarray:
    """Each well's equilibrium of DOF `i`: the mean x of its recordings."""
    return np.array([np.mean([recs[k].x[:, i].mean() for k in g]) for g in groups])


def diagnose(recs, wells, model: GlobalModel, training: dict) -> list[str]:
    """Stage 6: warnings that read the data and the final model (they change nothing)."""
    found = []
    names = [r.name for r in recs]
    for i, (_, labels, groups) in enumerate(wells):
        xcol = [r.x[:, i] for r in recs]
        eq = equilibria(recs, i, groups)
        stiff = np.asarray(model.stiffness[i])
        slope = np.polynomial.polynomial.polyval(eq, np.polynomial.polynomial.polyder(stiff))
        swing, swung = _sanity.check_swings(i, names, xcol, labels, eq, slope)
        found += swing + _sanity.check_amplitude(i, names, xcol, labels, eq, skip=swung)
        found += _sanity.check_scales(i, names, xcol, labels)
        amps = [max(_sanity.vibration_amplitude(xcol[k]) for k in grp) for grp in groups]
        found += _sanity.check_global_shape(i, stiff, eq, amps, slope)
    return found + _sanity.check_fit_quality(training)
