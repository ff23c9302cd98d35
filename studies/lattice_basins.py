"""Basin map of the 4 x 4 grid of bistable trusses: the reconstructed model against the truth.

The grid (`gmr.systems.grid()`) is recorded at 2 % of the interwell distance, 50 dB, around its four
configurations and reconstructed (`reconstruct(recs, topology=graph, designs=system.designs)`).
The model's restoring laws with the truth's damping are swept too (what the laws alone reach).
Both the model and the truth start with every truss in its second (shallow) well and are pulled at
one node by the Eq. (25) half-sine (`SweepSettings(load="node:K")`, a negative amplitude: towards
the deep well); each point is classified by every element's well (`BasinMap.wells`) and by the
number of elements switched (`BasinMap.counts`). Agreement: the share of points whose model pattern
(every element's well) equals the truth's. Peer: SciPy's `solve_ivp` (RK45, the same tolerances) on
the truth's equations, point by point, on a subset of the grid, its time per point scaled to the grid.

Inside the records' range: the points whose pull |A| is at most the truss force at the lower end
of the system's box (`x_range`: the wells' span and 25 % beyond), i.e. whose static deflection of
the pulled truss stays where the records give its law; larger pulls drive it beyond the deep well,
where the model's law is the prior's continuation.

The truth's own sensitivity: its map against the maps of the truth with the trusses' stiffness k
or damping c changed by a small factor, and under tighter integration tolerances.

What the records hold (`--records`): the same maps for models fitted from records at other vibration
amplitudes and SNRs (one seed each), beside the largest error of the truss law over its interwell
span and of the truss damping over deformations in that span and speeds up to 2 (the pull's
switching speeds reach 2-5; the records' stay below 0.3).

    python studies/lattice_basins.py [--n 50] [--node 5] [--peer 60] [--records 0.02:50 0.03:70 ...] [--out results/lattice_basins.md]
"""

import argparse
import dataclasses
import time
import warnings
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from scipy.integrate import solve_ivp

import gmr_jax as gmr

RESULTS = Path(__file__).resolve().parents[1] / "results"


def peer_final(model, x0, f, a, node, settle, wells, rtol, atol):
    """SciPy RK45 of the truth under the pull (its equations written in NumPy, as a user would),
    classified as `basin_map` does (per element)."""
    d = model.n_dof
    B = np.asarray(model.topology.incidence)  # (E, D)
    k, w, rise, p0, s, c, c2, m = (np.asarray(getattr(model, n), float) for n in
                                   ("k", "w", "rise", "p", "s", "c", "c2", "masses"))
    l0 = np.sqrt(w**2 + rise**2)

    def rhs(t, y):
        x, v = y[:d], y[d:]
        e, ev = B @ x, B @ v
        force = k * e * (1.0 - l0 / np.sqrt(w**2 + e**2)) + p0 + s * e + c * ev + c2 * ev * np.abs(ev)
        load = np.zeros(d)
        load[node] = a * np.sin(2 * np.pi * f * t) if t <= 0.5 / f else 0.0
        return np.concatenate([v, (load - B.T @ force) / m])

    sol = solve_ivp(rhs, (0.0, 0.5 / f + settle), np.concatenate([x0, np.zeros(d)]), rtol=rtol, atol=atol)
    dfm = np.asarray(model.topology.deformations(jnp.asarray(sol.y[:d, -1])))
    return [int(np.nanargmin(np.abs(dfm[e] - wells[e]))) if np.sum(np.isfinite(wells[e])) > 1 else 0
            for e in range(wells.shape[0])]


def with_true_damping(model, truth):
    """The model's restoring laws with the truth's damping c d' + c2 d'|d'| on every element."""
    graph = truth.topology
    terms = [t for t in model.terms() if t["physics"] == "stiffness"]
    for e in range(graph.n_elements):
        for order, c in ((1, float(truth.c[e])), (2, float(truth.c2[e]))):
            if c:
                terms.append({"element": e, "physics": "velocity_damping", "order": order, "coefficient": c})
    return gmr.from_terms(np.asarray(model.masses), terms, graph)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=50)
    ap.add_argument("--node", type=int, default=5)
    ap.add_argument("--fmin", type=float, default=0.03)
    ap.add_argument("--fmax", type=float, default=1.5)
    ap.add_argument("--amin", type=float, default=-60.0)
    ap.add_argument("--amax", type=float, default=-1.0)
    ap.add_argument("--settle", type=float, default=150.0)
    ap.add_argument("--peer", type=int, default=60, help="points integrated by the SciPy peer")
    ap.add_argument("--records", nargs="*", default=["0.02:50", "0.03:50", "0.02:70", "0.03:70", "0.03:90"],
                    help="fraction:SNR of further record sets (what the records hold)")
    ap.add_argument("--out", default=str(RESULTS / "lattice_basins.md"))
    args = ap.parse_args()
    system = gmr.systems.grid()
    truth, graph = system.truth, system.truth.topology
    wells_t = gmr.stable_wells(truth, system.x_range)
    span = float(np.nanmax(wells_t[0]) - np.nanmin(wells_t[0]))  # a truss's interwell distance
    recs = gmr.systems.make_recordings(system, 0.02 * span, snr_db=50.0, seed=0)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = gmr.reconstruct(recs, topology=graph, designs=system.designs).value
    t_fit = time.perf_counter() - t0
    wells_m = gmr.stable_wells(model, system.x_range)
    second = np.where(np.sum(np.isfinite(wells_t), axis=1) > 1, 1, 0)
    x0_t = gmr.configuration(truth, wells_t, second)
    x0_m = gmr.configuration(model, wells_m, second)
    f = np.linspace(args.fmin, args.fmax, args.n)
    A = np.linspace(args.amin, args.amax, args.n)
    st = gmr.SweepSettings(settle_time=args.settle, load=f"node:{args.node}")
    mixed = with_true_damping(model, truth)
    maps, secs = {}, {}
    for name, m, w, x0 in (("truth", truth, wells_t, x0_t), ("model", model, wells_m, x0_m),
                           ("laws", mixed, wells_m, x0_m)):
        gmr.basin_map(m, f[:2], A[:2], w, x0=x0, settings=st, throw=False)  # compile apart
        t0 = time.perf_counter()
        maps[name] = gmr.basin_map(m, f, A, w, x0=x0, settings=st, throw=False)
        secs[name] = time.perf_counter() - t0
    bt, bm = maps["truth"].value, maps["model"].value
    pt, pm = np.asarray(bt.wells), np.asarray(bm.wells)
    same = np.all(pt == pm, axis=-1) & np.all(pt >= 0, axis=-1)
    ct, cm = np.asarray(bt.counts()), np.asarray(bm.counts())
    pl = np.asarray(maps["laws"].value.wells)
    same_laws = np.all(pt == pl, axis=-1) & np.all(pt >= 0, axis=-1)
    e5 = int(np.nonzero(np.asarray(graph.incidence)[:, args.node] != 0)[0][0])  # the pulled node's truss
    lo_d = float(system.x_range[e5][0])
    a_in = abs(float(truth.restoring(jnp.full(graph.n_elements, lo_d))[e5]))  # the truss force at the box's end
    inside = np.abs(A)[:, None] <= a_in
    inside = np.broadcast_to(inside, same.shape)
    rng = np.random.default_rng(0)
    pick = rng.choice(f.size * A.size, size=min(args.peer, f.size * A.size), replace=False)
    t0 = time.perf_counter()
    agree_peer = 0
    for k in pick:
        i, j = divmod(int(k), f.size)
        want = peer_final(truth, x0_t, f[j], A[i], args.node, args.settle, wells_t, 1e-6, 1e-8)
        agree_peer += int(want == list(pt[i, j]))
    per_point = (time.perf_counter() - t0) / pick.size
    n = f.size * A.size
    vals, cnt = np.unique(ct, return_counts=True)
    lines = [
        "# Lattice basins: the 4 x 4 grid, model against truth",
        "",
        f"`python studies/lattice_basins.py --n {args.n} --node {args.node} --peer {args.peer}` (module docstring: "
        "definitions). 2-core dev machine, float64.",
        "",
        f"Grid {args.n} x {args.n}: f {args.fmin:g}-{args.fmax:g} Hz, A {args.amin:g} to {args.amax:g} (a pull on node "
        f"{args.node}), settle {args.settle:g} s, from every truss in its second well. Fit: {t_fit:.1f} s (first call).",
        "",
        "| measure | value |",
        "|---|---|",
        f"| points where the model's pattern (every element's well) is the truth's | {100 * same.mean():.1f} % |",
        f"| points where the number of switched elements agrees | {100 * np.mean(ct == cm):.1f} % |",
        f"| the same with the model's laws and the truth's damping (pattern) | {100 * same_laws.mean():.1f} % |",
        f"| pattern agreement inside the records' range (abs(A) <= {a_in:.1f}, "
        f"{int(inside.sum())} points) | {100 * same[inside].mean():.1f} % (laws with the truth's damping "
        f"{100 * same_laws[inside].mean():.1f} %) |",
        "| truth's classes (elements switched: points) | " + ", ".join(f"{int(v)}: {c}" for v, c in zip(vals, cnt))
        + " |",
        f"| model's map, unsettled or failed points | {int(np.sum(cm < 0))} |",
        f"| sweep time, truth / model (lanes, compiled apart) | {secs['truth']:.1f} s / {secs['model']:.1f} s |",
        f"| SciPy solve_ivp (RK45, NumPy equations) on the truth, per point | {1e3 * per_point:.0f} ms ({per_point * n:.0f} s for the "
        f"grid, {per_point * n / secs['truth']:.0f}x the lanes sweep of the truth) |",
        f"| SciPy's final pattern equal to the lanes sweep's (truth) | {agree_peer}/{pick.size} |",
        "",
    ]
    lines += ["## The truth's own sensitivity", "", "| change to the truth | pattern agreement with the truth's map |",
              "|---|---|"]
    for label, field, factor in (("truss stiffness k x 1.0001", "k", 1.0001), ("truss stiffness k x 0.999", "k", 0.999),
                                 ("damping c x 1.01", "c", 1.01)):
        m = eqx.tree_at(lambda q: getattr(q, field), truth, getattr(truth, field) * factor)
        wp = gmr.stable_wells(m, system.x_range)
        pw = np.asarray(gmr.basin_map(m, f, A, wp, x0=gmr.configuration(m, wp, second), settings=st, throw=False).value.wells)
        lines.append(f"| {label} | {100 * np.mean(np.all(pt == pw, axis=-1)):.1f} % |")
    tight = dataclasses.replace(st, integrator=gmr.Integrator(rtol=1e-9, atol=1e-11))
    pw = np.asarray(gmr.basin_map(truth, f, A, wells_t, x0=x0_t, settings=tight, throw=False).value.wells)
    lines += [f"| integration tolerances rtol 1e-9, atol 1e-11 | {100 * np.mean(np.all(pt == pw, axis=-1)):.1f} % |", ""]
    if args.records:
        lines += ["## What the records hold", "",
                  "| records: amplitude (% interwell), SNR | truss law error | truss law error over the span and one "
                  "span beyond the deep well | truss damping error, speeds up to 2 | pattern agreement: model | model's laws, truth's "
                  "damping | model, inside the records' range |", "|---|---|---|---|---|---|---|"]
        bist = np.nonzero(system.designs == 0)[0]
        span_range = (float(np.nanmin(wells_t[0])), float(np.nanmax(wells_t[0])))
        for spec in args.records:
            frac, snr = (float(z) for z in spec.split(":"))
            recs = gmr.systems.make_recordings(system, frac * span, snr_db=snr, seed=0)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                mod = gmr.reconstruct(recs, topology=graph, designs=system.designs).value
            law = max(gmr.metrics.restoring_error(mod, truth, int(e), span_range) for e in bist)
            far = (2.0 * span_range[0] - span_range[1], span_range[1])  # the span and one span beyond the deep well
            law_far = max(gmr.metrics.restoring_error(mod, truth, int(e), far) for e in bist)
            damp = max(gmr.metrics.damping_error(mod, truth, int(e), span_range, (-2.0, 2.0)) for e in bist)
            w = gmr.stable_wells(mod, system.x_range)
            x0 = gmr.configuration(mod, w, second)
            agree = []
            for m in (mod, with_true_damping(mod, truth)):
                pw = np.asarray(gmr.basin_map(m, f, A, w, x0=x0, settings=st, throw=False).value.wells)
                agree.append(np.all(pt == pw, axis=-1) & np.all(pt >= 0, axis=-1))
            agree_in, agree = 100 * np.mean(agree[0][inside]), [100 * np.mean(a) for a in agree]
            lines.append(f"| {100 * frac:g} %, {snr:g} dB | {100 * law:.2f} % | {100 * law_far:.1f} % | {100 * damp:.1f} % | "
                         f"{agree[0]:.1f} % | {agree[1]:.1f} % | {agree_in:.1f} % |")
            print(lines[-1], flush=True)
        lines.append("")
    text = "\n".join(lines)
    print(text)
    Path(args.out).write_text(text)


if __name__ == "__main__":
    main()
