"""The reconstruction on recordings: one posterior of every well's records (the default), the
paper's route (local STLS fits, then the Hermite coordination) and the GMC-SINDy baseline.

Stages, in order (`reconstruct`):

1. Validate the recordings, settle masses and topology, fill missing v and a (`_resolve`).
2. Group each DOF's recordings into wells by their mean deformation (`_wells`).
3. The global law of each DOF: `_estimator.estimate` (weak-form rows, evidence-optimal
   posterior, cells of one design sharing a law) or, on the paper's route, `_paper`.
4. The model, its standard errors and band from one covariance; training scores.
5. Diagnostics that read the final model (`_estimator.diagnose`); they change nothing.
"""

import warnings as _warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np
import equinox as eqx

from .._config import relieve_map_pressure
from .._coordination._coordinate import coordinate
from .._errors import GMRInputError
from .._fit._library import POSITION_DAMPING, STIFFNESS, VELOCITY_DAMPING, Library
from .._fit._local_fit import AutoThreshold, fit_local
from .._fit._stls import STLS, compress, stls_qr
from .._fit._threshold import default_thresholds, select_threshold
from .._model._admissible import damping_faults, fall_speed, restoring_faults
from .._model._model import GlobalModel
from .._model._predict import forces
from .._recordings._inputs import as_recordings
from .._recordings._recording import Recording, length_unit, regression_targets, validate
from .._solution import RESULTS, GMRComputationError, Solution, as_result
from .._topology import Graph, as_topology
from . import _sanity
from ._estimator import ReconstructSettings, diagnose, equilibria, estimate, model_from
from ._sanity import GMRDataWarning

#: Default STLS for the physics fits: pysindy semantics, normalised columns, no ridge.
DEFAULT_SOLVER = STLS(threshold=0.1, alpha=0.0, normalize_columns=True, unbias=True)
#: Default library: restoring and damping orders 5 (the evidence route reads its damping order without `settings`).
DEFAULT_LIBRARY = Library(5, 5)

#: the global step: one posterior of all wells' records, or the paper's coordination of local fits
ROUTES = ("evidence", "hermite", "gls")


def _resolve(recordings, masses, topology, min_recordings=2):
    """Validate the recordings, settle topology and masses, fill missing v/a; also run the
    checks on the raw data (`_sanity`: masses, clipping, missing input). Returns the completed
    recordings, the masses, the topology and the data warnings."""
    if len(recordings) == 0:
        raise GMRInputError("no recordings given: pass one recording per equilibrium")
    recs = [validate(r, r.name) for r in recordings]
    d = recs[0].n_dof
    for r in recs:
        if not r.equilibrium_observed:
            raise GMRInputError(
                f"{r.name}: x was integrated from {r.integration['from']} (no displacement sensor), so the "
                f"equilibrium it vibrated about is unobservable; a global model needs where each equilibrium "
                f"is: give each recording its rest position as 'equilibrium' (a CSV column 'equilibrium' that "
                f"repeats it, an NPZ key, or Recording(equilibrium=...); --columns equilibrium=VALUE gives every "
                f"file the same value, so it fits one well only), or record x")
        if r.n_dof != d:
            raise GMRInputError(f"{r.name}: has {r.n_dof} DOFs but {recs[0].name} has {d}")
    topology = as_topology(("chain" if d > 1 else "independent") if topology is None else topology)
    warnings = [why] if (why := length_unit(recs)[1]) else []  # refused where the files' units differ
    if masses is None:
        _sanity.check_masses([r.name for r in recs], [r.masses for r in recs])
        found = [r.masses for r in recs if r.masses is not None]
        masses = found[0] if found else np.ones(d)
        if not found and d > 1 and topology.name != "independent":
            # a chain's cells carry the masses beyond them: unit masses are a rescaling only when they are equal
            # (hand-made 2-cell chain, masses 1 and 0.5, none given: cell 0 175 % off, damping x18)
            warnings.append(f"no masses given (none in the recordings, no masses=/--masses): each taken as 1; in a "
                            f"{topology.name} the cells carry the masses beyond them, so the cell forces are right "
                            f"(per unit mass) only if the {d} masses are equal: give them (--masses M0,M1,..., a "
                            f"column m0, m1, ... in each CSV, or Recording(masses=...))")
        forced = [r.name for r in recs if r.force is not None and np.any(np.asarray(r.force) != 0)]
        if not found and forced:
            # a force input does not scale out as a base input does: y = force - m a is wrong for every m but the
            # true one
            warnings.append(f"no masses given (none in the recordings, no masses=/--masses) and {forced[0]}"
                            f"{' and others are' if len(forced) > 1 else ' is'} driven by a force: each mass is taken "
                            f"as 1, and with a force input that is not a rescaling (the fit balances the force "
                            f"against m a): every coefficient is wrong unless the mass is 1 in the force's units; "
                            f"give it (--masses M, a column m in each CSV, or Recording(masses=...))")
    masses = np.asarray(masses, float).reshape(-1)
    if masses.shape[0] != d or np.any(masses <= 0) or not np.all(np.isfinite(masses)):
        raise GMRInputError(f"masses must be {d} positive numbers, got {masses.tolist()}")
    if len(recs) < min_recordings:
        raise GMRInputError(
            f"only {len(recs)} recording(s): the coordination needs small-vibration recordings "
            f"around at least two distinct equilibria (one file per equilibrium)"
        )
    for r in recs:
        warnings += _sanity.check_clipping(r.name, _measured_columns(r))
        warnings += _sanity.check_missing_input(r.name, r.x, r.driven)
        warnings += _sanity.check_units(r.name, r, topology)
        warnings += _sanity.check_acceleration_offset(r.name, r, topology)
    recs = [r.complete(topology) for r in recs]
    warnings += [w for r in recs for w in _sanity.check_force_units(r.name, r, topology, masses)]
    return recs, masses, topology, warnings


def _measured_columns(rec: Recording) -> dict:
    """Label -> samples of every measured (not derived) signal column of a recording."""
    cols = {}
    for key, pre in (("x", "x"), ("v", "v"), ("a", "a"), ("force", "f")):
        val = getattr(rec, key)
        if val is not None and key not in rec.derived:
            cols |= {f"{pre}{i}": val[:, i] for i in range(val.shape[1])}
    if rec.base_acc is not None:
        cols["base_acc"] = rec.base_acc
    return cols


def _emit(warnings: list[str]) -> None:
    for w in warnings:
        _warnings.warn(w, GMRDataWarning, stacklevel=3)


def _wells(recs, i: int, well_tol: float):
    """Group the recordings of DOF `i` into wells (`group_wells`); refuse one well only, or two
    wells that are one well recorded twice (`_sanity.check_distinct_wells`).

    Returns the recording means, their well labels and, per well, the recording indices."""
    means = np.array([r.x[:, i].mean() for r in recs])
    spread = np.ptp(means)
    labels = group_wells(means, well_tol * spread if spread > 0 else 0.0)
    n_wells = labels.max() + 1
    if n_wells < 2:
        raise GMRInputError(
            f"DOF {i}: all recordings are around the same equilibrium (mean x = {means.mean():.4g}); "
            f"the coordination needs recordings around at least two distinct equilibria"
        )
    groups = [[k for k in range(len(recs)) if labels[k] == w] for w in range(n_wells)]
    amps = [_sanity.vibration_amplitude(r.x[:, i]) for r in recs]
    _sanity.check_distinct_wells(
        i, [[recs[k].name for k in g] for g in groups],
        [np.mean([means[k] for k in g]) for g in groups], [min(amps[k] for k in g) for g in groups])
    return means, labels, groups


def group_wells(means: np.ndarray, tol: float) -> np.ndarray:
    """Label recordings whose mean deformation differs by less than `tol` as the same well;
    labels ordered by increasing deformation."""
    order = np.argsort(means)
    labels = np.empty(len(means), int)
    current, last = -1, None
    for i in order:
        if last is None or means[i] - last > tol:
            current += 1
        labels[i] = current
        last = means[i]
    return labels


def _pad_stack(chunks: list[list[np.ndarray]]):
    """Concatenate each group's arrays and pad groups to one length (weight 0 on padding)."""
    cat = [np.concatenate(c) for c in chunks]
    n = max(c.shape[0] for c in cat)
    out = np.zeros((len(cat), n))
    w = np.zeros((len(cat), n))
    for i, c in enumerate(cat):
        out[i, : c.shape[0]] = c
        w[i, : c.shape[0]] = 1.0
    return out, w


@dataclass
class DofReport:
    """What the reconstruction did for one DOF (cell)."""

    equilibria: np.ndarray
    local_coef: np.ndarray
    local_stderr: np.ndarray
    thresholds: np.ndarray
    recordings_per_well: list
    stats: dict = field(default_factory=dict)


class _Failure:
    """The first numerical failure met on the way (a RESULTS code and where), raised at once
    as `GMRComputationError` when `throw`, else kept for the Solution's `result`."""

    def __init__(self, what: str, throw: bool):
        self.what, self.throw = what, throw
        self.code, self.detail = RESULTS.successful, ""

    def note(self, code, detail: str):
        code = as_result(getattr(code, "_value", code))
        if self.throw:
            raise GMRComputationError(self.what, code, detail)
        if self.code == RESULTS.successful:
            self.code, self.detail = code, detail


def _solution(model, failure: _Failure, method, library, reports, training, warnings, recs) -> Solution:
    from .._model._metadata import ranges

    stats = {"method": method, "library": library, "dofs": reports, "training": training,
             "warnings": warnings, "failure": failure.detail,
             "data_range": ranges(recs, "x"), "speed_range": ranges(recs, "v")}
    unit = length_unit(recs)[0]
    if unit is not None:
        stats["units"] = {"length": unit}  # from the files' headers
    return Solution(value=model, result=failure.code, stats=stats)


def training_scores(model: GlobalModel, recs, masses, topology) -> dict:
    """R² and NRMSE of the model force against the measured force, per recording and DOF."""
    out = {}
    for r in recs:
        y = regression_targets(r, masses, topology)
        yhat = forces(model, r.x, r.v)
        resid = np.sum((y - yhat) ** 2, axis=0)
        total = np.sum((y - y.mean(axis=0)) ** 2, axis=0)
        out[r.name] = {"r2": (1 - resid / total).tolist(), "nrmse": np.sqrt(resid / total).tolist()}
    return out


def reconstruct(
    recordings: list[Recording],
    library: Library = DEFAULT_LIBRARY,
    solver: STLS = DEFAULT_SOLVER,
    select: AutoThreshold | None = AutoThreshold(),
    *,
    topology=None,
    masses=None,
    coordination: str = "evidence",
    settings: ReconstructSettings | None = None,
    designs=None,
    throw: bool = True,
    progress: Callable[[str], None] | None = None,
) -> Solution:
    """Global model of each DOF from small-vibration recordings around its equilibria,

        y = f - m a = F(x) + sum_j B_j sgn(v)|v|^j + C(x) v        (Eqs. 1, 8),

    by one of two routes. "evidence" (default): every well's records in weak form (no
    differentiated signal) under one Gaussian prior on the global law, its scales, the restoring
    degree and the wells' noise by the evidence; cells labelled one design share a law as far
    as their data agree (`ReconstructSettings`, `reconstruct_arrays`). "hermite", "gls":
    the paper's route, an STLS fit of the local library at each well (Eqs. 5-10), coordinated by
    the exact Hermite interpolant (Eq. 18) or its covariance-weighted least-squares form.

    **Arguments:**

    - `recordings`: one per equilibrium (per configuration for a chain): `Recording`s, file paths
      or dicts of named signals; missing v and a are estimated from x.
    - `library`, `solver`, `select`: the paper route's local library and STLS (`select=None`:
      `solver.threshold` as given); `library.damping_order` is the evidence route's damping order
      unless `settings` is given.
    - `topology`: "chain" (default for several DOFs), "independent", or a `Graph` (evidence only;
      x: node displacements). `masses`: per DOF (default: the recordings'). `designs`: one label per
      DOF (per element on a `Graph`); those with one label are one design and share one law, as
      far as their data agree on a chain or independent DOFs (default: each its own law).
    - `coordination`: "evidence", "hermite" or "gls".
    - `settings`: a `ReconstructSettings` (degree, damping order, well grouping, window).
    - `throw`: raise `GMRComputationError` on a numerical failure (else read `result`).
    - `progress`: called with a short sentence at each stage, e.g. `print`.

    **Returns:** a `Solution`: `value` the `GlobalModel` with standard errors and `covariance`
    (one covariance: `force_band`, `sample_models`), `result` a `RESULTS` code, `stats` with
    `method`, `library`, `settings`, `dofs` (a `DofReport` per DOF), `training` (R², NRMSE) and
    `warnings` (also issued as `GMRDataWarning`s). User mistakes raise `GMRInputError`.
    """
    recordings = as_recordings(recordings)  # paths and arrays as well as Recordings
    if coordination not in ROUTES:
        raise GMRInputError(f"coordination must be one of {', '.join(map(repr, ROUTES))}, got {coordination!r}")
    if settings is None:
        settings = ReconstructSettings(damping_order=library.damping_order)
    elif coordination == "evidence" and library != DEFAULT_LIBRARY and library.damping_order != settings.damping_order:
        raise GMRInputError(
            f"library.damping_order ({library.damping_order}) and settings.damping_order ({settings.damping_order}) "
            f"disagree; the evidence route reads settings: pass ReconstructSettings(damping_order="
            f"{library.damping_order}, ...) and leave library out")
    if isinstance(topology, Graph):
        return _graph(recordings, topology, designs, coordination, settings, masses, throw, progress)
    relieve_map_pressure()  # a long session's compiled programs (`_config.map_pressure`)
    failure = _Failure("reconstruct", throw)
    say = progress or (lambda msg: None)
    recs, masses, topology, warnings = _resolve(recordings, masses, topology)
    d = recs[0].n_dof
    wells = [_wells(recs, i, settings.well_tol) for i in range(d)]
    if designs is not None and coordination != "evidence":
        raise GMRInputError(f"designs: cells share a law on the 'evidence' route only (the paper's route fits each "
                            f"DOF on its own), got coordination={coordination!r}; drop designs or use the default route")
    if coordination == "evidence":
        blocks, covs, dof_stats = estimate(recs, masses, topology, settings, wells, say, failure,
                                           _labels(designs, d))
        local = [None] * d
    else:
        blocks, covs, dof_stats, local = _paper(recs, masses, topology, wells, library, solver, select,
                                                coordination, say, failure)
    model = model_from(masses, topology, blocks, covs)
    say("training scores and checks")
    training = training_scores(model, recs, masses, topology)
    warnings += diagnose(recs, wells, model, training)
    reports = []
    for i, (_, labels, groups) in enumerate(wells):
        eq = equilibria(recs, i, groups)
        coef, se_l, thr = local[i] if local[i] is not None else (np.zeros((len(groups), 0)),) * 2 + (np.zeros(len(groups)),)
        reports.append(DofReport(equilibria=eq, local_coef=coef, local_stderr=se_l, thresholds=thr,
                                 recordings_per_well=[[recs[k].name for k in g] for g in groups],
                                 stats=dof_stats[i] | {"escapes": _sanity.escapes(np.asarray(model.stiffness[i]), eq)}))
    _emit(warnings)
    sol = _solution(model, failure, "GMR", library, reports, training, warnings, recs)
    sol.stats["settings"] = settings
    return sol


def _paper(recs, masses, topology, wells, library, solver, select, method, say, failure):
    """Stage 3 on the paper's route: per well, the STLS fit of the local library to y = f - m a
    (Eqs. 5-10); per DOF, `coordinate` (Eqs. 12-21) with the covariance propagated from the local
    fits. Returns the blocks, covariances, stats and, per DOF, (local coef, their standard
    errors, thresholds)."""
    d = recs[0].n_dof
    targets = [regression_targets(r, masses, topology) for r in recs]
    blocks, covs, stats, local = [], [], [], []
    for i in range(d):
        _, _, groups = wells[i]
        say(f"{f'DOF {i} ({i + 1}/{d}): ' if d > 1 else ''}local fits at {len(groups)} wells, {method} coordination")
        xs, w = _pad_stack([[recs[k].x[:, i] for k in g] for g in groups])
        vs, _ = _pad_stack([[recs[k].v[:, i] for k in g] for g in groups])
        ys, _ = _pad_stack([[targets[k][:, i] for k in g] for g in groups])
        sols = [fit_local(xs[k], vs[k], ys[k], library, solver, select, weights=w[k], throw=False)
                for k in range(len(groups))]
        for k, sl in enumerate(sols):
            if sl.result != RESULTS.successful:
                failure.note(sl.result, f"DOF {i}, well {k}: local fit")
        fits = _stack([sl.value for sl in sols])
        coord = jax.device_get(coordinate(fits, library, method=method, throw=False))
        if coord.result != RESULTS.successful:
            failure.note(coord.result, f"DOF {i}: coordination of the equilibria "
                         f"{np.asarray(fits.equilibrium).round(6).tolist()}")
        g = coord.value
        blocks.append(tuple(np.asarray(a) for a in (g.stiffness, g.velocity_damping, g.position_damping)))
        covs.append(np.asarray(coord.aux))
        stats.append({"coordination": method} | {k: np.asarray(v).tolist() for k, v in coord.stats.items()})
        coef = np.asarray(fits.coef)
        local.append((coef, np.sqrt(np.clip(np.diagonal(np.asarray(fits.covariance), axis1=1, axis2=2), 0, None)),
                      np.asarray(fits.threshold)))
    return blocks, covs, stats, local


@eqx.filter_jit
def _stack(trees):
    """The trees stacked leaf by leaf (one compiled program, not one eager stack per leaf)."""
    return jax.tree_util.tree_map(lambda *a: jnp.stack(a), *trees)


def _labels(designs, d: int):
    """`designs` as one integer label per DOF, or None."""
    if designs is None:
        return None
    lab = np.asarray(designs)
    if lab.shape != (d,) or not np.issubdtype(lab.dtype, np.integer):
        raise GMRInputError(f"designs must be one integer label per DOF ({d} of them), got {lab.tolist()!r}; "
                            f"DOFs with one label share one law, e.g. {[0] * d} (gmr fit --designs {','.join(['0'] * d)}) for cells "
                            f"of one design")
    return lab


def _graph(recordings, graph, designs, coordination, settings, masses, throw, progress) -> Solution:
    """`reconstruct` on a `Graph` (`_graph`)."""
    from ._graph import reconstruct_graph

    if coordination != "evidence":
        raise GMRInputError(f"a graph is fitted on the 'evidence' route only (its elements' laws are identified "
                            f"jointly from the nodes' balances), got coordination={coordination!r}; use "
                            f"coordination='evidence'")
    relieve_map_pressure()
    say = progress or (lambda msg: None)
    recs, masses, _, warnings = _resolve(recordings, masses, "independent", min_recordings=1)
    sol = reconstruct_graph(recs, masses, graph, designs, settings, say)
    sol.stats["warnings"] = warnings + sol.stats["warnings"]
    sol.stats["settings"] = settings
    _emit(sol.stats["warnings"])
    if throw and sol.result != RESULTS.successful:
        _Failure("reconstruct", True).note(sol.result, "graph: evidence maximisation")
    return sol


def coefficients_to_blocks(coef: np.ndarray, library: Library):
    """Place a library coefficient vector into (stiffness, velocity_damping, position_damping)."""
    coef = np.asarray(coef)
    s = np.zeros(library.restoring_order + 1)
    v = np.zeros(library.damping_order + 1)
    p = np.zeros(library.damping_order + 1)
    for c, (phys, k) in zip(coef, library.terms()):
        {STIFFNESS: s, VELOCITY_DAMPING: v, POSITION_DAMPING: p}[phys][k] = c
    return s, v, p


def gmc_sindy(
    recordings: list[Recording],
    library: Library = Library(7, 7),
    solver: STLS = DEFAULT_SOLVER,
    select: AutoThreshold | None = AutoThreshold(),
    *,
    topology: str | None = None,
    masses=None,
    throw: bool = True,
) -> Solution:
    """The paper's baseline (GMC-SINDy with data assembly, Sec. 2.1): all recordings stacked
    in global coordinates, one global library Θ(x, v), one STLS fit per DOF. Same threshold
    rule as `reconstruct`, so the comparison isolates the method.

    **Returns:** a `Solution` as `reconstruct`'s (`stats["method"]` "GMC-SINDy"). An STLS whose
    support was still changing at `max_iter` is kept (as pysindy does) with a warning in
    `stats["warnings"]`, beside the data checks of `reconstruct` that apply to one global fit
    (masses, clipping, missing input, training R²); a non-finite fit is a failure (`throw`)."""
    recordings = as_recordings(recordings)  # paths and arrays as well as Recordings
    relieve_map_pressure()  # a long session's compiled programs (`_config.map_pressure`)
    failure = _Failure("gmc_sindy", throw)
    recs, masses, topology, warnings = _resolve(recordings, masses, topology, min_recordings=1)
    d = recs[0].n_dof
    targets = [regression_targets(r, masses, topology) for r in recs]
    stiff, vdamp, pdamp, reports = [], [], [], []
    for i in range(d):
        x = jnp.asarray(np.concatenate([r.x[:, i] for r in recs]))
        v = jnp.asarray(np.concatenate([r.v[:, i] for r in recs]))
        y = jnp.asarray(np.concatenate([t[:, i] for t in targets]))
        theta = library(x, v)
        slv = solver
        if select is not None:
            grid = default_thresholds(theta, y, select.n_grid, select.lo)
            sel = select_threshold(theta, y, grid, solver, n_folds=select.n_folds)
            slv = eqx.tree_at(lambda s: s.threshold, solver, sel.value)
        sol = stls_qr(compress(theta, y), slv)
        if sol.result == RESULTS.stls_max_iterations:
            warnings.append(f"DOF {i}: {RESULTS[sol.result]}")
        elif sol.result != RESULTS.successful:
            failure.note(sol.result, f"DOF {i}: global STLS fit")
        s, v_, p = coefficients_to_blocks(np.asarray(sol.value), library)
        stiff.append(s), vdamp.append(v_), pdamp.append(p)
        reports.append(DofReport(equilibria=np.array([]), local_coef=np.asarray(sol.value)[None],
                                 local_stderr=np.full((1, library.n_terms), np.nan),
                                 thresholds=np.asarray(slv.threshold)[None], recordings_per_well=[],
                                 stats={"result": RESULTS[sol.result]}))
    model = model_from(masses, topology, list(zip(stiff, vdamp, pdamp)))
    training = training_scores(model, recs, masses, topology)
    warnings += _sanity.check_fit_quality(training)
    warnings += _baseline_faults(model, recs)
    _emit(warnings)
    return _solution(model, failure, "GMC-SINDy", library, reports, training, warnings, recs)


def _baseline_faults(model: GlobalModel, recs) -> list[str]:
    """GMC-SINDy's model held to GMR's admissibility (a baseline damping law that feeds energy in between the
    wells, or a restoring force with wells the data do not have): per DOF with two or more
    wells (recordings grouped as `reconstruct` groups them), `restoring_faults` over the wells' span widened by half
    of it, and `damping_faults` there up to the speed of a fall from anywhere in that span to the lowest well."""
    out = []
    for i in range(model.n_dof):
        means = np.array([r.x[:, i].mean() for r in recs])
        spread = float(np.ptp(means))
        labels = group_wells(means, ReconstructSettings().well_tol * spread)
        if labels.max() < 1:
            continue
        wells = np.array([means[labels == k].mean() for k in range(labels.max() + 1)])
        k = np.asarray(model.stiffness[i], float)
        half = 0.5 * (wells.max() - wells.min())
        speed = fall_speed(k, wells, float(model.masses[i]), wells.min() - half, wells.max() + half)
        why = restoring_faults(k, wells)
        if speed > 0:
            why += damping_faults(np.asarray(model.velocity_damping[i]), np.asarray(model.position_damping[i]), wells,
                                  speed)
        if why:
            out.append(f"DOF {i}: the GMC-SINDy model is not admissible where it is used (its {wells.size} recorded "
                       f"wells and the span between them, widened by half of it; speeds up to {speed:.3g}, a fall from "
                       f"there to the lowest well): {'; '.join(why)}; simulations of it can gain energy or escape")
    return out
