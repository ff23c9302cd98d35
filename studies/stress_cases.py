"""Synthetic stress cases on both routes, against the curvature oracle.

Non-polynomial cells (the shallow arch / von Mises truss, the magnetic bistable, the truss cells
of a 3-cell Kresling chain) excited by a base sweep at 0.2-0.5 % of their interwell distance,
30 dB noise on every channel, float32 time stamps (cast to float32 and back, as a lab file
stores them) and partial sensors (displacement only, velocity only with the equilibrium given,
a chain without its velocity channels). Each case is reconstructed by `gmr.reconstruct` on each
route of `--routes` (default: "evidence", the default, and "gls", the paper's route) and judged by

- spurious wells: stable equilibria of the fitted restoring force within one box-span of the
  metrics box, against the truth's (count);
- divergence: free runs of the fitted model from a grid of initial states over the metrics box
  (x and v, where the errors and basin maps are measured), unforced, 20 slowest natural periods,
  and under the training input from every equilibrium; a run that fails or leaves the box
  widened by two spans on either side is diverged;
- restoring error (relative L2 over the metrics box) against the curvature oracle's: the
  Hermite interpolant of each well's exact F, F', F'' (target: within 2x);
- whether the failures are warned (`GMRDataWarning`).

`--slow-seeds N` refits a velocity-only case's sweeps with x measured instead, as recorded and
high-passed at v's integration cut-off (`slow_content`): what a velocity sensor cannot carry.

    python studies/stress_cases.py [--cases arch_xva,magnet_xva_f32,...] [--seeds 1]
        [--routes evidence,gls] [--out results/stress_cases.md]
    python studies/stress_cases.py --slow-seeds 4 --cases arch_v_f32 --out results/stress_cases_slow.md
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
ROUTES = ("evidence", "gls")
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


def evaluate(case: Case, amplitude: float, seed: int, route: str = "evidence", snr: float = SNR) -> dict:
    system = case.make_system()
    recs = recordings(case, amplitude, seed, snr)
    head = {"case": case.name, "seed": seed, "amplitude": amplitude, "snr": snr, "route": route}
    t0 = time.time()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            sol = g.reconstruct(recs, coordination=route, throw=False,
                                designs=system.designs if route == "evidence" else None)
        except g.GMRInputError as e:
            return head | {"refused": str(e)}
    secs = time.time() - t0
    data_warnings = [str(w.message) for w in caught if issubclass(w.category, g.GMRDataWarning)]
    model = sol.value
    d = system.truth.n_dof
    row = head | {"secs": secs, "result": g.RESULTS[sol.result] or "successful", "warnings": data_warnings,
                  "degrees": [r.stats.get("degree", r.stats.get("K_r")) for r in sol.stats["dofs"]],
                  "ratios": response_ratios(system, amplitude).ravel().tolist(), "dofs": []}
    div = divergence(model, system, amplitude, seed)
    row["divergence"] = div
    for i in range(d):
        fit_w, true_w = well_counts(model, system, i)
        err = g.metrics.restoring_error(model, system.truth, i, system.x_range[i])
        orc = oracle_error(system, i)
        row["dofs"].append({"wells": fit_w, "true_wells": true_w, "error": err, "oracle": orc,
                            "oracle_vs": oracle_error(system, i, 1), "ratio": err / orc})
    row["pass"] = {
        "wells": all(x["wells"] <= x["true_wells"] for x in row["dofs"]),
        "divergence": div["free"] == 0 and div["forced"] == 0,
        "error": all(x["ratio"] <= 2.0 for x in row["dofs"]),
    }
    row["warned"] = bool(data_warnings)
    return row


# --- report -----------------------------------------------------------------------------------


def _pct(x):
    return f"{100 * x:.3g} %"


def describe(row: dict, header: str) -> list[str]:
    if "refused" in row:
        return [f"### {header}", "", f"Base amplitude {row['amplitude']:.3g}, {row['snr']:.3g} dB, route "
                f"{row['route']}: refused (`GMRInputError`): {row['refused']}", ""]
    p = row["pass"]
    div = row["divergence"]
    out = [f"### {header}", "",
           f"Base amplitude {row['amplitude']:.3g}, {row['snr']:.3g} dB; amplitude ratios per well "
           f"{', '.join(f'{100 * r:.2g} %' for r in row['ratios'])}; route {row['route']}, restoring degree "
           f"{', '.join(map(str, row['degrees']))}; {row['secs']:.0f} s; result {row['result']}.", "",
           "| DOF | wells fitted / true | restoring error | curvature oracle | ratio (target <= 2) | value+slope oracle |",
           "|---|---|---|---|---|---|"]
    for i, x in enumerate(row["dofs"]):
        out.append(f"| {i} | {x['wells']} / {x['true_wells']} | {_pct(x['error'])} | {_pct(x['oracle'])} | "
                   f"{x['ratio']:.2f} | {_pct(x['oracle_vs'])} |")
    out += ["", f"Divergence: {div['free']} of {div['n_free']} free runs, {div['forced']} of {div['n_forced']} runs "
            f"under the training sweep. Criteria: spurious wells {'pass' if p['wells'] else 'FAIL'}, divergence "
            f"{'pass' if p['divergence'] else 'FAIL'}, error within 2x of the oracle {'pass' if p['error'] else 'FAIL'}; "
            f"GMRDataWarnings: {len(row['warnings'])}.", ""]
    if row["warnings"]:
        out += [f"- warning: {w[:400]}{'...' if len(w) > 400 else ''}" for w in row["warnings"]] + [""]
    return out


def nominal_kresling5(routes) -> list[str]:
    """Not a stress case: the nominal 5-cell chain (0.3 mm, 60 dB, seed 0) on each route."""
    s = g.systems.kresling5()
    recs = g.systems.make_recordings(s, g.systems.KRESLING5_AMPLITUDE, seed=0)
    orc = [oracle_error(s, i) for i in range(5)]
    out = ["## Not a stress case: the nominal 5-cell Kresling chain (0.3 mm, 60 dB, seed 0)", "",
           f"Curvature oracle per cell {', '.join(_pct(e) for e in orc)}.", "",
           "| route | restoring error per cell | GMRDataWarnings |", "|---|---|---|"]
    for route in routes:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            sol = g.reconstruct(recs, coordination=route, designs=s.designs if route == "evidence" else None)
        errs = [g.metrics.restoring_error(sol.value, s.truth, i, s.x_range[i]) for i in range(5)]
        out.append(f"| {route} | {', '.join(_pct(e) for e in errs)} | "
                   f"{sum(issubclass(w.category, g.GMRDataWarning) for w in caught)} |")
    return out + [""]


def slow_content(case: Case, seeds: int, route: str = "evidence") -> list[str]:
    """Is it what a velocity sensor cannot carry? The same records with x measured, as recorded
    and with their content below the cut-off v's integration would use removed (`_integrate`:
    the static offset and its drift as the sweep passes each resonance, a signature of F'' at
    small vibrations), each reconstructed on `route`, beside the velocity-only case."""
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
             f"each with `gmr.reconstruct(coordination={route!r})`.", "",
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
                sol = g.reconstruct(recs, coordination=route, throw=False,
                                    designs=system.designs if route == "evidence" else None)
            errs.append(g.metrics.restoring_error(sol.value, system.truth, 0, system.x_range[0]))
        lines.append(f"| {seed} | {', '.join(f'{c:.3g}' for c in cuts)} | {_pct(errs[0])} | {_pct(errs[1])} | {_pct(errs[2])} |")
        print(lines[-1], flush=True)
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
    ap.add_argument("--routes", default=",".join(ROUTES), help="reconstruct's routes, side by side (evidence, gls, hermite)")
    ap.add_argument("--slow-seeds", type=int, default=0,
                    help="instead: the velocity-only cases refitted from x as recorded and high-passed, this many seeds")
    ap.add_argument("--no-nominal", action="store_true", help="skip the nominal kresling5 table")
    ap.add_argument("--out", default="results/stress_cases.md")
    args = ap.parse_args()
    routes = args.routes.split(",")
    if args.slow_seeds:
        t0 = time.time()
        lines = ["# Stress cases: what a velocity sensor cannot carry", ""]
        for name in args.cases.split(","):
            if CASES[name].sensing == "v" and CASES[name].system != "kresling3":
                for route in routes:
                    lines += slow_content(CASES[name], args.slow_seeds, route)
        lines.insert(1, f"\n`python studies/stress_cases.py --slow-seeds {args.slow_seeds} --cases {args.cases} "
                        f"--routes {args.routes} --out {args.out}` ({(time.time() - t0) / 60:.1f} min on the shared "
                        f"2-core dev machine).")
        return emit(args.out, lines)
    t_start = time.time()
    body, summary = [], []
    for name in args.cases.split(","):
        case = CASES[name]
        amp = base_amplitude(case.make_system(), case.ratio)
        for seed in range(args.seeds):
            for route in routes:
                row = evaluate(case, amp, seed, route)
                body += describe(row, f"{name}, seed {seed}, {route}")
                summary.append(row)
                print("\n".join(describe(row, f"{name}, {route}")[:10]), flush=True)
    if not args.no_nominal:
        body += nominal_kresling5(routes)
    write(args, summary, body, time.time() - t_start)


def write(args, summary, body, secs):
    lines = ["# Stress cases", "",
             f"`python studies/stress_cases.py --seeds {args.seeds}"
             + (f" --cases {args.cases}" if args.cases != ",".join(CASES) else "")
             + (f" --routes {args.routes}" if args.routes != ",".join(ROUTES) else "")
             + f"` ({secs / 60:.1f} min on the shared 2-core dev machine).", "",
             __doc__.split("\n\n`--slow-seeds")[0].split("\n\n", 1)[1], "",
             "| case | seed | route | amplitude ratios | spurious wells | diverged (free / forced) | restoring error / oracle "
             "(per DOF) | within 2x | warned |",
             "|---|---|---|---|---|---|---|---|---|"]
    for row in summary:
        if "refused" in row:
            lines.append(f"| {row['case']} | {row['seed']} | {row['route']} | refused: {row['refused'][:120]} | | | | | |")
            continue
        div = row["divergence"]
        spur = sum(max(0, x["wells"] - x["true_wells"]) for x in row["dofs"])
        errs = ", ".join(f"{_pct(x['error'])} / {_pct(x['oracle'])}" for x in row["dofs"])
        lines.append(f"| {row['case']} | {row['seed']} | {row['route']} | "
                     f"{', '.join(f'{100 * r:.2g}' for r in row['ratios'])} % | {spur} | "
                     f"{div['free']}/{div['n_free']}, {div['forced']}/{div['n_forced']} | {errs} | "
                     f"{'yes' if row['pass']['error'] else 'NO'} | {len(row['warnings'])} |")
    lines += ["", "## Per case", ""] + body
    with open(args.out, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("wrote", args.out)


if __name__ == "__main__":
    main()
