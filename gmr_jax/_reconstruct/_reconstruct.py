"""The end-to-end reconstruction of Algorithm 1 on recordings, and the GMC-SINDy baseline."""

import warnings as _warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._config import relieve_map_pressure
from .._coordination._coordinate import GlobalCoefficients, coordinate, split_flat
from .._coordination._discrepancy import add_discrepancy, calibrate_covariance, discrepancy
from .._coordination._joint import CONFLICT as JOINT_CONFLICT
from .._coordination._joint import (
    JointSettings,
    RowFilter,
    damping_faults,
    fall_speed,
    joint_coordinate,
    restoring_faults,
    row_filter,
)
from .._errors import GMRInputError
from .._fit._library import POSITION_DAMPING, STIFFNESS, VELOCITY_DAMPING, Library
from .._fit._local_fit import AutoThreshold, LocalFit
from .._fit._stls import STLS, compress, stls_qr
from .._fit._threshold import default_thresholds, select_threshold
from .._model._model import GlobalModel
from .._model._predict import forces
from .._recordings._derivatives import TONAL, apply_gain, band_edge, tonal_fraction
from .._recordings._inputs import as_recordings
from .._recordings._recording import Recording, length_unit, regression_targets, validate
from .._solution import RESULTS, GMRComputationError, Solution, as_result
from .._topology import Graph, as_topology
from . import (
    _design_law,
    _noise,
    _resolution,
    _sanity,
    _shape_prior,
    _velocity_noise,
    _window_check,
)
from ._damping_orders import add_order_vectors, unresolved_orders
from ._damping_slopes import add_slope_vectors, slope_vectors, unresolved_slopes
from ._degree import (
    averaged_parts,
    confine_borrowed,
    degree,
    least_risk_degree,
    mixture,
    odd_degree,
    odd_gls,
    redundancy,
)
from ._filter_gain import gain_segments, matched_target
from ._local_rules import (
    _dissipative_at_rest,
    _extend_damping,
    _extend_position_damping,
    _extend_restoring,
    _fit_wells,
    _one_of_a_group,
    _refit_screened_damping,
    _screen,
    _share_velocity_damping,
    _under_top_order,
    low_order_terms,
)
from ._sanity import GMRDataWarning
from ._slow import band_rows, curvature_only, edge_weights, restore_slow, segments
from ._truncation import with_truncation
from ._velocity_noise import recorded_speed

#: Default STLS for the physics fits: pysindy semantics, normalised columns, no ridge.
DEFAULT_SOLVER = STLS(threshold=0.1, alpha=0.0, normalize_columns=True, unbias=True)


def _resolve(recordings, masses, topology, min_recordings=2, what="fit", exclude_center=False):
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
    recs = [r.complete(topology, exclude_center=exclude_center) for r in recs]  # True: x'' leaves out x(t)
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


def inner_samples(rec: Recording) -> np.ndarray:
    """(N,) 1 where the recording's estimated acceleration is a window's centre estimate, 0 on
    the first and last half-window (scipy's edge fit extrapolates there: ten times the noise,
    correlated with x). All 1 where the accelerations were measured."""
    out = np.ones(rec.n_samples)
    windows = [w for w in ((rec.derivation or {}).get("a") or {}).get("windows", []) if w]
    if windows:
        half = max(windows) // 2
        out[:half], out[rec.n_samples - half:] = 0.0, 0.0
    return out


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


def stack_padded(rows) -> np.ndarray:
    """Stack per-DOF coefficient vectors of different lengths, zero-padded to the longest."""
    n = max(np.asarray(r).shape[0] for r in rows)
    return np.stack([np.pad(np.asarray(r, float), (0, n - np.asarray(r).shape[0])) for r in rows])


def stack_covariances(covs, stiff, vdamp, pdamp) -> np.ndarray:
    """Per-DOF covariances of (stiffness, velocity_damping, position_damping) concatenated at
    each DOF's own widths, placed into the padded layout of `GlobalModel.covariance`."""
    widths = [[np.asarray(b[i]).shape[0] for b in (stiff, vdamp, pdamp)] for i in range(len(covs))]
    top = np.max(np.array(widths), axis=0)
    out = np.zeros((len(covs), int(top.sum()), int(top.sum())))
    for i, (c, w) in enumerate(zip(covs, widths)):
        idx = np.concatenate([off + np.arange(n) for off, n in zip(np.cumsum([0, *top[:-1]]), w)])
        out[i][np.ix_(idx, idx)] = np.asarray(c, float)
    return out


def _model_from_blocks(masses, topology, stiff, vdamp, pdamp, stderr=None, covariance=None) -> GlobalModel:
    return GlobalModel(
        masses=jnp.asarray(masses),
        stiffness=jnp.asarray(stack_padded(stiff)),
        velocity_damping=jnp.asarray(stack_padded(vdamp)),
        position_damping=jnp.asarray(stack_padded(pdamp)),
        topology=topology,
        stderr=stderr,
        covariance=None if covariance is None else jnp.asarray(stack_covariances(covariance, stiff, vdamp, pdamp)),
    )


def training_scores(model: GlobalModel, recs, masses, topology, rows=None) -> dict:
    """R² and NRMSE of the model force against the measured force, per recording and DOF. `rows`: per
    DOF, the low-pass of the joint regression's rows where its accelerations were estimated
    (`_derived_rows`, None elsewhere); those DOFs also get "r2_in_band" (per DOF, None where no
    filter), the R² of both forces low-passed alike (the filter's ends left out), which the fit-quality
    check reads: above the response's band the estimated force is differentiation noise."""
    out = {}
    for r in recs:
        y = regression_targets(r, masses, topology)
        yhat = forces(model, r.x, r.v)
        resid = np.sum((y - yhat) ** 2, axis=0)
        total = np.sum((y - y.mean(axis=0)) ** 2, axis=0)
        out[r.name] = {"r2": (1 - resid / total).tolist(), "nrmse": np.sqrt(resid / total).tolist()}
        if rows is not None and any(f is not None for f in rows):
            band = []
            for i, f in enumerate(rows):
                taps = None if f is None else np.asarray(f.taps, float)
                if taps is None or taps.size >= r.n_samples:
                    band.append(None)
                    continue
                yf, hf = (np.convolve(np.asarray(a)[:, i], taps, mode="valid") for a in (y, yhat))
                tot = float(np.sum((yf - yf.mean()) ** 2))
                band.append(float(1.0 - np.sum((yf - hf) ** 2) / tot) if tot > 0 else None)
            out[r.name]["r2_in_band"] = band
    return out


def _speed(fits: LocalFit, vs, w, mass: float, library: Library) -> float:
    """A generous bound on the speeds a model of this DOF will see: 3 x the recorded ones, or
    the interwell distance times the stiffest well's angular frequency."""
    eq = np.asarray(fits.equilibrium)
    k_max = float(np.max(np.abs(np.asarray(fits.coef)[:, library.column(STIFFNESS, 1)])))
    return max(3.0 * recorded_speed(vs, w), float(np.ptp(eq)) * np.sqrt(k_max / mass))


#: auto coordination: on a paper route whose restoring shape alone is inadmissible and untested by
#: redundant local data, the joint regression replaces it when each well's unexplained variance
#: 1 - R² is at most (1 + this) times the paper route's (the joint explains every well as well).
JOINT_R2_SLACK = 0.25


#: ... and the replacement is chosen among the joint's admissible candidates within this score (-2 log
#: evidence) of the best by the tamest extrapolation (`JointSettings.tie`; 6: "strong" evidence on
#: Kass and Raftery's scale decides, anything less does not)
REPLACEMENT_TIE = 6.0


def _replacement_settings(paper: Solution) -> JointSettings:
    """The joint regression that may replace a paper route of degree K: degrees up to the first
    odd one above K (room to confine; higher degrees fit the wells' data no better and wiggle
    where no datum is). That cap is a choice against wiggles, not the data's limit: no truncation tail in its
    band (`JointSettings.truncation`)."""
    k = int(np.asarray(paper.stats["K_r"]))
    return JointSettings(max_degree=min(max(k + 2 if k % 2 else k + 1, 3), JointSettings().max_degree),
                         tie=REPLACEMENT_TIE, truncation=False)


def _well_r2(g: GlobalCoefficients, xs, vs, ys, w) -> np.ndarray:
    """Per well, the R² of the global law `g` of one DOF on that well's samples (1 where the
    force does not vary and the law reproduces it)."""
    model = GlobalModel(masses=np.ones(1), stiffness=np.asarray(g.stiffness)[None],
                        velocity_damping=np.asarray(g.velocity_damping)[None],
                        position_damping=np.asarray(g.position_damping)[None])
    xs, vs, ys, w = (np.asarray(a) for a in (xs, vs, ys, w))
    yhat = forces(model, xs.reshape(-1, 1), vs.reshape(-1, 1))
    yhat = yhat.reshape(xs.shape)
    out = []
    for k in range(xs.shape[0]):
        m = w[k] > 0
        total = np.sum((ys[k, m] - ys[k, m].mean()) ** 2)
        resid = np.sum((ys[k, m] - yhat[k, m]) ** 2)
        out.append(1.0 - resid / total if total > 0 else (1.0 if resid == 0 else -np.inf))
    return np.array(out)


def _paper_route_faults(coord: Solution, fits: LocalFit, xs, vs, ys, w, speed: float,
                        library: Library) -> dict[str, list[str]]:
    """Why the paper's coordination of one DOF is not to be used, by kind: "data" (it failed,
    or it explains a well's own data poorly: R^2 < `MIN_R2`), "blowup" (it blows up between the
    wells: `_sanity.blowup`), "damping" (`damping_faults`),
    "restoring" (`restoring_faults`); empty lists where it is fine."""
    if coord.result != RESULTS.successful:
        return {"data": [RESULTS[coord.result]], "damping": [], "restoring": [], "blowup": []}
    g = coord.value
    eq = np.asarray(fits.equilibrium)
    faults = {"data": [], "damping": damping_faults(g.velocity_damping, g.position_damping, eq, speed),
              "restoring": restoring_faults(g.stiffness, eq), "blowup": []}
    for x0, r2 in zip(eq, _well_r2(g, xs, vs, ys, w)):
        if not r2 >= _sanity.MIN_R2:
            faults["data"].append(f"it explains the data of the well at x = {float(x0):.4g} poorly (R² {r2:.3g})")
    # an interpolant that blew up between the wells (rule 9 c) explains each well's own data, yet no
    # datum supports it where it is used
    b = _sanity.blowup(g.stiffness, eq, np.asarray(fits.coef)[:, library.column(STIFFNESS, 1)])
    if b is not None:
        faults["blowup"].append(f"it blows up between the wells (|F| reaches {b['force']:.4g} at x = {b['x']:.4g}, "
                              f"{b['ratio']:.3g} times the largest local stiffness times the wells' distance)")
    return faults


#: the paper route's exact law is not supported where two standard errors of its restoring force (propagated
#: from the local fits) exceed this share of it between the wells (RMS): a term kept at a few standard
#: errors, exact in the interpolant (`_undetermined`)
UNDETERMINED = 0.25
def _undetermined(coord: Solution, fits: LocalFit) -> float:
    """Two standard errors of the paper route's restoring force over the wells' span (RMS; the coordination's
    covariance, propagated from the local fits), relative to the force's RMS there; 0 where not finite."""
    eq = np.asarray(fits.equilibrium, float)
    k = np.asarray(coord.value.stiffness, float)
    cov = np.asarray(coord.aux, float)[: k.size, : k.size]
    if eq.size < 2 or not (np.all(np.isfinite(cov)) and np.all(np.isfinite(k))):
        return 0.0
    phi = np.polynomial.polynomial.polyvander(np.linspace(eq.min(), eq.max(), 201), k.size - 1)
    sd = np.sqrt(np.clip(np.einsum("ij,jk,ik->i", phi, cov, phi), 0.0, None))
    return float(2.0 * np.linalg.norm(sd) / max(np.linalg.norm(phi @ k), 1e-300))


def _joint_explains_as_well(joint: Solution, paper: Solution, xs, vs, ys, w) -> tuple[bool, str]:
    """Whether the joint regression is admissible and explains every well's data about as well
    as the paper route (`JOINT_R2_SLACK`); the reason where not."""
    if joint.result != RESULTS.successful or not joint.stats.get("joint_admissible", False):
        return False, "the joint regression found no admissible model"
    rj, rp = _well_r2(joint.value, xs, vs, ys, w), _well_r2(paper.value, xs, vs, ys, w)
    worse = (1.0 - rj) > (1.0 + JOINT_R2_SLACK) * (1.0 - rp)
    if np.any(worse):
        k = int(np.argmax(worse))
        return False, f"the admissible joint regression explains a well's data worse (R² {rj[k]:.6g} against {rp[k]:.6g})"
    return True, ""



def _steady_sines(recordings, dofs=None) -> bool:
    """Whether a recording is a steady sine in some DOF (of `dofs`, default all; `tonal_fraction` >=
    `TONAL`)."""
    return any(tonal_fraction(r.x[:, i], r.dt) >= TONAL for r in recordings if r.x is not None
               for i in (range(r.x.shape[1]) if dofs is None else dofs) if np.ptp(r.x[:, i]) > 0)


def _derived_rows(recs, groups, i: int) -> RowFilter | None:
    """The joint regression's row filter of DOF `i` (`row_filter`) where its wells' accelerations
    were estimated: cut from the highest 99.5 % band edge of their x; None where the recordings'
    sampling steps differ (the padded rows are filtered sample by sample) or where a record is a
    steady sine (`tonal_fraction` >= `TONAL`): its nonlinearity speaks through the harmonics, above the
    cut."""
    members = [recs[k] for g in groups for k in g]
    dts = np.array([r.dt for r in members])
    if np.ptp(dts) > 1e-6 * dts.max():
        return None
    if _steady_sines(members, [i]):
        return None
    edge = max(band_edge(r.x[:, i], r.dt) for r in members)
    return row_filter(float(dts[0]), edge) if edge > 0 else None


def _joint(fits: LocalFit, xs, vs, ys, w, speed: float, restoring: Solution | None = None,
           settings: JointSettings = JointSettings(), x_noise=None, rows: RowFilter | None = None,
           segs=None, gain=None, v_noise=None) -> Solution:
    """The joint coordination (`joint_coordinate`) as a `Solution` like `coordinate`'s; given
    the paper route's `restoring` (a `coordinate` Solution), only the damping is refitted,
    to the force left after its restoring force. `x_noise`: per well, the variance of the noise
    on x (None where any well has none): the regression is corrected for it. `rows`: the low-pass
    of rows whose target holds estimated accelerations (`row_filter`). `segs`: per well, its records'
    slow bands where x was integrated (`_slow.segments`), taken out of the rows. `gain`: where the
    accelerations were estimated, `(segments, ys)`: per well its records' filter gains
    (`_filter_gain.gain_segments`, from x only), through which the columns pass, and the targets with their inputs through
    them (`_filter_gain.matched_target`), which replace `ys`."""
    eq = np.asarray(fits.equilibrium)
    gain_segs = None
    if gain is not None:
        gain_segs, ys = gain
    var = np.asarray(fits.rss) / np.maximum(np.asarray(fits.n_samples), 1.0)
    var = np.where(var > 0, var, np.max(var) if np.any(var > 0) else 1.0)
    # the noise of a measured v (`_joint._velocity_noise`), where every well has it
    v_eiv = None if v_noise is None or any(v is None for v in v_noise) else np.asarray(v_noise, float)
    if restoring is None:
        eiv = None if x_noise is None or any(v is None for v in x_noise) else np.asarray(x_noise, float)
        stiff, vdamp, pdamp, cov, stats = joint_coordinate(xs, vs, ys, w, eq, var, speed, settings, x_noise=eiv,
                                                           rows=rows, band=segs, gain=gain_segs, v_noise=v_eiv)
    else:
        stiff = np.asarray(restoring.value.stiffness)
        fx = np.polynomial.polynomial.polyval(np.asarray(xs), stiff)
        if gain_segs is not None:
            fx = np.stack([apply_gain(sg, f) for sg, f in zip(gain_segs, fx)])
        ys = np.asarray(ys) - fx
        settings = JointSettings(log_lambdas=(0.0,), damping_only=True)

        _, vdamp, pdamp, cov_j, stats = joint_coordinate(xs, vs, ys, w, eq, var, speed, settings, rows=rows,
                                                         band=segs, gain=gain_segs, v_noise=v_eiv)
        nk, nj = stiff.shape[0], cov_j.shape[0] - (settings.max_degree + 1)
        cov = np.zeros((nk + nj, nk + nj))
        cov[:nk, :nk] = np.asarray(restoring.aux)[:nk, :nk]
        cov[nk:, nk:] = cov_j[settings.max_degree + 1 :, settings.max_degree + 1 :]
        # prior-data conflict (`_joint.CONFLICT`): the data reject every admissible damping law; the one they
        # prefer differs from the chosen one by a discrepancy of its form, not noise, which enters whole (as on
        # the joint route, `_calibrated`)
        free = np.asarray(stats.get("joint_unconstrained", []), float)[settings.max_degree + 1 :]
        if free.size == nj and float(stats.get("joint_conflict", 0.0)) > JOINT_CONFLICT:
            cov[nk:, nk:] += np.outer(free, free)
        stats = restoring.stats | stats
    g = GlobalCoefficients(jnp.asarray(stiff), jnp.asarray(vdamp), jnp.asarray(pdamp))
    if restoring is None:
        stats |= {"K_r": stats["joint_degree"], "cond_r": 0.0}
    stats |= {"K_d": stats["joint_damping_degree"], "cond_d": 0.0}
    finite = bool(np.all(np.isfinite(np.asarray(g.flat()))))
    return Solution(value=g, result=RESULTS.successful if finite else RESULTS.nonfinite, stats=stats,
                    aux=jnp.asarray(cov))


def _calibrated(coord: Solution, fits: LocalFit, library: Library, route: str, paper_sound: bool,
                confining: bool = False):
    """One DOF's global coefficients and their calibrated covariance (`_discrepancy`): the
    paper route's propagated covariance with its residual scale and embedded-error discrepancy;
    the joint regression's posterior covariance plus its degree choice's discrepancy (the best
    admissible law of another degree, `joint_alternative`) and, where the paper route's local
    Taylor data were sound (each well explained: `paper_sound`), the paper route's embedded-error
    discrepancy (blocks padded where that is longer). Returns `(GlobalCoefficients, covariance)`."""
    g, cov = coord.value, np.asarray(coord.aux)
    if not np.all(np.isfinite(cov)) or not np.all(np.isfinite(np.asarray(g.flat()))):
        return g, cov
    if route == "joint":
        alt = np.asarray(coord.stats.get("joint_alternative", np.zeros(cov.shape[0])), float)
        # prior-data conflict (`_joint.CONFLICT`): the data reject every admissible law; the one they prefer
        # (inadmissible: a spurious well or an escape where no datum is) differs from the chosen one by
        # `joint_unconstrained`, a discrepancy of the chosen law's form, not noise: it enters whole
        free = np.asarray(coord.stats.get("joint_unconstrained", np.zeros(cov.shape[0])), float)
        cov = cov + np.outer(alt, alt) + np.outer(free, free)
        if not paper_sound:
            return g, cov
        s, b, p, cov = add_discrepancy(g.stiffness, g.velocity_damping, g.position_damping, cov, fits, library)
        return GlobalCoefficients(jnp.asarray(s), jnp.asarray(b), jnp.asarray(p)), cov
    def bound(cap):  # a borrowed law lowered to confine (`confine_borrowed`) or to average with
        return None if cap is None else jnp.asarray(int(cap))

    averaged = route in ("gls", "gls + joint damping") and "averaged_weight" in coord.stats
    parts = averaged_parts(coord, fits, library) if averaged else None
    if parts is not None:  # a borrowed law averaged with a lower degree (`least_risk_degree`): each calibrated
        cals = [calibrate_covariance(fits, library, np.asarray(sol.aux), method="gls", confining=confining,
                                     max_degree=bound(cap)) for sol, cap in parts]
        mixed = mixture(parts[0][0], parts[1][0], float(coord.stats["averaged_weight"]), cals)
        if route == "gls":
            return g, mixed
        # the joint damping's block as the joint regression gave it (as for a law not averaged)
        ns = np.asarray(g.stiffness).shape[0]
        cov = np.array(cov, float)
        cov[:ns, :ns] = mixed[:ns, :ns]
        return g, cov
    cap = bound(coord.stats.get("max_degree_r"))
    if route == "gls + joint damping":
        cov = calibrate_covariance(fits, library, cov, method="gls", damping=False, confining=confining,
                                   max_degree=cap)
    else:
        cov = calibrate_covariance(fits, library, cov, method=route, confining=confining, max_degree=cap)
    spread = np.asarray(coord.stats.get("truncation_alternative", []), float)  # `_truncation_degree`
    if spread.size:
        cov = np.array(cov, float)
        cov[: spread.size, : spread.size] += np.outer(spread, spread)
    return g, cov


def _systematic(coord: Solution, fits: LocalFit, library: Library, route: str, confining: bool, cov) -> np.ndarray | None:
    """The part of a DOF's calibrated covariance `cov` that is its restoring law's embedded error (`_discrepancy`:
    the interpolant's difference from its neighbours in the degree sequence, from this DOF's local Taylor data), as
    sum d d' on the restoring block: systematic, shared by cells of one design whose laws are interpolated alike
    (`_design_law`). None where `cov` does not hold it whole (cov minus it not positive semi-definite: an averaged
    or a joint law without the paper route's discrepancy)."""
    cap = coord.stats.get("max_degree_r")
    method = "hermite" if route == "hermite" else "gls"
    try:
        vectors = discrepancy(fits, library, method=method, confining=confining,
                              max_degree=None if cap is None else jnp.asarray(int(cap)))["restoring"][0]
    except Exception:  # noqa: BLE001 - a discrepancy that cannot be formed: nothing known to be systematic
        return None
    cov = np.asarray(cov, float)
    out = np.zeros_like(cov)
    for d in vectors:
        full = np.zeros(cov.shape[0])
        if d.size > cov.shape[0]:
            return None
        full[: d.size] = d
        out += np.outer(full, full)
    rest = cov - out
    if not np.all(np.isfinite(rest)) or np.linalg.eigvalsh(0.5 * (rest + rest.T)).min() < -1e-9 * max(
            float(np.trace(np.abs(cov))), 1e-300):
        return None
    return out


def _truncation_degree(coord: Solution, fits: LocalFit, xs, vs, ys, w, library: Library, band=None):
    """The paper route's restoring degree chosen from the local fits one restoring order higher
    (`_truncation.with_truncation`: where the next Taylor term biases the kept ones, the chi-squared test
    rejects the true degree), the law then fitted at that degree from the fits as they were (its
    `stats["max_degree_r"]`: the calibration takes the same bound), with the spread to the next odd
    degree's law as a discrepancy of the degree choice (`stats["truncation_alternative"]`, added to the
    calibrated band). Where that degree is not lower, `coord` as it was. Returns `(coord, notes)`."""
    probe = jax.device_get(coordinate(with_truncation(fits, xs, vs, ys, w, library, band), library, method="gls",
                                      throw=False))
    k0, k = int(coord.stats["K_r"]), int(probe.stats["K_r"])
    if probe.result != RESULTS.successful or coord.result != RESULTS.successful or k >= k0:
        return coord, []
    alt = jax.device_get(coordinate(fits, library, method="gls", max_degree=jnp.asarray(k), throw=False))
    if alt.result != RESULTS.successful or not np.all(np.isfinite(np.asarray(alt.value.flat()))):
        return coord, []
    alt.stats["max_degree_r"] = k
    # the degree choice's discrepancy: the next odd degree's law less this one, in the band (`_calibrated`)
    other = odd_gls(fits, library, k + 2)
    other = coord if other is None else other
    alt.stats["truncation_alternative"] = (np.asarray(other.value.stiffness, float)
                                           - np.asarray(alt.value.stiffness, float)).tolist()
    return alt, [f"degree {k} instead of {k0}: the local conditions' misfit at degree {k} is within the "
                 f"truncation of their Taylor series (chi-squared p = {float(probe.stats['p_r']):.3g} with the "
                 f"local fits one restoring order higher)"]


def _coordinate_dof(fits: LocalFit, xs, vs, ys, w, library: Library, coordination: str, mass: float, i: int,
                    odd_only: bool = False, x_noise=None, rows: RowFilter | None = None, band=None, segs=None,
                    gain=None, v_noise=None):
    """One DOF's coordination route (`reconstruct`'s `coordination`; "auto": the paper route, GLS,
    checked for inadmissible shapes and faults, replaced or complemented by the joint regression where
    the module's rules say so). `odd_only`: the GLS takes odd degrees only (a DOF that borrowed
    orders, `_shape_prior`). Returns `(coord, route, why, paper_sound, confining, warnings)`."""
    warnings = []
    why, route = [], "gls" if coordination == "auto" else coordination
    paper_sound = False  # the paper route's local Taylor data explain every well (auto only)
    confining = False  # the GLS restoring degree restricted to odd ones (auto only, `odd_degree`)
    speed = _speed(fits, vs, w, mass, library) if coordination in ("auto", "joint") else None
    energy = None if speed is None else 0.5 * float(mass) * speed**2  # the model's energy bound
    lowered = []  # why the degree was lowered: to confine a borrowed law, or by the truncation test
    if coordination == "joint":
        coord = _joint(fits, xs, vs, ys, w, speed, x_noise=x_noise, rows=rows, segs=segs, gain=gain, v_noise=v_noise)
    else:
        coord = jax.device_get(coordinate(fits, library, method="gls" if coordination == "auto" else coordination,
                                          confining=odd_only, throw=False))
        if coordination == "auto" and odd_only:
            coord, lowered = confine_borrowed(coord, fits, library, energy)
            coord, risk_notes = least_risk_degree(coord, fits, library, energy)
            lowered = lowered + risk_notes
        elif coordination == "auto":
            coord, lowered = _truncation_degree(coord, fits, xs, vs, ys, w, library, band)
        if coordination == "auto":
            faults = _paper_route_faults(coord, fits, xs, vs, ys, w, speed, library)
            why = faults["restoring"] + faults["damping"] + faults["data"] + faults["blowup"]
            paper = coord
            paper_sound = not faults["data"]
            if faults["data"]:
                coord, route = _joint(fits, xs, vs, ys, w, speed, x_noise=x_noise, rows=rows, segs=segs, gain=gain, v_noise=v_noise), "joint"
            elif faults["blowup"]:  # it explains the wells' data, its shape between them is the fault
                coord, route = _joint(fits, xs, vs, ys, w, speed, settings=_replacement_settings(paper),
                                      x_noise=x_noise, rows=rows, segs=segs, gain=gain, v_noise=v_noise), "joint"
            else:
                # A restoring shape that is inadmissible (even degree, turning outward, extra sign changes)
                # is the paper's verdict only where redundant local data test it (the over-determined GLS:
                # the NES, whose truth turns outward 0.5 spans beyond its outer wells). The exact
                # interpolant's shape away from the wells is extrapolation (single-tone arch: a quintic
                # from F, F', F'' at two wells turns outward 0.9 spans out and diverges on cross-well
                # motion): the joint regression replaces it where it explains every well as well.
                # Redundant conditions confirm a law that turns outward (the NES truth does, and crosses zero again
                # within the span checked), never an even degree: that comes from a term resolved at some wells
                # only, or from local coefficients the truncated Taylor series biased
                even = degree(paper.value.stiffness) % 2 == 0
                unconfirmed = bool(faults["restoring"]) and (redundancy(paper) == 0 or even)
                # ... and only where the motions the model is used on reach the escape
                reach = _sanity.reachable_escapes(paper.value.stiffness, fits.equilibrium, energy)
                # An even degree (a term resolved at some wells only) gives way to the highest odd degree
                # below it, fitted to all the local conditions, where that one is admissible and the
                # conditions do not reject it (`odd_degree`)
                odd = odd_degree(paper, fits, library, energy) if unconfirmed else None
                if odd is not None:
                    coord = paper = odd
                    confining, unconfirmed = True, False
                    fit = (f"chi-squared p = {float(odd.stats['p_r']):.3g}" if float(odd.stats["dof_r"]) > 0 else
                           "as many conditions as coefficients: it interpolates them")
                    why = why + [f"replaced by the odd degree-{int(odd.stats['K_r'])} law fitted to all the local "
                                 f"conditions (an even degree cannot confine; {fit})"]
                # ... but an even degree cannot confine on both sides whatever the bound says (a paper law
                # replaced by the odd degree above is no longer unconfirmed, so `even` is still that of the law
                # this test judges)
                if unconfirmed and not reach and not even:
                    why = why + ["kept: no motion within the model's energy bound "
                                 f"({energy:.3g}) reaches an escape"]
                    unconfirmed = False
                # ... and an exact law whose local data do not determine it between the wells (a term kept at a
                # few standard errors) is the interpolant of noise there: the joint regression weighs the data
                spread = _undetermined(paper, fits)
                if spread > UNDETERMINED and not unconfirmed:
                    why = why + [f"the local data determine its restoring force between the wells only to "
                                 f"±{100 * spread:.3g} % (two standard errors, RMS)"]
                    unconfirmed = True
                if unconfirmed:
                    cand = _joint(fits, xs, vs, ys, w, speed, settings=_replacement_settings(paper), x_noise=x_noise,
                                  rows=rows, segs=segs, gain=gain, v_noise=v_noise)
                    ok, reason = _joint_explains_as_well(cand, paper, xs, vs, ys, w)
                    if ok:
                        coord, route = cand, "joint"
                    else:
                        why = why + [f"kept: {reason}"]
                if route == "gls" and faults["damping"]:
                    coord, route = _joint(fits, xs, vs, ys, w, speed, restoring=paper, rows=rows, segs=segs, gain=gain, v_noise=v_noise), "gls + joint damping"
                elif route == "gls" and segs is None and _velocity_noise.worth_measuring(fits, v_noise, vs, w, library,
                                                                                          gain):
                    # ... and where the noise of a measured v, which the local fits take as exact, moves the damping
                    # (not where the columns pass a filter gain or a slow band: the joint regression does not correct
                    # for it there)
                    corrected = _joint(fits, xs, vs, ys, w, speed, restoring=paper, rows=rows, segs=segs, gain=gain,
                                       v_noise=v_noise)
                    moved = _velocity_noise.moved(corrected, fits, vs, w)
                    if (moved > _velocity_noise.V_NOISE_DAMPING and corrected.result == RESULTS.successful
                            and corrected.stats.get("joint_admissible", False)):
                        coord, route = corrected, "gls + joint damping"
                        why = why + [f"damping: the noise of the measured v moves it by {moved:.3g} standard errors "
                                     "(RMS over the wells' span and the recorded speeds); the joint regression's, "
                                     "corrected for it, replaces the local fits'"]
                if route != "joint" and unconfirmed:
                    warnings += _sanity.check_escape_reach(i, np.asarray(paper.value.stiffness),
                                                           np.asarray(fits.equilibrium), energy)
                elif route != "joint" and faults["restoring"] and redundancy(paper) > 0 and not confining:
                    why = why + [f"kept: {redundancy(paper)} local conditions beyond the global law's "
                                 f"coefficients confirm its shape"]
    if lowered:
        coord.stats["degree_notes"] = lowered  # why a borrowed law has the degree it has (`_degree`)
    return coord, route, lowered + why, paper_sound, confining, warnings  # in the order they were decided


def _v_noise_report(v_noise, applied: bool) -> list[dict | None]:
    """Per well, the joint regression's correction for the noise on a measured v
    (`_joint._velocity_noise`): the noise's sd and whether it was applied (the coordination's
    `joint_velocity_noise`). None: not applicable."""
    return [None if s is None else {"noise_sd": float(np.sqrt(s)), "applied": bool(applied)} for s in v_noise]


def _eiv_report(x_noise, xs, w, applied) -> list[dict | None]:
    """Per well, the errors-in-variables correction of its local fit: the noise on x (sd, and
    relative to the sd of the vibration) and whether it was applied (None: not applicable)."""
    out = []
    for k, var in enumerate(x_noise):
        if var is None:
            out.append(None)
            continue
        wk = np.asarray(w[k], float)
        xk = np.asarray(xs[k], float)
        mean = np.sum(wk * xk) / np.sum(wk)
        sd_q = float(np.sqrt(np.sum(wk * (xk - mean) ** 2) / np.sum(wk)))
        sd = float(np.sqrt(var))
        out.append({"noise_sd": sd, "of_vibration": sd / sd_q if sd_q > 0 else float("inf"),
                    "applied": bool(np.asarray(applied)[k]) if applied is not None else False})
    return out


def _borrow(fits: LocalFit, plan: list[dict], xs, vs, ys, w, library: Library, x_noise=None, band=None):
    """Refit the wells of one DOF that borrow orders (`_shape_prior.refit_with_prior`); returns the
    fits and, per well, the orders borrowed."""
    eq = np.asarray(fits.equilibrium, float)
    span = float(eq[-1] - eq[0])
    coef, cov = np.array(fits.coef, float), np.array(fits.covariance, float)
    borrowed = []
    for k, borrow in enumerate(plan):
        if borrow:
            coef[k], cov[k] = _shape_prior.refit_with_prior(
                xs[k] - eq[k], vs[k], ys[k], w[k], library, coef[k], float(fits.rss[k]),
                float(fits.n_samples[k]), span, borrow, x_noise=(x_noise or [None] * len(plan))[k],
                band=(band or [None] * len(plan))[k])
        borrowed.append(sorted(borrow))
    return eqx.tree_at(lambda f: (f.coef, f.covariance), fits, (coef, cov)), borrowed


#: `_pool_laws` says so where pooling narrowed a DOF's band between the wells by more than this factor (rms standard
#: deviation over the nodes)
DESIGN_NARROWING = 3.0


def _pool_laws(stiff: list, vdamp: list, pdamp: list, covs: list, reports: list, recs, noise=None) -> list[str]:
    """`_design_law.pool_design_laws` on every DOF's law and calibrated covariance, in place; the
    outcome per DOF goes to `reports[i].stats["shared_design"]["law"]`. Returns the warnings of the DOFs whose band
    between the wells the pooling narrowed by more than `DESIGN_NARROWING` (cells whose laws err alike, one
    non-polynomial shape interpolated from the same Taylor orders, agree with each other: the pooling cannot tell a
    shared error from a shared law)."""
    said = []
    sizes = [(a.size, b.size, c.size) for a, b, c in zip(stiff, vdamp, pdamp)]
    ok = [np.asarray(cv).shape == (sum(n),) * 2 for cv, n in zip(covs, sizes)]
    flats = [np.concatenate([a, b, c]) for a, b, c in zip(stiff, vdamp, pdamp)]
    idx = [i for i in range(len(flats)) if ok[i]]
    ranges = [np.concatenate([reports[i].equilibria, [min(float(r.x[:, i].min()) for r in recs),
                                                      max(float(r.x[:, i].max()) for r in recs)]])
              for i in range(len(flats))]  # where each DOF's wells are looked for
    new_f, new_c, law = _design_law.pool_design_laws([flats[i] for i in idx], [sizes[i][0] for i in idx],
                                                     [covs[i] for i in idx], [ranges[i] for i in idx],
                                                     None if noise is None else [noise[i] for i in idx])
    members = [idx[k] for k in law["members"]]
    for k, i in enumerate(idx):
        ns, nv, _ = sizes[i]
        stiff[i], vdamp[i], pdamp[i] = new_f[k][:ns], new_f[k][ns:ns + nv], new_f[k][ns + nv:]
        covs[i] = new_c[k]
        entry = {"cells": members, "tau": law["tau"]}
        if k in law["per_dof"]:
            entry |= law["per_dof"][k]
            before, after = entry["sd_before"], entry["sd_after"]
            if after > 0 and before > DESIGN_NARROWING * after:
                said.append(
                    f"DOF {i}: its band between the wells is the design's: cells {members} pooled as one design (their "
                    f"laws {100 * (law['tau'] or 0.0):.3g} % apart beyond their noise) narrowed it from an rms "
                    f"standard deviation of {100 * before:.3g} % to {100 * after:.3g} % of F'(w0) L. That holds only "
                    f"if the cells share one law: fitted laws that agree can still share one error (a non-polynomial "
                    f"law interpolated alike from the same Taylor orders), which pooling cannot see; fit with "
                    f"--no-shared-design (shared_design=False) for the DOF's own band, or record motion between the "
                    f"wells to check it")
        else:
            entry["why"] = law["excluded"].get(k, "not pooled")
        reports[i].stats.setdefault("shared_design", {})["law"] = entry
    for i in range(len(flats)):
        if not ok[i]:
            reports[i].stats.setdefault("shared_design", {})["law"] = {"why": "its covariance is missing"}
    return said


def _design_stats(design: dict | None, i: int, borrowed: list, why: str | None = None,
                  coord: Solution | None = None) -> dict:
    """`dofs[i].stats["shared_design"]`: the orders this DOF borrowed per well, the lending cells,
    the cells' estimated design spread tau, or why this DOF took no part; for a DOF that borrowed,
    its global restoring degree and why it has that degree (`_degree`)."""
    if design is None:
        return {"used": False, "why": "off or a single DOF"}
    out = {"tau": design["tau"], "cells": design["members"], "borrowed": borrowed,
           "used": any(borrowed)}
    if any(borrowed) and coord is not None:
        out["degree"] = int(coord.stats["K_r"])
        out["degree_notes"] = list(coord.stats.get("degree_notes", []))
    if i in design["excluded"] or why:
        out["why"] = why or design["excluded"][i]
    return out


def reconstruct(
    recordings: list[Recording],
    library: Library = Library(5, 5),
    solver: STLS = DEFAULT_SOLVER,
    select: AutoThreshold | None = AutoThreshold(),
    *,
    topology: str | None = None,
    masses=None,
    well_tol: float = 0.1,
    screen_sigma: float | None = 3.0,
    coordination: str = "auto",
    settings=None,
    keep_low_orders: bool = True,
    keep_restoring_order: int | None = None,
    shared_damping: bool = True,
    extend_restoring: bool | None = None,
    shared_design: bool | None = None,
    structured_noise: bool | None = None,
    errors_in_variables: bool = True,
    velocity_eiv: bool = True,
    designs=None,
    throw: bool = True,
    progress: Callable[[str], None] | None = None,
) -> Solution:
    """Global model reconstruction (Algorithm 1) from small-vibration recordings around each equilibrium.

    At each well k of DOF i, the force the DOF carries, y = f - m a (Eq. 8), is regressed on the local library
    Theta(x - x_k, v) (Eqs. 5-7); the wells' Taylor coefficients are then coordinated into one global law
    (Eqs. 12-21), y = F(x) + C(x) v + sum_j B_j sgn(v)|v|^j. The cases behind each default are in
    docs/explanation/reconstruction-defaults.md.

    **Arguments:**

    - `recordings`: one per equilibrium (per configuration for a chain): `Recording`s, file paths
      (`load_recording`) or dicts of named signals; missing v and a are estimated from x.
    - `library`: local library orders r, d (Eqs. 5-7). `solver`, `select`: the STLS settings (`select=None`:
      `solver.threshold` as given).
    - `topology`: "chain" (default for several DOFs), "independent", or a `Graph` (x: node displacements; the
      "evidence" route only: every element's law from every node's balance). `masses`: per DOF (default: the
      recordings'). `designs`: on a `Graph`, one label per element; elements with one label share one law.
    - `well_tol`: recordings whose mean deformation differs by less than this fraction of the cell's spread are one well.
    - `screen_sigma`: local terms under this many standard errors are zeroed before the coordination (None: kept).
    - `coordination`: "auto", "gls", "hermite" (the paper's exact interpolant) or "evidence" (one posterior over
      every well's records, `reconstruct_arrays`; only `settings`, `masses`, `topology`, `throw`, `progress` apply).
    - `settings`: a `ReconstructSettings` for `coordination="evidence"`.
    - `keep_low_orders`, `keep_restoring_order`: x^0 .. x^order, v and x v are exempt from the STLS threshold (the
      t-screen still judges them); the order defaults to 3 with measured accelerations, 2 differentiated from v, 1.
    - `shared_damping`: one set of terms sgn(v)|v|^j (j != 1) for every well (Eq. 21).
    - `extend_restoring`: raise each well's restoring order while the next term is resolved (default: with measured
      accelerations; up to q^2, kept whatever its t, with estimated accelerations and `structured_noise`).
    - `shared_design`: cells of one design lend their resolved orders as a prior (default: on unless "hermite").
    - `structured_noise`: estimated accelerations' noise taken as it is (centre tap out, edges out, sandwich
      covariances); default on for x integrated from v and for estimated accelerations on non-tonal records.
    - `errors_in_variables`, `velocity_eiv`: correct for the white noise on a measured x (local fits) and on a
      measured v (the joint regression's columns and covariance).
    - `throw`: raise `GMRComputationError` on a numerical failure (else read `result`; NaN where it failed).
    - `progress`: called with a short sentence at each stage, e.g. `print`.

    **Returns:** a `Solution`: `value` the `GlobalModel` with standard errors and the calibrated `covariance`
    (`force_band`, `sample_models`), `result` a `RESULTS` code, `stats` with `method`, `library`, `dofs` (a
    `DofReport` per DOF), `training` (R², NRMSE) and `warnings` (the checks' findings, also `GMRDataWarning`s).
    User mistakes raise `GMRInputError` before anything is computed.
    """
    recordings = as_recordings(recordings)  # paths and arrays as well as Recordings
    if isinstance(topology, Graph):
        return _graph(recordings, topology, designs, coordination, settings, library, masses, throw, progress)
    if coordination == "evidence":
        return _evidence(recordings, settings, library, masses, topology, well_tol, throw, progress)
    given = dict(locals())  # the call's arguments, for rule 14d's refit (`_window_check`)
    relieve_map_pressure()  # a long session's compiled programs (`_config.map_pressure`)
    failure = _Failure("reconstruct", throw)
    say = progress or (lambda msg: None)
    measured = all(r.a is not None and "a" not in r.derived for r in recordings)
    # accelerations differentiated once from a measured v (x integrated from it, its slow shift restored)
    once = all((r.a is not None and "a" not in r.derived) or (r.integration or {}).get("from") == "v"
               for r in recordings)
    if keep_restoring_order is None:
        keep_restoring_order = 3 if measured else (2 if once else 1)
    if structured_noise is None:  # on where x was integrated from a measured v, or on swept records
        structured_noise = (all((r.integration or {}).get("from") == "v" for r in recordings)
                            or (not measured and not _steady_sines(recordings)))
    extend_upto = None
    if extend_restoring is None:  # estimated accelerations with their noise's structure: up to the curvature
        extend_restoring, extend_upto = (True, None) if measured else (structured_noise, 2)
    recs, masses, topology, warnings = _resolve(recordings, masses, topology, exclude_center=structured_noise)
    d = recs[0].n_dof
    wells = [_wells(recs, i, well_tol) for i in range(d)]  # refusals before any fit
    targets = [regression_targets(r, masses, topology) for r in recs]
    # an x integrated from v or a: the slow shift its drift removal took, restored (`_slow`)
    recs = [restore_slow(r, y) for r, y in zip(recs, targets)]
    stiff, vdamp, pdamp, se_s, se_v, se_p, covs, reports = [], [], [], [], [], [], [], []
    systematic_of = []  # per DOF, what `_systematic` needs (computed only where cells are pooled)
    k1 = library.column(STIFFNESS, 1)  # restoring_order >= 1 (`Library`)
    local, noises, x_noises, row_filters, segs_all, gains, v_noises = [], [], [], [], [], [], []
    for i in range(d):
        _, labels, groups = wells[i]
        xs, w = _pad_stack([[recs[k].x[:, i] for k in g] for g in groups])
        if structured_noise or not measured:  # the edge fits' rows: not the taps' gain
            w = w * _pad_stack([[inner_samples(recs[k]) for k in g] for g in groups])[0]
        segs = segments(recs, groups, i)  # x integrated: each record's slow band (`_slow`)
        if segs is not None:  # the integration's ends left out
            w = w * _pad_stack([[e] for e in edge_weights(recs, groups)])[0]
        vs, _ = _pad_stack([[recs[k].v[:, i] for k in g] for g in groups])
        ys, _ = _pad_stack([[targets[k][:, i] for k in g] for g in groups])
        keep = low_order_terms(library, keep_restoring_order) if keep_low_orders else None
        noise = [_noise.well_noise(recs, grp, i, masses, topology) if structured_noise else None
                 for grp in groups]  # None: a measured, or OLS asked for
        # variances as arrays: a Python float is static to the jitted fit (one compile per value)
        x_noise = [None if (var := _noise.x_noise_variance(recs, grp, i) if errors_in_variables else None) is None
                   else jnp.asarray(var, float) for grp in groups]
        say(f"{f'DOF {i} ({i + 1}/{d}): ' if d > 1 else ''}local fits at {len(groups)} wells")
        # x integrated from v or a: the local regressions in the band above its drift cut-off (`_slow.band_rows`)
        band = band_rows(recs, groups, i, w, targets, library, masses, topology, segs)
        # estimated accelerations: the joint regression's columns through the filter's gain, as the local fits'
        # (`_filter_gain.gain_segments`), where its rows are not low-passed (steady sines: the harmonics carry the
        # nonlinearity, where G < 1); low-passed rows keep the band where G is about 1, and G there only spreads
        # the noise of x
        row_filters.append(None if measured else _derived_rows(recs, groups, i))
        gsegs = gain_segments(recs, groups) if row_filters[i] is None else None
        gains.append(None if gsegs is None
                     else (gsegs, _pad_stack([[matched_target(recs[k], targets[k][:, i], i, masses, topology)
                                               for k in g] for g in groups])[0]))
        sols = jax.device_get(_fit_wells(xs, vs, ys, w, library, solver, select, keep, noise, x_noise, band))
        fits: LocalFit = sols.value
        fitted = fits  # before the t-screen (`_extend_position_damping` refits beside its zeroed restoring terms)
        eiv = _eiv_report(x_noise, xs, w, sols.stats.get("eiv_applied"))
        if screen_sigma is not None:
            screened = _screen(fits, screen_sigma, library)
            # wells that keep some damping terms (before the next rule)
            screened = _refit_screened_damping(fits, screened, xs, vs, ys, w, library, solver, screen_sigma, i,
                                               failure, noise, x_noise, band)
            # wells whose damping terms the screen zeroed all at once
            screened = _one_of_a_group(fits, screened, xs, vs, ys, w, library, solver, screen_sigma, i, failure,
                                       noise, x_noise, band)
            fits = screened
        codes = np.asarray(sols.result._value)
        for k in np.nonzero(codes != RESULTS.successful._value)[0]:
            failure.note(codes[k], f"DOF {i}, well {k}: local fit")
        dropped = []
        fits, at_rest = _dissipative_at_rest(fits, xs, vs, ys, w, library, solver, screen_sigma, i, failure,
                                             noise, x_noise, band)
        if shared_damping:
            fits, dropped = _share_velocity_damping(fits, xs, vs, ys, w, library, solver, keep, screen_sigma, i,
                                                    failure, noise, x_noise, band)
            fits, again = _dissipative_at_rest(fits, xs, vs, ys, w, library, solver, screen_sigma, i, failure,
                                               noise, x_noise, band, shared=True)
            at_rest = sorted(set(at_rest) | set(again))
        damping_added = []
        if screen_sigma is not None:
            fits, damping_added = _extend_damping(fits, xs, vs, ys, w, library, solver, screen_sigma, i, failure,
                                                  noise, x_noise, band)
        position_added = [[] for _ in groups]
        if screen_sigma is not None:
            fits, position_added = _extend_position_damping(fits, xs, vs, ys, w, library, solver, screen_sigma, i,
                                                            failure, noise, x_noise, band, fitted=fitted)
        added = [[] for _ in groups]
        if extend_restoring and screen_sigma is not None:
            fill = extend_upto == 2  # F'' whatever its t
            fits, added = _extend_restoring(fits, xs, vs, ys, w, library, solver, screen_sigma, i, failure, noise,
                                            x_noise, extend_upto, band, fill=fill)
        local.append((labels, groups, xs, vs, ys, w, fits, dropped, added, eiv, band, at_rest, damping_added,
                      position_added))
        # estimated accelerations: the joint regression on low-passed rows (`row_filter`)
        segs_all.append(segs)
        noises.append(noise)
        x_noises.append(x_noise)
        # the noise of a measured v, for the joint regression's velocity columns (`_joint._velocity_noise`)
        v_noises.append([_noise.v_noise_variance(recs, grp, i) if velocity_eiv else None for grp in groups])
    # cells of one design: the well-excited cells lend the curvature the weakly excited ones miss
    plan, design = [None] * d, None
    if shared_design is None:
        shared_design = coordination != "hermite"
    if shared_design and d > 1:
        plan, design = _shape_prior.share_curvature([loc[6] for loc in local], library,
                                                    screen_sigma if screen_sigma is not None else 3.0)
    for i in range(d):
        labels, groups, xs, vs, ys, w, fits, dropped, added, eiv, band, at_rest, damping_added, position_added = local[i]
        data_fits = fits  # the local fits from the data alone (reported; the resolution report reads them)
        borrowed, design_why = [], None
        integrated = segs_all[i] is not None  # F, F', F'' only (`_slow.curvature_only`)
        if plan[i] is not None:
            fits, borrowed = _borrow(fits, plan[i], xs, vs, ys, w, library, x_noises[i], band)
        fits = curvature_only(fits, library) if integrated else fits
        say(f"{f'DOF {i} ({i + 1}/{d}): ' if d > 1 else ''}coordination ({coordination})")
        coord, route, why, paper_sound, confining, found = _coordinate_dof(
            fits, xs, vs, ys, w, library, coordination, float(masses[i]), i, odd_only=any(borrowed),
            x_noise=x_noises[i], rows=row_filters[i], band=band, segs=segs_all[i], gain=gains[i], v_noise=v_noises[i])
        if any(borrowed) and route == "joint":
            # the law with the borrowed orders was inadmissible and the joint regression (which sees
            # only this cell's data) would replace it: the cell goes on alone
            faults = [n for n in why if n not in coord.stats.get("degree_notes", [])]  # not the degree's notes
            design_why = "the borrowed orders gave an inadmissible law: " + "; ".join(faults[:1])
            fits, borrowed = (curvature_only(data_fits, library) if integrated else data_fits), []
            coord, route, why, paper_sound, confining, found = _coordinate_dof(
                fits, xs, vs, ys, w, library, coordination, float(masses[i]), i, x_noise=x_noises[i],
                rows=row_filters[i], band=band, segs=segs_all[i], gain=gains[i], v_noise=v_noises[i])
        warnings += found
        if coord.result != RESULTS.successful:
            failure.note(coord.result, f"DOF {i}: coordination of the equilibria "
                         f"{np.asarray(fits.equilibrium).round(6).tolist()}, condition numbers "
                         f"{float(coord.stats['cond_r']):.3g}/{float(coord.stats['cond_d']):.3g}")
        g = coord.value
        names = [r.name for r in recs]
        xcol = [r.x[:, i] for r in recs]
        eq = np.asarray(fits.equilibrium)
        coef = np.asarray(data_fits.coef)
        local_se = np.sqrt(np.clip(np.diagonal(np.asarray(data_fits.covariance), axis1=1, axis2=2), 0, None))
        local_k = coef[:, k1]
        swing, swung = _sanity.check_swings(i, names, xcol, labels, eq, local_k)
        warnings += swing + _sanity.check_amplitude(i, names, xcol, labels, eq, skip=swung)
        warnings += _sanity.check_scales(i, names, xcol, labels)
        well_names = [", ".join(names[k] for k in grp) for grp in groups]
        exempt = _under_top_order(coef, library) if screen_sigma is not None else None
        if exempt is not None:  # orders `_extend_restoring` added are kept on purpose (F'': whatever t)
            for k, orders in enumerate(added):
                exempt[k, library.indices(STIFFNESS)[list(orders)]] = True
        warnings += _sanity.check_significance(i, well_names, library.names(), coef, local_se, exempt)
        amps = [max(_sanity.vibration_amplitude(xcol[k]) for k in grp) for grp in groups]
        warnings += _sanity.check_global_shape(i, np.asarray(g.stiffness), eq, amps, local_k)
        n_k = g.stiffness.shape[0]
        xall = np.concatenate(xcol)
        warnings += _sanity.check_determination(i, np.asarray(g.stiffness), np.asarray(coord.aux)[:n_k, :n_k],
                                                float(xall.min()), float(xall.max()))
        noise_rel = _sanity.restoring_uncertainty(g.stiffness, np.asarray(coord.aux), float(xall.min()),
                                                  float(xall.max()))
        se = split_flat(np.sqrt(np.clip(np.diag(np.asarray(coord.aux)), 0.0, None)), g)
        if route == "joint" and float(coord.stats.get("joint_conflict", 0.0)) > JOINT_CONFLICT:
            warnings += _sanity.check_conflict(i, np.asarray(g.stiffness), np.asarray(coord.aux)[:n_k, :n_k],
                                               coord.stats["joint_unconstrained"], float(coord.stats["joint_conflict"]),
                                               float(xall.min()), float(xall.max()))
        if coord.stats.get("joint_damping_alternative_orders") is not None:  # rule 14
            warnings += _sanity.check_damping_choice(
                i, np.asarray(g.velocity_damping), np.asarray(g.position_damping),
                coord.stats["joint_damping_alternative_velocity"], coord.stats["joint_damping_alternative_position"],
                coord.stats["joint_damping_alternative_orders"], float(coord.stats["joint_damping_alternative_delta"]),
                recorded_speed(vs, w), _speed(fits, vs, w, float(masses[i]), library), float(xall.min()),
                float(xall.max()))
        # a DOF that borrowed was coordinated with odd degrees only: its discrepancy is that degree choice's
        g, cov_i = _calibrated(coord, fits, library, route, paper_sound, confining or any(borrowed))
        # a well that fixes the damping's value only: the slope it leaves open, in the band (`_damping_slopes`);
        # not where the joint regression fitted the damping to every well's data with its own position terms
        if "joint" not in route:
            slopes = unresolved_slopes(data_fits, xs, vs, ys, w, library, solver, noises[i], x_noises[i], band)
            cov_i = add_slope_vectors(cov_i, *(np.asarray(a).shape[0] for a in (g.stiffness, g.velocity_damping,
                                                                                 g.position_damping)),
                                      slope_vectors(eq, *slopes))
            # velocity orders no well kept (rule 14b): in the band, and said where they matter
            found_orders = unresolved_orders(data_fits, xs, vs, ys, w, library, solver, np.asarray(g.velocity_damping),
                                             noises[i], x_noises[i], band)
            cov_i = add_order_vectors(cov_i, np.asarray(g.stiffness).shape[0], np.asarray(g.velocity_damping).shape[0],
                                      found_orders)
            coord.stats["unresolved_velocity_orders"] = {j: v[:3] + v[4:] for j, v in found_orders.items()}
            warnings += _sanity.check_unresolved_damping(
                i, np.asarray(g.velocity_damping), np.asarray(g.position_damping), found_orders, recorded_speed(vs, w),
                _sanity.crossing_speed(g.stiffness, eq, float(masses[i])), float(xall.min()), float(xall.max()))
        se = GlobalCoefficients(*(np.pad(np.asarray(a), (0, np.asarray(b).shape[0] - np.asarray(a).shape[0]))
                                  for a, b in zip((se.stiffness, se.velocity_damping, se.position_damping),
                                                  (g.stiffness, g.velocity_damping, g.position_damping))))
        warnings += _sanity.check_band(i, np.asarray(g.stiffness), cov_i, noise_rel, float(xall.min()),
                                       float(xall.max()))  # rule 11b: the band written with the model
        covs.append(cov_i)
        systematic_of.append((coord, fits, route, confining or any(borrowed)))  # `_systematic`, where pooled
        stiff.append(np.asarray(g.stiffness)), vdamp.append(np.asarray(g.velocity_damping))
        pdamp.append(np.asarray(g.position_damping))
        se_s.append(np.asarray(se.stiffness)), se_v.append(np.asarray(se.velocity_damping))
        se_p.append(np.asarray(se.position_damping))
        reports.append(DofReport(
            equilibria=eq,
            local_coef=coef,
            local_stderr=local_se,
            thresholds=np.asarray(data_fits.threshold),
            recordings_per_well=[[recs[k].name for k in g] for g in groups],
            stats={k: np.asarray(v).tolist() for k, v in coord.stats.items()}
            | {"dropped_velocity_damping": dropped, "negative_friction_dropped": at_rest,
               "damping_orders_added": damping_added, "position_damping_orders_added": position_added,
               "restoring_orders_added": added, "errors_in_variables": eiv, "coordination": route,
               "velocity_noise": _v_noise_report(v_noises[i], coord.stats.get("joint_velocity_noise", False)),
               "paper_route_rejected": why, "shared_design": _design_stats(design, i, borrowed, design_why, coord),
               "escapes": _sanity.escapes(np.asarray(g.stiffness), eq)},
        ))
    # cells of one design: the law between the wells, pooled (`_design_law`), unless the local ratios
    # already showed the cells to be of different designs
    other_designs = design is not None and design["tau"] is not None and design["tau"] > _shape_prior.TAU_MAX
    if shared_design and d > 1 and not other_designs:
        say("cells of one design: their laws between the wells pooled")
        noise_covs = []  # per DOF, the calibrated covariance less its restoring law's embedded error
        for (c_, f_, r_, conf_), cov_ in zip(systematic_of, covs):
            sys_ = _systematic(c_, f_, library, r_, conf_, cov_)
            noise_covs.append(None if sys_ is None else cov_ - sys_)
        warnings += _pool_laws(stiff, vdamp, pdamp, covs, reports, recs, noise_covs)
    say("training scores, sanity checks, resolution report")
    stderr = {STIFFNESS: jnp.asarray(stack_padded(se_s)), VELOCITY_DAMPING: jnp.asarray(stack_padded(se_v)),
              POSITION_DAMPING: jnp.asarray(stack_padded(se_p))}
    model = _model_from_blocks(masses, topology, stiff, vdamp, pdamp, stderr, covs)
    training = training_scores(model, recs, masses, topology, row_filters)
    warnings += _sanity.check_fit_quality(training)
    resolution = _resolution.resolution_report(recs, targets, [wl[2] for wl in wells], reports, model, library,
                                               masses, topology, noises)  # what each well resolved, excitation advice
    warnings += resolution.warnings()
    window_stats = {}
    if _steady_sines(recordings):  # rule 14d (`_window_check`: x-only records, a law beyond the viscous term)
        refit = lambda r: reconstruct(**{**given, "recordings": r, "throw": False, "progress": None})  # noqa: E731
        found, window_stats = _window_check.check(refit, recordings, model, topology, structured_noise, say)
        warnings += found
    for i, st in window_stats.items():
        reports[i].stats["window_check"] = st
    _emit(warnings)
    sol = _solution(model, failure, "GMR", library, reports, training, warnings, recs)
    sol.stats["resolution"] = resolution
    return sol


def _graph(recordings, graph, designs, coordination, settings, library, masses, throw, progress) -> Solution:
    """`reconstruct` on a `Graph` (`_graph`)."""
    from ._estimator import ReconstructSettings
    from ._graph import reconstruct_graph

    if coordination not in ("auto", "evidence"):
        raise GMRInputError(f"a graph is fitted on the 'evidence' route only (its elements' laws are identified "
                            f"jointly from the nodes' balances), got coordination={coordination!r}; use "
                            f"coordination='evidence'")
    if settings is None:
        settings = ReconstructSettings(damping_order=library.damping_order)
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


def _evidence(recordings, settings, library, masses, topology, well_tol, throw, progress) -> Solution:
    """`reconstruct` on one probabilistic model of the data (`_estimator`)."""
    from ._estimator import ReconstructSettings, diagnose, equilibria, estimate, model_from

    if settings is None:
        settings = ReconstructSettings(damping_order=library.damping_order, well_tol=well_tol)
    relieve_map_pressure()
    failure = _Failure("reconstruct", throw)
    say = progress or (lambda msg: None)
    recs, masses, topology, warnings = _resolve(recordings, masses, topology)
    d = recs[0].n_dof
    wells = [_wells(recs, i, settings.well_tol) for i in range(d)]
    blocks, covs, dof_stats = estimate(recs, masses, topology, settings, wells, say, failure)
    model = model_from(masses, topology, blocks, covs)
    say("training scores and checks")
    training = training_scores(model, recs, masses, topology)
    warnings += diagnose(recs, wells, model, training)
    reports = []
    for i, (_, labels, groups) in enumerate(wells):
        eq = equilibria(recs, i, groups)
        st = dof_stats[i] | {"K_r": int(dof_stats[i]["degree"]), "K_d": int(settings.damping_order),
                             "escapes": _sanity.escapes(np.asarray(model.stiffness[i]), eq)}
        reports.append(DofReport(equilibria=eq, local_coef=np.zeros((len(groups), 0)),
                                 local_stderr=np.zeros((len(groups), 0)), thresholds=np.zeros(len(groups)),
                                 recordings_per_well=[[recs[k].name for k in g] for g in groups], stats=st))
    _emit(warnings)
    sol = _solution(model, failure, "GMR", library, reports, training, warnings, recs)
    sol.stats["settings"] = settings
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
    model = _model_from_blocks(masses, topology, stiff, vdamp, pdamp)
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
        labels = group_wells(means, 0.1 * spread)
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
