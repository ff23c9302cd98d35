"""Issue 15: synthetic stress cases with the defaults, against the curvature oracle.

Non-polynomial cells (the shallow arch / von Mises truss, the magnetic bistable, the truss cells
of a 3-cell Kresling chain) excited by a base sweep at 0.2-0.5 % of their interwell distance,
30 dB noise on every channel, float32 time stamps (cast to float32 and back, as a lab file
stores them) and partial sensors (displacement only, velocity only with the equilibrium given,
a chain without its velocity channels). Each case is reconstructed with `gmr.reconstruct`
defaults and judged by

- spurious wells: stable equilibria of the fitted restoring force within one box-span of the
  metrics box, against the truth's (count);
- divergence: free runs of the fitted model from a grid of initial states over the metrics box
  (x and v, where the errors and basin maps are measured), unforced, 20 slowest natural periods,
  and under the training input from every equilibrium; a run that fails or leaves the box
  widened by two spans on either side is diverged;
- restoring error (relative L2 over the metrics box) against the curvature oracle's: the
  Hermite interpolant of each well's exact F, F', F'' (target: within 2x);
- the noise floor: the same interpolant with each well's F, F', F''/2 drawn about the truth's
  with the local fit's standard errors (`TermResolution.se_h`), median and 90th percentile over
  400 draws (SciPy's `KroghInterpolator`, not the tool's): what the paper's exact interpolant
  reaches from local Taylor data as noisy as these records allow. Not a bound on every
  estimator: the joint regression weighs the raw records with a curvature prior and may beat it
  (arch_x). `--floor-seeds N` checks those standard errors against the scatter of the local
  estimates over N noise seeds, and for a velocity-only case refits the same sweeps with x
  measured, as recorded and high-passed at v's integration cut-off (`slow_content`);
- whether the failures are warned (`GMRDataWarning`), and the per-well resolution table
  (`stats["resolution"]`, `gmr_jax._reconstruct._resolution`);
- the excitation advice checked: where a needed term is unresolved, the case is re-recorded
  with the base amplitude scaled to the advised one, and (separately) at the original amplitude
  with the advised SNR, and refitted.

    python studies/stress_cases.py [--cases arch_xva,magnet_xva_f32,...] [--seeds 1]
        [--out results/stress_cases.md]
    python studies/stress_cases.py --sweep arch --out results/stress_cases_sweep.md
        # the resolution bound against the restoring error, by amplitude
    python studies/stress_cases.py --floor-seeds 8 --cases arch_v_f32,kresling3_xa_f32 \
        --out results/stress_cases_floor.md   # the noise floor against the seeds' scatter
"""

import argparse
import time
import warnings
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

import gmr_jax as g

SNR = 30.0
MAX_ADVISED_RATIO = 0.3  # the report's small-vibration cap (it advises samples or SNR beyond it)
TARGET_RATIO = 0.0045  # the most excited well of each case at 0.45 % of its interwell distance


@dataclass(frozen=True)
class Case:
    name: str
    system: str  # "arch", "magnet", "kresling3"
    sensing: str  # "xva", "x", "v", "xa"
    float32_time: bool = False
    ratio: float = TARGET_RATIO

    def make_system(self):
        return {"arch": g.systems.shallow_arch, "magnet": g.systems.magnetic_bistable,
                "kresling3": g.systems.kresling3}[self.system]()


CASES = {c.name: c for c in (
    Case("arch_xva", "arch", "xva"),
    Case("magnet_xva_f32", "magnet", "xva", True),
    Case("arch_x", "arch", "x"),
    Case("arch_v_f32", "arch", "v", True),
    Case("magnet_x", "magnet", "x"),
    Case("kresling3_xa_f32", "kresling3", "xa", True),
)}


# --- data -------------------------------------------------------------------------------------


def response_ratios(system, amplitude: float) -> np.ndarray:
    """(wells, dof) vibration amplitude / interwell distance of noise-free sweeps at `amplitude`."""
    recs = g.systems.make_recordings(system, amplitude, snr_db=None)
    eq = np.asarray(system.equilibria, float)
    dist = np.abs(eq[1:] - eq[:-1]).min(axis=0) if eq.shape[0] > 1 else np.ones(eq.shape[1])
    return np.array([[np.percentile(np.abs(r.x[:, i] - r.x[:, i].mean()), 99.9) / dist[i]
                      for i in range(eq.shape[1])] for r in recs])


def base_amplitude(system, ratio: float) -> float:
    """The base amplitude that puts the most excited well at `ratio` (the response is linear
    in the base amplitude at these small vibrations; probed at 1e-4 of the interwell scale)."""
    eq = np.asarray(system.equilibria, float)
    probe = 1e-3 * float(np.ptp(eq))
    return probe * ratio / float(response_ratios(system, probe).max())


def recordings(case: Case, amplitude: float, seed: int, snr: float = SNR):
    s = case.make_system()
    recs = g.systems.make_recordings(s, amplitude, snr_db=snr, seed=seed)
    out = []
    for k, r in enumerate(recs):
        t = r.t.astype(np.float32).astype(np.float64) if case.float32_time else r.t
        common = dict(t=t, base_acc=r.base_acc, masses=r.masses, name=r.name)
        if case.sensing == "xva":
            out.append(g.Recording(x=r.x, v=r.v, a=r.a, **common))
        elif case.sensing == "x":
            out.append(g.Recording(x=r.x, **common))
        elif case.sensing == "xa":
            out.append(g.Recording(x=r.x, a=r.a, **common))
        elif case.sensing == "v":
            out.append(g.Recording(v=r.v, equilibrium=np.asarray(s.equilibria[k], float), **common))
    return out


# --- the curvature oracle -----------------------------------------------------------------------


def truth_taylor(system, dof: int, order: int = 2) -> np.ndarray:
    """(wells, order + 1) the truth's F^(k)(x_i) / k! at every equilibrium of `dof`."""
    d = system.truth.n_dof

    def f(x):
        return system.truth.restoring(jnp.zeros(d).at[dof].set(x))[dof]

    out, fk = [], f
    for k in range(order + 1):
        out.append([float(fk(x)) / float(np.prod(np.arange(1, k + 1))) for x in np.asarray(system.equilibria[:, dof], float)])
        fk = jax.grad(fk)
    return np.array(out).T


def oracle_stiffness(system, dof: int, order: int = 2) -> np.ndarray:
    """Ascending coefficients of the Hermite interpolant of the truth's exact Taylor
    coefficients F^(k)(x_i) / k!, k = 0..`order`, at every well of `dof` (the other cells at 0;
    the built-in cells' restoring forces depend on their own deformation only)."""
    nodes = np.asarray(system.equilibria[:, dof], float)
    coef, degree, _ = g.hermite_interpolate(jnp.asarray(nodes), jnp.asarray(truth_taylor(system, dof, order)),
                                            jnp.full(nodes.size, order))
    return np.asarray(coef)[: int(degree) + 1]


def truth_on_box(system, dof: int, n: int = 401) -> tuple[np.ndarray, np.ndarray]:
    """(xs, F(xs)): the truth's restoring force of `dof` on `n` points of its metrics box (the other cells at 0)."""
    xs = np.linspace(*system.x_range[dof], n)
    d = system.truth.n_dof
    return xs, np.asarray(jax.vmap(lambda x: system.truth.restoring(jnp.zeros(d).at[dof].set(x))[dof])(jnp.asarray(xs)))


def oracle_error(system, dof: int, order: int = 2) -> float:
    xs, truth = truth_on_box(system, dof)
    fit = np.polynomial.polynomial.polyval(xs, oracle_stiffness(system, dof, order))
    return float(np.linalg.norm(fit - truth) / np.linalg.norm(truth))


def noise_floor(system, dof: int, se: np.ndarray, draws: int = 400, seed: int = 0) -> np.ndarray:
    """Restoring errors (draws,) of the curvature oracle with each well's Taylor data F^(k)/k!
    drawn from N(truth, se^2) (`se` (wells, 3), the local fits' standard errors): SciPy's Hermite
    interpolant (`KroghInterpolator`, repeated nodes take F, F', F''), relative L2 over the box."""
    from scipy.interpolate import KroghInterpolator

    nodes = np.asarray(system.equilibria[:, dof], float)
    taylor = truth_taylor(system, dof)
    fact = np.array([1.0, 1.0, 2.0])
    xs, truth = truth_on_box(system, dof)
    rng = np.random.default_rng(seed)
    errs = []
    for _ in range(draws):
        tk = (taylor + rng.standard_normal(taylor.shape) * se) * fact  # F, F', F''
        fit = KroghInterpolator(np.repeat(nodes, 3), tk.reshape(-1))(xs)
        errs.append(np.linalg.norm(fit - truth) / np.linalg.norm(truth))
    return np.array(errs)


def matched_wells(res, system, dof: int) -> list | None:
    """Per truth well of `dof`, the resolution report's nearest fitted well (None where the fit found a
    different number of wells)."""
    wells = [w for w in res.wells if w.dof == dof]
    nodes = np.asarray(system.equilibria[:, dof], float)
    if len(wells) != nodes.size:
        return None
    eq = np.array([w.equilibrium for w in wells])
    return [wells[int(np.argmin(np.abs(eq - x)))] for x in nodes]


def local_se(res, system, dof: int) -> np.ndarray | None:
    """(wells, 3) the local fits' standard errors of F, F', F''/2 at the truth's wells of `dof`
    (`se_h`: the local fit's, or the hierarchical fit's where larger or the term was dropped; `matched_wells`)."""
    wells = matched_wells(res, system, dof)
    return None if wells is None else np.array([[t.se_h for t in w.terms[:3]] for w in wells])


# --- criteria ---------------------------------------------------------------------------------


def well_counts(model, system, dof: int) -> tuple[int, int]:
    """Stable equilibria of the fitted and the true restoring force of `dof` within one span of the box."""
    lo, hi = system.x_range[dof]
    rng = (lo - (hi - lo), hi + (hi - lo))
    fit = sum(s for _, s in g.metrics.equilibria(model, dof, rng))
    true = sum(s for _, s in g.metrics.equilibria(system.truth, dof, rng))
    return int(fit), int(true)


def natural_period(system) -> float:
    """The slowest linear period at the wells (single DOF: per well; chain: the base cell with all masses)."""
    m = float(np.sum(np.asarray(system.truth.masses)))
    ks = []
    for i in range(system.equilibria.shape[0]):
        x0 = jnp.asarray(system.equilibria[i], float)
        ks.append(float(jax.jacfwd(system.truth.restoring)(x0)[0, 0]))
    return float(2 * np.pi * np.sqrt(m / max(min(ks), 1e-12)))


def divergence(model, system, amplitude: float, seed: int = 0) -> dict:
    """Free runs from initial states over the metrics box, and runs under the training sweep."""
    d = system.truth.n_dof
    lo, hi = system.x_range[:, 0], system.x_range[:, 1]
    span = hi - lo
    box = (jnp.asarray(lo - 2 * span), jnp.asarray(hi + 2 * span))
    if d == 1:
        xg, vg = np.meshgrid(np.linspace(lo[0], hi[0], 9), np.linspace(*system.v_range[0], 5))
        x0s, v0s = xg.reshape(-1, 1), vg.reshape(-1, 1)
    else:
        rng = np.random.default_rng(seed)
        x0s = lo + span * rng.random((24, d))
        v0s = system.v_range[:, 0] + np.ptp(system.v_range, axis=1) * rng.random((24, d))
    duration = 20 * natural_period(system)
    ts = jnp.linspace(0.0, duration, 2001)
    free = jax.vmap(lambda x0, v0: g.simulate(model, g.NoInput(d), ts, x0, v0, box=box, throw=False))(
        jnp.asarray(x0s), jnp.asarray(v0s))
    ok_free = (np.asarray(free.result._value) == g.RESULTS.successful._value) & np.all(
        np.isfinite(np.asarray(free.value[0])), axis=(1, 2))
    ts_tr = jnp.arange(int(round(system.duration * system.fs)) + 1) / system.fs
    exc = g.BaseChirp(jnp.asarray(amplitude, float), system.sweep[0], system.sweep[1], system.duration, n_dof=d)
    forced = jax.vmap(lambda x0: g.simulate(model, exc, ts_tr, x0, box=box, throw=False))(
        jnp.asarray(system.equilibria, float))
    ok_forced = (np.asarray(forced.result._value) == g.RESULTS.successful._value) & np.all(
        np.isfinite(np.asarray(forced.value[0])), axis=(1, 2))
    return {"free": int((~ok_free).sum()), "n_free": int(ok_free.size),
            "forced": int((~ok_forced).sum()), "n_forced": int(ok_forced.size)}


def evaluate(case: Case, amplitude: float, seed: int, snr: float = SNR) -> dict:
    system = case.make_system()
    recs = recordings(case, amplitude, seed, snr)
    t0 = time.time()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            sol = g.reconstruct(recs, throw=False)
        except g.GMRInputError as e:
            return {"case": case.name, "seed": seed, "amplitude": amplitude, "snr": snr, "refused": str(e)}
    secs = time.time() - t0
    data_warnings = [str(w.message) for w in caught if issubclass(w.category, g.GMRDataWarning)]
    model = sol.value
    d = system.truth.n_dof
    res = sol.stats["resolution"]
    row = {"case": case.name, "seed": seed, "amplitude": amplitude, "snr": snr, "secs": secs, "result": g.RESULTS[sol.result] or "successful",
           "warnings": data_warnings, "resolution": res, "routes": [r.stats.get("coordination") for r in sol.stats["dofs"]],
           "ratios": [w.ratio for w in res.wells], "dofs": []}
    div = divergence(model, system, amplitude, seed)
    row["divergence"] = div
    for i in range(d):
        fit_w, true_w = well_counts(model, system, i)
        err = g.metrics.restoring_error(model, system.truth, i, system.x_range[i])
        orc = oracle_error(system, i)
        se = local_se(res, system, i)
        floor = noise_floor(system, i, se) if se is not None else np.array([np.nan])
        row["dofs"].append({"wells": fit_w, "true_wells": true_w, "error": err, "oracle": orc,
                            "oracle_vs": oracle_error(system, i, 1), "ratio": err / orc,
                            "floor": float(np.median(floor)), "floor90": float(np.percentile(floor, 90))})
    row["pass"] = {
        "wells": all(x["wells"] <= x["true_wells"] for x in row["dofs"]),
        "divergence": div["free"] == 0 and div["forced"] == 0,
        "error": all(x["ratio"] <= 2.0 for x in row["dofs"]),
    }
    row["warned"] = bool(data_warnings)
    return row


def advised_snr(row: dict) -> float | None:
    """The SNR at which every needed term would be resolved at the same amplitude (20 log10 rho dB more)."""
    rhos = [t.rho for _, t in row["resolution"].missing()]
    return row["snr"] + 20 * np.log10(max(rhos)) if rhos else None


def advised_amplitude(row: dict) -> float | None:
    """The base amplitude at which every needed term would be resolved (the report's advice,
    scaled by the largest advised / current amplitude ratio), None when nothing is missing."""
    res = row["resolution"]
    miss = res.missing()
    # the advice itself says when amplitude alone cannot do it: F' (its standard error does not fall with
    # amplitude at a fixed SNR), or an amplitude beyond the small-vibration regime
    if not miss or any(t.advised_ratio is None or t.advised_ratio > MAX_ADVISED_RATIO for _, t in miss):
        return None
    return row["amplitude"] * max(t.advised_ratio / w.ratio for w, t in miss)


# --- report -----------------------------------------------------------------------------------


def _pct(x):
    return f"{100 * x:.3g} %"


def describe(row: dict, header: str) -> list[str]:
    if "refused" in row:
        return [f"### {header}", "", f"Base amplitude {row['amplitude']:.3g}, {row['snr']:.3g} dB: refused "
                f"(`GMRInputError`): {row['refused']}", ""]
    p = row["pass"]
    div = row["divergence"]
    out = [f"### {header}", "",
           f"Base amplitude {row['amplitude']:.3g}, {row['snr']:.3g} dB; amplitude ratios per well "
           f"{', '.join(f'{100 * r:.2g} %' for r in row['ratios'])}; coordination {', '.join(map(str, row['routes']))}; "
           f"{row['secs']:.0f} s; result {row['result']}.", "",
           "| DOF | wells fitted / true | restoring error | curvature oracle | ratio (target <= 2) | value+slope oracle "
           "| noise floor (median / 90 %) |",
           "|---|---|---|---|---|---|---|"]
    for i, x in enumerate(row["dofs"]):
        out.append(f"| {i} | {x['wells']} / {x['true_wells']} | {_pct(x['error'])} | {_pct(x['oracle'])} | "
                   f"{x['ratio']:.2f} | {_pct(x['oracle_vs'])} | {_pct(x['floor'])} / {_pct(x['floor90'])} |")
    out += ["", f"Divergence: {div['free']} of {div['n_free']} free runs, {div['forced']} of {div['n_forced']} runs "
            f"under the training sweep. Criteria: spurious wells {'pass' if p['wells'] else 'FAIL'}, divergence "
            f"{'pass' if p['divergence'] else 'FAIL'}, error within 2x of the oracle {'pass' if p['error'] else 'FAIL'}; "
            f"GMRDataWarnings: {len(row['warnings'])}.", ""]
    if row["warnings"]:
        out += [f"- warning: {w[:400]}{'...' if len(w) > 400 else ''}" for w in row["warnings"]] + [""]
    out += ["Per-well resolution (`stats[\"resolution\"]`):", "", str(row["resolution"]), ""]
    return out


def nominal_kresling5() -> list[str]:
    """Not a stress case: the resolution table of the nominal 5-cell chain (0.3 mm, 60 dB, seed 0)."""
    s = g.systems.kresling5()
    recs = g.systems.make_recordings(s, g.systems.KRESLING5_AMPLITUDE, seed=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sol = g.reconstruct(recs)
    errs = [g.metrics.restoring_error(sol.value, s.truth, i, s.x_range[i]) for i in range(5)]
    orc = [oracle_error(s, i) for i in range(5)]
    return ["## Not a stress case: the nominal 5-cell Kresling chain (0.3 mm, 60 dB, seed 0)", "",
            f"Restoring error per cell {', '.join(_pct(e) for e in errs)}; curvature oracle "
            f"{', '.join(_pct(e) for e in orc)}; GMRDataWarnings: "
            f"{sum(issubclass(w.category, g.GMRDataWarning) for w in caught)}.", "",
            str(sol.stats["resolution"]), ""]


def sweep(system_name: str, seeds: int) -> list[str]:
    """The F'' bound of the resolution report against the restoring error, by amplitude."""
    case = Case(f"{system_name}_xva", system_name, "xva")
    s = case.make_system()
    lines = [f"# Resolution bound against restoring error: {system_name}, x v a at {SNR:g} dB, by amplitude", "",
             f"Curvature oracle {_pct(oracle_error(s, 0))}. Columns: the most excited well's amplitude ratio, the "
             "largest F'' bound over the wells (two noise-limited standard errors of F''/2 carried through the "
             "interpolant of F, F', F'' at the wells: RMS over the span, % of the force's RMS), "
             "the restoring error and its ratio to the oracle, F'' resolved at every well (bound <= "
             f"{100 * g.ResolutionReport.bound:g} %).",
             "", "| ratio | seed | F'' bound | restoring error | / oracle | F'' resolved everywhere |", "|---|---|---|---|---|---|"]
    for ratio in (0.002, 0.0035, 0.005, 0.01, 0.02, 0.04):
        amp = base_amplitude(s, ratio)
        for seed in range(seeds):
            recs = recordings(case, amp, seed)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                sol = g.reconstruct(recs, throw=False)
            res = sol.stats["resolution"]
            b2 = [w.terms[2] for w in res.wells]
            bound = max(t.impact for t in b2)
            err = g.metrics.restoring_error(sol.value, s.truth, 0, s.x_range[0])
            lines.append(f"| {_pct(ratio)} | {seed} | {_pct(bound)} | {_pct(err)} | {err / oracle_error(s, 0):.2f} | "
                         f"{all(t.resolved for t in b2)} |")
            print(lines[-1], flush=True)
    return lines


def slow_content(case: Case, seeds: int) -> list[str]:
    """Is it what a velocity sensor cannot carry? The same records with x measured, as recorded
    and with their content below the cut-off v's integration would use removed (`_integrate`:
    the static offset and its drift as the sweep passes each resonance, a signature of F'' at
    small vibrations), each reconstructed with the defaults, beside the velocity-only case."""
    from scipy.fft import dct, idct

    def remove_drift(y, dt, f_hp):  # as `_integrate.remove_drift`: cosine-transform content below f_hp zeroed
        c = dct(y, type=2, norm="ortho", axis=0)
        c[np.arange(c.shape[0]) / (2.0 * c.shape[0] * dt) < f_hp] = 0.0
        return idct(c, type=2, norm="ortho", axis=0)

    system = case.make_system()
    amp = base_amplitude(system, case.ratio)
    lines = [f"### {case.name}: is it the slow content a velocity sensor cannot carry?", "",
             "The same sweeps with x measured instead (displacement only, 30 dB), as recorded and high-passed at "
             "the cut-off the velocity-only integration uses (cosine transform, `_integrate.remove_drift`), "
             "each with `gmr.reconstruct` defaults.", "",
             "| seed | cut-off (Hz, per well) | x as recorded | x high-passed | v only (this case) |", "|---|---|---|---|---|"]
    for seed in range(seeds):
        raw = g.systems.make_recordings(system, amp, snr_db=SNR, seed=seed)
        recs_x, recs_hp, cuts = [], [], []
        for k, r in enumerate(raw):
            dt = float(r.t[1] - r.t[0])
            cut = float(g.Recording(t=r.t, v=r.v, equilibrium=np.asarray(system.equilibria[k], float)).integration[
                "f_highpass_hz"][0])  # the cut-off the velocity-only recording integrates with
            x = remove_drift(r.x - r.x.mean(axis=0), dt, cut) + np.asarray(system.equilibria[k], float)
            common = {"t": r.t, "base_acc": r.base_acc, "masses": r.masses, "name": r.name}
            recs_x.append(g.Recording(x=r.x, **common))
            recs_hp.append(g.Recording(x=x, **common))
            cuts.append(cut)
        errs = []
        for recs in (recs_x, recs_hp, recordings(case, amp, seed)):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                sol = g.reconstruct(recs, throw=False)
            errs.append(g.metrics.restoring_error(sol.value, system.truth, 0, system.x_range[0]))
        lines.append(f"| {seed} | {', '.join(f'{c:.3g}' for c in cuts)} | {_pct(errs[0])} | {_pct(errs[1])} | {_pct(errs[2])} |")
        print(lines[-1], flush=True)
    return lines + [""]


def floor_check(case: Case, seeds: int) -> list[str]:
    """The noise floor's standard errors against the scatter of the local F''/2 over `seeds` noise
    seeds, and the defaults' restoring error over those seeds against the floor."""
    system = case.make_system()
    amp = base_amplitude(system, case.ratio)
    d = system.truth.n_dof
    coefs, ses, errs = [], [], []  # per seed: (dof, wells) F''/2, (dof, wells, 3) se_h, (dof,) errors
    for seed in range(seeds):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sol = g.reconstruct(recordings(case, amp, seed), throw=False)
        res = sol.stats["resolution"]
        ses.append([local_se(res, system, i) for i in range(d)])
        coefs.append([[w.terms[2].coef for w in matched_wells(res, system, i)] for i in range(d)])
        errs.append([g.metrics.restoring_error(sol.value, system.truth, i, system.x_range[i]) for i in range(d)])
        print(case.name, seed, errs[-1], flush=True)
    coefs, ses, errs = np.array(coefs), np.array(ses), np.array(errs)
    rms_se = np.sqrt(np.mean(ses**2, axis=0))  # (dof, wells, 3)
    lines = [f"## {case.name}: {seeds} noise seeds", "",
             f"Base amplitude {amp:.3g}, {SNR:g} dB, `gmr.reconstruct` defaults on each seed.", "",
             "| DOF | well x | truth F''/2 | mean estimate | scatter (sd over seeds) | RMS standard error (`se_h`) "
             "| dropped |", "|---|---|---|---|---|---|---|"]
    for i in range(d):
        taylor = truth_taylor(system, i)
        for k, x in enumerate(np.asarray(system.equilibria[:, i], float)):
            cs = coefs[:, i, k]
            lines.append(f"| {i} | {x:.4g} | {taylor[k, 2]:.4g} | {cs.mean():.4g} | {cs.std(ddof=1):.3g} | "
                         f"{rms_se[i, k, 2]:.3g} | {int(np.sum(cs == 0))} |")
    lines += ["", "| DOF | curvature oracle | noise floor (median / 90 %, RMS standard errors) | restoring error "
              "(median / max over seeds) | per seed |", "|---|---|---|---|---|"]
    for i in range(d):
        floor = noise_floor(system, i, rms_se[i])
        lines.append(f"| {i} | {_pct(oracle_error(system, i))} | {_pct(np.median(floor))} / "
                     f"{_pct(np.percentile(floor, 90))} | {_pct(np.median(errs[:, i]))} / {_pct(errs[:, i].max())} | "
                     f"{', '.join(f'{100 * e:.3g}' for e in errs[:, i])} % |")
    # cells of one design (the truth's Taylor data proportional): an estimator that pools them
    # (inverse-variance mean of the relative Taylor data) has a lower floor
    taylors = np.array([truth_taylor(system, i) for i in range(d)])  # (dof, wells, 3)
    scale = taylors[:, :1, 1:2]  # each cell's F' at its first well
    rel = taylors / scale
    if d > 1 and np.allclose(rel, rel[:1], rtol=1e-6, atol=1e-12):
        rel_se = rms_se / np.abs(scale)
        with np.errstate(divide="ignore"):
            pooled = np.where(np.all(rel_se > 0, axis=0), 1.0 / np.sqrt(np.sum(1.0 / np.where(rel_se > 0, rel_se, np.inf) ** 2,
                                                                              axis=0)), 0.0)
        floor = noise_floor(system, 0, pooled * np.abs(scale[0]))
        lines += ["", f"The {d} cells are one design (the truth's Taylor data proportional): pooled (inverse-variance "
                  f"mean of each well's relative F, F', F''/2 over the cells), the noise floor is {_pct(np.median(floor))} "
                  f"(median) / {_pct(np.percentile(floor, 90))} (90 %), against the defaults' median "
                  f"{_pct(np.median(errs))} over seeds and cells."]
    return lines + [""]


def emit(path: str, lines: list[str]) -> None:
    """Write the report's `lines` to `path` and print them."""
    with open(path, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("\n".join(lines))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--seeds", type=int, default=1)
    ap.add_argument("--sweep", default=None, help="bound calibration on this system (arch, magnet) instead")
    ap.add_argument("--floor-seeds", type=int, default=0, help="the noise floor against this many seeds' scatter instead")
    ap.add_argument("--no-advice-check", action="store_true")
    ap.add_argument("--no-nominal", action="store_true", help="skip the nominal kresling5 resolution table")
    ap.add_argument("--out", default="results/stress_cases.md")
    args = ap.parse_args()
    if args.sweep:
        t0 = time.time()
        lines = sweep(args.sweep, args.seeds)
        lines.insert(1, f"\n`python studies/stress_cases.py --sweep {args.sweep} --seeds {args.seeds} --out {args.out}` "
                        f"({(time.time() - t0) / 60:.1f} min).")
        return emit(args.out, lines)
    if args.floor_seeds:
        t0 = time.time()
        lines = [f"# Stress cases: the noise floor against {args.floor_seeds} noise seeds", ""]
        for name in args.cases.split(","):
            lines += floor_check(CASES[name], args.floor_seeds)
            if CASES[name].sensing == "v" and CASES[name].system != "kresling3":
                lines += slow_content(CASES[name], min(args.floor_seeds, 4))
        lines.insert(1, f"\n`python studies/stress_cases.py --floor-seeds {args.floor_seeds} --cases {args.cases} "
                        f"--out {args.out}` ({(time.time() - t0) / 60:.1f} min on the shared 2-core dev machine).")
        return emit(args.out, lines)
    t_start = time.time()
    body, summary = [], []
    for name in args.cases.split(","):
        case = CASES[name]
        amp = base_amplitude(case.make_system(), case.ratio)
        for seed in range(args.seeds):
            row = evaluate(case, amp, seed)
            body += describe(row, f"{name}, seed {seed}")
            adv = None if args.no_advice_check else advised_amplitude(row)
            after = evaluate(case, adv, seed) if adv is not None else None
            if after is not None:
                body += describe(after, f"{name}, seed {seed}, re-recorded at the advised amplitude")
            snr = None if args.no_advice_check else advised_snr(row)
            louder = evaluate(case, amp, seed, snr) if snr is not None else None
            if louder is not None:
                body += describe(louder, f"{name}, seed {seed}, re-recorded at the advised SNR")
            summary.append((row, after, louder))
            print("\n".join(describe(row, name)[:12]), flush=True)
    if not args.no_nominal:
        body += nominal_kresling5()
    write(args, summary, body, time.time() - t_start)


def write(args, summary, body, secs):
    lines = ["# Stress cases", "",
             f"`python studies/stress_cases.py --seeds {args.seeds}"
             + (f" --cases {args.cases}" if args.cases != ",".join(CASES) else "")
             + f"` ({secs / 60:.1f} min on the shared 2-core dev machine).", "",
             __doc__.split("\n\n    python")[0].split("\n\n", 1)[1], "",
             "| case | seed | amplitude ratios | spurious wells | diverged (free / forced) | restoring error / oracle "
             "(noise floor, median; per DOF) | within 2x | warned | resolution: needed and unresolved | at the advised amplitude "
             "| at the advised SNR (same amplitude) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]

    def checked(row, after, what):
        if after is None:
            return "-"
        if "refused" in after:
            return f"{what}: refused ({after['refused'][:90]}...)"
        errs_a = ", ".join(f"{_pct(x['error'])}" for x in after["dofs"])
        return (f"{what}: still missing {len(after['resolution'].missing())}; error {errs_a}; within 2x "
                f"{'yes' if after['pass']['error'] else 'no'}; diverged {after['divergence']['free']}+"
                f"{after['divergence']['forced']}; warnings {len(after['warnings'])}")

    for row, after, louder in summary:
        if "refused" in row:
            lines.append(f"| {row['case']} | {row['seed']} | refused: {row['refused'][:120]} | | | | | | | | |")
            continue
        div = row["divergence"]
        spur = sum(max(0, x["wells"] - x["true_wells"]) for x in row["dofs"])
        errs = ", ".join(f"{_pct(x['error'])} / {_pct(x['oracle'])} (floor {_pct(x['floor'])})" for x in row["dofs"])
        miss = "; ".join(f"DOF {w.dof} x={w.equilibrium:.3g}: {t.name}"
                         for w, t in row["resolution"].missing()) or "-"
        adv = (checked(row, after, f"x{after['amplitude'] / row['amplitude']:.2g} base amplitude") if after else
               "not advised (F' unresolved, or beyond the small-vibration regime)" if row["resolution"].missing() else "-")
        snr = checked(row, louder, f"{louder['snr']:.3g} dB" if louder else "")
        lines.append(f"| {row['case']} | {row['seed']} | {', '.join(f'{100 * r:.2g}' for r in row['ratios'])} % | {spur} | "
                     f"{div['free']}/{div['n_free']}, {div['forced']}/{div['n_forced']} | {errs} | "
                     f"{'yes' if row['pass']['error'] else 'NO'} | {len(row['warnings'])} | {miss} | {adv} | {snr} |")
    lines += ["", "## Per case", ""] + body
    with open(args.out, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("wrote", args.out)


if __name__ == "__main__":
    main()
