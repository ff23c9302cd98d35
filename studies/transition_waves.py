"""Transition waves on the grounded 2 x 8 ladder: the reconstructed model against the truth.

The ladder (`gmr.systems.grounded_ladder()`: every node held to the ground by a bistable von
Mises truss, linear couplers along the rails, linear rungs) starts with every truss in its second
well, the shallower one. A half-sine pull of amplitude A (`--f` Hz, towards the first well) on both
nodes of level 0 snaps the first level; the snap can run up the rails, level after level (a
transition wave, the stored energy released at each level paying for the damping), or stop (the
front is pinned by the lattice's discreteness). The model is reconstructed from small vibrations
(`--frac` of the interwell distance, 50 dB on every channel, the system's four configurations;
`reconstruct(recs, topology=graph, designs=system.designs)`).

Per run (truth and model, `gmr.transition_front` for `--t1` s, the load `gmr.HalfSineNodes` on
level 0's nodes): each truss's crossing time, the first time its deformation passes the saddle of
its law; the wave propagates when every truss has crossed and ends in the first well. Front speed,
levels per second: the inverse of the median spacing of the levels' crossing times over levels
1..levels-2 (the pulled level and the free end left out; the median, so that a dwell of the front
at its launch does not count). Threshold: the smallest pull amplitude that propagates, by
bisection to 1 % below the sweep's first propagating amplitude.

    python studies/transition_waves.py [--seeds 0 1 2] [--amps 1 2 ... 40] [--frac 0.02] [--coupler 2] [--out results/transition_waves.md]
"""

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

import gmr_jax as gmr

RESULTS = Path(__file__).resolve().parents[1] / "results"


def front(model, start, target, a, f, t1, levels):
    """`gmr.transition_front` of a pull of magnitude `a` towards the first well on level 0's nodes."""
    n = model.n_dof // 2
    load = gmr.HalfSineNodes(f, -a, (0, n), n_dof=model.n_dof)
    return gmr.transition_front(model, start, target, load, t1, levels)


def threshold(model, start, target, f, t1, levels, amps, answers):
    """Smallest pull amplitude that propagates: bisection to 1 % between the sweep's last pinned
    amplitude and its first propagating one (NaN: none propagates)."""
    first = next((i for i, ok in enumerate(answers) if ok), None)
    if first is None:
        return np.nan
    if first == 0:
        return amps[0]
    lo, hi = amps[first - 1], amps[first]
    while hi - lo > 0.01 * hi:
        mid = 0.5 * (lo + hi)
        ok = bool(front(model, start, target, mid, f, t1, levels).propagated)
        lo, hi = (lo, mid) if ok else (mid, hi)
    return hi


def run(system, seed, frac, amps, f, t1):
    truth, graph = system.truth, system.truth.topology
    n = graph.nodes // 2
    levels = np.full(graph.n_elements, -1)
    levels[: 2 * n] = np.tile(np.arange(n), 2)  # the grounding trusses, level = height on the rail
    wells_t = gmr.stable_wells(truth, system.x_range)
    span = float(np.nanmax(wells_t[0]) - np.nanmin(wells_t[0]))
    recs = gmr.systems.make_recordings(system, frac * span, snr_db=50.0, seed=seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = gmr.reconstruct(recs, topology=graph, designs=system.designs).value
    bist = np.nonzero(system.designs == 0)[0]
    law = max(gmr.metrics.restoring_error(model, truth, int(e), (wells_t[0, 0], wells_t[0, 1])) for e in bist)
    ends = {}
    for who, m in (("truth", truth), ("model", model)):
        w = gmr.stable_wells(m, system.x_range)
        two = np.sum(np.isfinite(w), axis=1) > 1
        ends[who] = (gmr.configuration(m, w, np.where(two, 1, 0)), gmr.configuration(m, w, np.zeros(len(w), int)))
    rows = []
    for a in amps:
        ft, fm = (front(m, *ends[who], a, f, t1, levels) for who, m in (("truth", truth), ("model", model)))
        rows.append({"A": a, "truth": ft, "model": fm})
    thr = tuple(threshold(m, *ends[who], f, t1, levels, amps, [bool(r[who].propagated) for r in rows])
                for who, m in (("truth", truth), ("model", model)))
    return {"seed": seed, "law": law, "rows": rows, "threshold": thr}


def figure(res, levels, path, shown=10.0):
    """Level reached and front speed against the pull amplitude (truth, model), and rail A's
    node displacements at the amplitude `shown`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    amps = np.array([r["A"] for r in res["rows"]])
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    for who, style in (("truth", "ko-"), ("model", "rx--")):
        axes[0].plot(amps, [int(r[who].reached) for r in res["rows"]], style, ms=5, label=who)
        axes[1].plot(amps, [float(r[who].speed) for r in res["rows"]], style, ms=5, label=who)
    axes[0].set(xlabel="pull amplitude A", ylabel="highest level switched", title="propagates or pinned")
    axes[1].set(xlabel="pull amplitude A", ylabel="front speed (levels/s)", title="front speed (where it propagates)")
    for ax in axes[:2]:
        ax.legend(fontsize=8)
    r = min(res["rows"], key=lambda r: abs(r["A"] - shown))
    for who, style in (("truth", "k-"), ("model", "r--")):
        ts, x = np.asarray(r[who].ts), np.asarray(r[who].x)
        for k in range(levels):
            axes[2].plot(ts, x[:, k] + 2.5 * k, style, lw=0.8, label=who if k == 0 else None)
    axes[2].set(xlabel="t (s)", ylabel="node displacement + 2.5 x level", title=f"rail A, A = {r['A']:g}")
    axes[2].legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--amps", type=float, nargs="+", default=[float(a) for a in range(1, 41)])
    ap.add_argument("--frac", type=float, default=0.02)
    ap.add_argument("--f", type=float, default=1.0)
    ap.add_argument("--t1", type=float, default=40.0)
    ap.add_argument("--coupler", type=float, default=1.8, help="rail couplers' and rungs' stiffness")
    ap.add_argument("--out", default=str(RESULTS / "transition_waves.md"))
    args = ap.parse_args()
    t_start = time.perf_counter()
    system = gmr.systems.grounded_ladder(coupler=args.coupler, rung=args.coupler)
    levels = system.truth.topology.nodes // 2
    results = []
    for seed in args.seeds:
        res = run(system, seed, args.frac, args.amps, args.f, args.t1)
        results.append(res)
        print(seed, res["law"], res["threshold"], [(r["A"], float(r["truth"].speed), float(r["model"].speed))
                                                   for r in res["rows"]], flush=True)
    fig_name = Path(args.out).with_suffix(".png").name
    figure(results[0], levels, RESULTS / "figures" / fig_name)
    rows = [(res, r) for res in results for r in res["rows"]]
    agree = sum(bool(r["truth"].propagated) == bool(r["model"].propagated) for _, r in rows)
    errs = [abs(float(r["model"].speed / r["truth"].speed) - 1) for _, r in rows
            if r["truth"].propagated and r["model"].propagated]
    thr = [res["threshold"][1] / res["threshold"][0] - 1 for res in results]
    amps_text = (f"{args.amps[0]:g} {args.amps[1]:g} ... {args.amps[-1]:g}" if len(args.amps) > 4
                 else " ".join(f"{a:g}" for a in args.amps))
    lines = [
        f"# Transition waves on the grounded 2 x 8 ladder (couplers and rungs {args.coupler:g}): model against truth",
        "",
        f"`python studies/transition_waves.py --seeds {' '.join(map(str, args.seeds))} --amps {amps_text} --frac "
        f"{args.frac:g} --coupler {args.coupler:g}` "
        f"({(time.perf_counter() - t_start) / 60:.1f} min on the 2-core dev machine; definitions in the module "
        "docstring). Per seed a model reconstructed from "
        f"{100 * args.frac:g} % vibrations at 50 dB (the system's four configurations); pull on level 0 (both rails), "
        f"half-sine at {args.f:g} Hz, from every truss in its second well, {args.t1:g} s. Figure: "
        f"`figures/{fig_name}` (seed {args.seeds[0]}).",
        "",
        f"- Propagate / pinned: the same answer on {agree} of {len(rows)} (seed, amplitude) pairs.",
        "- Front speed: model within " + (f"{100 * max(errs):.1f} % of the truth's (largest over the {len(errs)} "
                                          "pairs where both propagate; median "
                                          f"{100 * float(np.median(errs)):.2f} %)." if errs else "- (no pair where both propagate)."),
        "- Threshold amplitude (smallest pull that propagates): model / truth - 1 = "
        + ", ".join(f"{100 * t:+.1f} %" for t in thr) + " (seeds in order).",
        "",
        "| seed | truss law error (%) | threshold: truth | threshold: model | same answer | amplitudes that differ "
        "(truth's answer) | speed error: largest / median |",
        "|---|---|---|---|---|---|---|",
    ]
    for res in results:
        diff = [f"{r['A']:g} ({'propagates' if r['truth'].propagated else 'pinned'})" for r in res["rows"]
                if bool(r["truth"].propagated) != bool(r["model"].propagated)]
        e = [abs(float(r["model"].speed / r["truth"].speed) - 1) for r in res["rows"]
             if r["truth"].propagated and r["model"].propagated]
        lines.append(f"| {res['seed']} | {100 * res['law']:.2f} | {res['threshold'][0]:.3g} | {res['threshold'][1]:.3g} | "
                     f"{len(res['rows']) - len(diff)} / {len(res['rows'])} | {', '.join(diff) or '-'} | "
                     + (f"{100 * max(e):.2f} / {100 * float(np.median(e)):.2f} % |" if e else "- |"))
    lines += ["", f"Seed {args.seeds[0]} per amplitude (reached: the highest level whose trusses all crossed):", "",
              "| A | truth: propagates | reached | speed (levels/s) | model: propagates | reached | speed | speed error |",
              "|---|---|---|---|---|---|---|---|"]
    for r in results[0]["rows"]:
        pt, st, pm, sm = (bool(r["truth"].propagated), float(r["truth"].speed), bool(r["model"].propagated),
                          float(r["model"].speed))
        err = f"{100 * (sm / st - 1):+.2f} %" if pt and pm else "-"
        lines.append(f"| {r['A']:g} | {'yes' if pt else 'no'} | {int(r['truth'].reached)} | {st:.4g} | "
                     f"{'yes' if pm else 'no'} | {int(r['model'].reached)} | {sm:.4g} | {err} |")
    text = "\n".join(lines) + "\n"
    print(text)
    Path(args.out).write_text(text)


if __name__ == "__main__":
    main()
