"""The loop fit -> discover -> basins on a chain of three designs whose small vibrations cannot fix the damping.

Truth (`MixedChain`, unit masses, a chain from the base): cell 0 a quintic double well
20 (u^5 - u), cell 1 the preloaded von Mises truss of `systems.shallow_arch`, cell 2 an asymmetric
cubic 30 u (u + 1.2) (u - 0.8); damping 0.6 v + 1.0 v^3 in cells 0 and 2 (cubic damping), 0.6 v in
cell 1. Records: base sweeps 0.2-5 Hz around the all-low and the all-high configurations, the most
excited cell at `--ratio` of its interwell distance, x v a at `--snr` dB (the small vibrations);
one deployment record (a strong base sweep from all-low that crosses the wells) for `discover`, and
a second one, from all-high at another amplitude, as its holdout.

Steps and measures:

1. `gmr.reconstruct` (defaults): restoring error per cell over its interwell span, the damping it
   kept.
2. `gmr.discover(fit, [deployment], [holdout])`, with the fit's posterior as prior (default) and
   without (`prior=False`): the cubic damping found per cell against the truth's (target: within
   20 %), the holdout error before -> after, and each cell's restoring error after (what the
   re-calibration did to what the wells determined).
3. Basin maps over an `--n` x `--n` (f, A) grid of the Eq. (25) tip load from all-low: the share
   of points in the truth's configuration for the fit, the fit's laws with the true damping, and
   each augmented model; the fit's `basin_probability` over `--draws` drawn models (the share of
   points whose most probable configuration is the truth's, and the share with probability < 0.9).

    python studies/discover_loop.py [--seeds 0 1 2] [--n 24] [--out results/discover_loop.md]
"""

import argparse
import time
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import gmr_jax as g
from gmr_jax.systems import System, make_recordings

CUBIC = (1.0, 0.0, 1.0)
VISCOUS = (0.6, 0.6, 0.6)


class MixedChain(g.AbstractMechanicalModel):
    """Three bistable cells of different designs in a chain (module docstring)."""

    masses: jax.Array
    topology: g.AbstractTopology = eqx.field(static=True, default=g.Chain())

    def restoring(self, x):
        u0, u1, u2 = x[0], x[1], x[2]
        l0 = (2.0**2 + 1.0**2) ** 0.5
        return jnp.stack([20.0 * (u0**5 - u0),
                          100.0 * u1 * (1.0 - l0 / jnp.sqrt(4.0 + u1**2)) + 2.0,
                          30.0 * u2 * (u2 + 1.2) * (u2 - 0.8)])

    def damping(self, x, v):
        return jnp.asarray(VISCOUS) * v + jnp.asarray(CUBIC) * v**3


LOW = np.array([-1.0, -1.0902327, -1.2])
HIGH = np.array([1.0, 0.8838359, 0.8])
SPAN = HIGH - LOW


def system(equilibria, sweep=(0.2, 5.0), duration=60.0) -> System:
    return System(name="mixed", truth=MixedChain(jnp.ones(3)), equilibria=np.asarray(equilibria), sweep=sweep,
                  duration=duration, fs=200.0, x_range=np.stack([LOW - 0.1 * SPAN, HIGH + 0.1 * SPAN], 1),
                  v_range=np.tile([-3.0, 3.0], (3, 1)))


def small_records(ratio, snr, seed):
    s = system([LOW, HIGH])
    clean = make_recordings(s, 1e-3, snr_db=None)
    amp = max(np.percentile(np.abs(r.x - r.x.mean(0)), 99.9, axis=0).max() for r in clean) / 1e-3
    amp = ratio * SPAN.min() / amp
    return make_recordings(s, amp, snr_db=snr, seed=seed), amp


def deployment(start, amplitude, snr, seed, name):
    r = make_recordings(system([start], sweep=(0.5, 3.0), duration=40.0), amplitude, snr_db=snr, seed=seed)[0]
    return g.Recording(t=r.t, x=r.x, v=r.v, a=r.a, base_acc=r.base_acc, masses=r.masses, name=name)


def crossings(rec) -> int:
    mid = 0.5 * (LOW + HIGH)
    side = np.sign(rec.x - mid)
    return int(np.sum(side[1:] != side[:-1]))


def restoring_errors(model, truth) -> list[float]:
    out = []
    for i in range(3):
        u = np.linspace(LOW[i], HIGH[i], 401)
        X = np.zeros((u.size, 3))
        X[:, i] = u
        ft = np.asarray(jax.vmap(truth.restoring)(jnp.asarray(X)))[:, i]
        fm = np.asarray(jax.vmap(model.restoring)(jnp.asarray(X)))[:, i]
        out.append(float(np.linalg.norm(fm - ft) / np.linalg.norm(ft)))
    return out


def band_cover(model, truth) -> list[float]:
    """Share of each cell's interwell span where the 95 % band holds the truth's restoring force."""
    return [g.metrics.band_coverage(model, truth, i, (LOW[i], HIGH[i]), n=101, level=0.95).share for i in range(3)]


def damping_errors(model, truth, vmax) -> list[float]:
    """Relative L2 error of each cell's damping force over its interwell span x [-vmax_i, vmax_i]."""
    out = []
    for i in range(3):
        u, w = np.meshgrid(np.linspace(LOW[i], HIGH[i], 41), np.linspace(-vmax[i], vmax[i], 81))
        X, V = np.zeros((u.size, 3)), np.zeros((u.size, 3))
        X[:, i], V[:, i] = u.ravel(), w.ravel()
        ft = np.asarray(jax.vmap(truth.damping)(jnp.asarray(X), jnp.asarray(V)))[:, i]
        fm = np.asarray(jax.vmap(model.damping)(jnp.asarray(X), jnp.asarray(V)))[:, i]
        out.append(float(np.linalg.norm(fm - ft) / np.linalg.norm(ft)))
    return out


def with_true_damping(model):
    terms = [t for t in model.terms() if t["physics"] == "stiffness"]
    for i in range(3):
        terms.append({"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": VISCOUS[i]})
        if CUBIC[i]:
            terms.append({"dof": i, "physics": "velocity_damping", "order": 3, "coefficient": CUBIC[i]})
    return g.from_terms(np.asarray(model.masses), terms, "chain")


def cubic_of(model, i) -> float:
    vd = np.asarray(model.velocity_damping)
    return float(vd[i, 3]) if vd.shape[1] > 3 else 0.0


def configs(model, f, A, settle, truth_wells=None):
    wells = truth_wells if truth_wells is not None else g.stable_wells(
        model, np.stack([LOW - 0.1 * SPAN, HIGH + 0.1 * SPAN], 1))
    sol = g.basin_map(model, f, A, wells, x0=jnp.asarray(LOW), settings=g.SweepSettings(settle_time=settle),
                      throw=False)
    return np.asarray(sol.value.config)


def run(seed, args):
    truth = MixedChain(jnp.ones(3))
    recs, amp = small_records(args.ratio, args.snr, seed)
    dep = deployment(LOW, args.deploy, args.snr, seed + 100, "deployment")
    hold = deployment(HIGH, args.holdout, args.snr, seed + 200, "holdout")
    t0 = time.time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = g.reconstruct(recs, topology="chain").value
    t_fit = time.time() - t0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        pooled = g.reconstruct(recs, topology="chain", designs=[0, 0, 0])
    row = {"seed": seed, "base amplitude": amp, "crossings": (crossings(dep), crossings(hold)),
           "fit restoring": restoring_errors(fit, truth), "fit cubic": [cubic_of(fit, i) for i in range(3)],
           "fit damping": damping_errors(fit, truth, np.abs(dep.v).max(0)),
           "labelled one design": (restoring_errors(pooled.value, truth), band_cover(pooled.value, truth),
                                   pooled.stats["dofs"][0].stats.get("design_spread")),
           "fit band": band_cover(fit, truth),
           "fit time": t_fit}
    reps = {}
    for label, prior in (("posterior prior", True), ("least squares", False)):
        t0 = time.time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rep = g.discover(fit, [dep], [hold], prior=prior).value
        aug = rep.model
        found = {(f["dof"], f["physics"], f.get("order")): f["coefficient"] for f in rep.findings}
        reps[label] = aug
        row[label] = {
            "cubic": [cubic_of(aug, i) for i in range(3)],
            "findings": sorted(f"{f['dof']}:{f['physics']}" for f in rep.findings),
            "holdout": (rep.before["nrmse"], rep.after["nrmse"], rep.before["kind"]),
            "restoring": restoring_errors(aug, truth), "warnings": len(rep.warnings), "time": time.time() - t0,
            "damping": damping_errors(aug, truth, np.abs(dep.v).max(0)),
            "found": found}
    f = np.linspace(args.fmin, args.fmax, args.n)
    A = np.linspace(args.amin, args.amax, args.n)
    truth_wells = np.stack([LOW, HIGH], 1)
    ref = configs(truth, f, A, args.settle, truth_wells)
    agree = lambda c: float(np.mean(c == ref))  # noqa: E731
    row["map"] = {"truth configurations": int(len(np.unique(ref))),
                  "fit": agree(configs(fit, f, A, args.settle)),
                  "fit + true damping": agree(configs(with_true_damping(fit), f, A, args.settle))}
    for label, aug in reps.items():
        row["map"][f"augmented ({label})"] = agree(configs(aug, f, A, args.settle))
    prob = g.basin_probability(fit, f, A, jax.random.PRNGKey(seed), args.draws,
                               x_range=np.stack([LOW - 0.1 * SPAN, HIGH + 0.1 * SPAN], 1), x0=jnp.asarray(LOW),
                               settings=g.SweepSettings(settle_time=args.settle)).value
    p = np.asarray(prob.probability)
    top = np.asarray(prob.configs)[np.argmax(p, -1)]
    row["map"]["fit draws: most probable"] = agree(top)
    row["map"]["fit draws: p < 0.9"] = float(np.mean(p.max(-1) < 0.9))
    return row


def pct(a):
    return f"{100 * a:.3g} %"


def table(rows, args) -> str:
    lines = [
        "# The loop: fit -> discover -> basins, three designs in a chain",
        "",
        f"`python studies/discover_loop.py --seeds {' '.join(map(str, args.seeds))} --n {args.n}` "
        f"({args.minutes:.1f} min on the 2-core dev machine). Definitions: the module docstring of "
        "`studies/discover_loop.py`.",
        "",
        f"Truth: cubic damping {CUBIC[0]:g} v^3 in cells 0 and 2 (viscous {VISCOUS[0]:g} v everywhere). Small "
        f"vibrations at {pct(args.ratio)} of the interwell distance, {args.snr:g} dB, x v a; deployment record base "
        f"amplitude {args.deploy:g} from all-low, holdout {args.holdout:g} from all-high (0.5-3 Hz, 40 s).",
        "",
        "## Fit and discovery",
        "",
        "| seed | route | cubic damping cell 0 / 2 (truth 1, 1) | within 20 % | cell 1 cubic | findings | holdout "
        "NRMSE before -> after | restoring error per cell (interwell span) | damping error per cell (span x "
        "deployment speeds) | warnings |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['seed']} | fit | {r['fit cubic'][0]:.3g} / {r['fit cubic'][2]:.3g} | - | "
                     f"{r['fit cubic'][1]:.3g} | - | - | {', '.join(pct(e) for e in r['fit restoring'])} | "
                     f"{', '.join(pct(e) for e in r['fit damping'])} | - |")
        for label in ("posterior prior", "least squares"):
            d = r[label]
            ok = all(abs(d["cubic"][i] - CUBIC[i]) <= 0.2 * CUBIC[i] for i in (0, 2))
            b, a, kind = d["holdout"]
            lines.append(f"| {r['seed']} | discover, {label} | {d['cubic'][0]:.3g} / {d['cubic'][2]:.3g} | "
                         f"{'yes' if ok else 'NO'} | {d['cubic'][1]:.3g} | {', '.join(d['findings']) or '-'} | "
                         f"{pct(b)} -> {pct(a)} ({kind}) | {', '.join(pct(e) for e in d['restoring'])} | "
                         f"{', '.join(pct(e) for e in d['damping'])} | {d['warnings']} |")
    lines += ["", "## The cells labelled one design (`designs=[0, 0, 0]`) against each its own law (default)", "",
              "| seed | labels | restoring error per cell | 95 % band holds the truth on the span |", "|---|---|---|---|"]
    for r in rows:
        e, c, _ = r["labelled one design"]
        lines.append(f"| {r['seed']} | none (default) | {', '.join(pct(x) for x in r['fit restoring'])} | "
                     f"{', '.join(pct(x) for x in r['fit band'])} |")
        lines.append(f"| {r['seed']} | one design | {', '.join(pct(x) for x in e)} | {', '.join(pct(x) for x in c)} |")
    lines += ["", "## Basin maps from all-low (share of grid points in the truth's configuration)", ""]
    keys = list(rows[0]["map"].keys())
    lines.append("| seed | " + " | ".join(keys) + " |")
    lines.append("|---|" + "---|" * len(keys))
    for r in rows:
        lines.append(f"| {r['seed']} | " + " | ".join(
            str(r['map'][k]) if k == "truth configurations" else pct(r['map'][k]) for k in keys) + " |")
    lines += ["", f"Grid: f {args.fmin:g}-{args.fmax:g} Hz, A {args.amin:g}-{args.amax:g} (tip force, Eq. 25), "
              f"{args.n} x {args.n}, settle {args.settle:g} s; draws: {args.draws} models from the fit's covariance.",
              ""]
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--ratio", type=float, default=0.005)
    ap.add_argument("--snr", type=float, default=50.0)
    ap.add_argument("--deploy", type=float, default=0.6)
    ap.add_argument("--holdout", type=float, default=0.5)
    ap.add_argument("--n", type=int, default=24)
    ap.add_argument("--fmin", type=float, default=0.3)
    ap.add_argument("--fmax", type=float, default=4.0)
    ap.add_argument("--amin", type=float, default=5.0)
    ap.add_argument("--amax", type=float, default=120.0)
    ap.add_argument("--settle", type=float, default=60.0)
    ap.add_argument("--draws", type=int, default=16)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    t0 = time.time()
    rows = []
    for s in args.seeds:
        rows.append(run(s, args))
        print(rows[-1], flush=True)
    args.minutes = (time.time() - t0) / 60
    text = table(rows, args)
    print(text)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(text)


if __name__ == "__main__":
    main()
