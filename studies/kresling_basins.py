"""Deployment basins of the 5-cell Kresling chain: reconstructed models vs the truth on one
(f, A) grid (paper Fig. 11; the basin issue's agreement check).

For each seed, GMR (and, for the first seed, GMC-SINDy(5,5)) is reconstructed from 60 dB base
sweeps in the folded and deployed configurations only, and its basin map under the Eq. (25)
tip half-sine is compared with the truth's on the same grid. Alongside:

- the *predictability* of the truth's map: the truth with every stiffness changed by +-0.1 %
  and +1 % (an identification error far below / at what small vibrations can promise). Points
  where truth, truth +0.1 % and truth -0.1 % agree are the "predictable" points; agreement is
  also reported on those alone;
- where the disagreements lie: Chebyshev distance (grid cells) to the nearest point of another
  configuration in the truth's map, beside the same distance for every grid point (on a finely
  striped map every point is near a boundary, which makes "near a boundary" say nothing).

Default chain: `kresling5(damping_ratio=KRESLING5_DEPLOYMENT_DAMPING)` (0.2) trained at
`KRESLING5_DEPLOYMENT_AMPLITUDE` (0.5 mm: 5 % of the interwell distance at the base cell);
`--zeta 0.04 --amp 3e-4 --settle 40` runs the lightly damped built-in chain.

Run: python studies/kresling_basins.py [--n 100] [--seeds 0 1 2] [--zeta 0.2] [--amp 5e-4]
Writes results/kresling_basins_z<zeta>.md and results/figures/kresling_basins_z<zeta>_*.png.
"""

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("EQX_ON_ERROR", "nan")

import gmr_jax as g  # noqa: E402

g.use_cpu_cores()  # all cores as JAX CPU devices: the sweeps are sharded over them

import equinox as eqx  # noqa: E402
import jax  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from scipy import ndimage  # noqa: E402

from gmr_jax.plots import basin_figure, config_label  # noqa: E402
from gmr_jax.systems import KRESLING5_DEPLOYMENT_AMPLITUDE, KRESLING5_DEPLOYMENT_DAMPING  # noqa: E402

RESULTS = Path(__file__).resolve().parents[1] / "results"
FIGURES = RESULTS / "figures"


def boundary_distance(config: np.ndarray) -> np.ndarray:
    """Chebyshev distance (grid cells) from each point to the nearest point of another
    configuration (grid edges do not count as boundaries)."""
    dist = np.full(config.shape, np.inf)
    c = config.astype(float)
    for r in range(1, max(config.shape)):
        size = 2 * r + 1
        lo = ndimage.minimum_filter(c, size=size, mode="nearest")
        hi = ndimage.maximum_filter(c, size=size, mode="nearest")
        new = (lo != hi) & np.isinf(dist)
        dist[new] = r
        if np.all(np.isfinite(dist)):
            break
    return dist


def scaled_stiffness(chain, factor):
    c = chain.cells
    return eqx.tree_at(lambda ch: ch.cells, chain,
                       eqx.tree_at(lambda c: (c.k_a, c.k_b), c, (c.k_a * factor, c.k_b * factor)))


def sweep(model, system, f, A, settings):
    wells = g.stable_wells(model, system.x_range)
    t0 = time.perf_counter()
    conf = np.asarray(g.basin_map(model, f, A, wells, settings=settings).value.config)
    return conf, time.perf_counter() - t0


def distance_summary(dist, mask):
    d = dist[mask]
    if d.size == 0:
        return "none"
    return (f"median {np.median(d):.0f}, {np.mean(d <= 1):.0%} within 1 cell, {np.mean(d <= 3):.0%} within 3, "
            f"max {d.max():.0f}")


def difference_figure(f, A, truth, model, path, title):
    fig, ax = plt.subplots(figsize=(7, 4.6), constrained_layout=True)
    edge = boundary_distance(truth) <= 1
    img = np.where(truth != model, 2, np.where(edge, 1, 0))
    cmap = matplotlib.colors.ListedColormap(["white", "0.8", "crimson"])
    ax.pcolormesh(f, A, img, cmap=cmap, vmin=-0.5, vmax=2.5, shading="auto")
    ax.legend([plt.Rectangle((0, 0), 1, 1, color=c) for c in ("0.8", "crimson")],
              ["truth basin boundary (1 cell)", "model != truth"], loc="upper right", fontsize=8)
    ax.set_xlabel("actuation frequency f [Hz]")
    ax.set_ylabel("actuation amplitude A [N]")
    ax.set_title(title, fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    p = argparse.ArgumentParser(description="Deployment basins of the 5-cell Kresling chain: models vs truth")
    p.add_argument("--n", type=int, default=100)
    p.add_argument("--zeta", type=float, default=KRESLING5_DEPLOYMENT_DAMPING)
    p.add_argument("--amp", type=float, default=KRESLING5_DEPLOYMENT_AMPLITUDE, help="training base amplitude (m)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    p.add_argument("--fmax", type=float, default=5.0)
    p.add_argument("--amax", type=float, default=1.0)
    p.add_argument("--settle", type=float, default=20.0)
    p.add_argument("--model", default=None, help="also compare this gmr-model/1 file (e.g. results/data/model_gmr_kresling5_refined.json, "
                   "written by studies/refine_kresling.py)")
    p.add_argument("--refine", action="store_true",
                   help="also refine each seed's GMR model on five 6 s deployment runs of the truth (Eq. 25 "
                   "from all folded, 60 dB; the points of refine_kresling.py) plus two 10 s sweeps, and compare it")
    args = p.parse_args()
    cmd = " ".join(["python studies/kresling_basins.py"] + sys.argv[1:])
    t_start = time.perf_counter()
    system = g.systems.kresling5(damping_ratio=args.zeta)
    tag = f"z{args.zeta:g}"
    f = np.linspace(0.1, args.fmax, args.n)
    A = np.linspace(0.02, args.amax, args.n)
    settings = g.SweepSettings(settle_time=args.settle)
    truth, t_truth = sweep(system.truth, system, f, A, settings)
    print(f"truth: {t_truth:.0f} s, {len(np.unique(truth))} configurations, unsettled {np.mean(truth < 0):.2%}",
          flush=True)
    ref = {}
    for name, factor in (("+0.1 %", 1.001), ("-0.1 %", 0.999), ("+1 %", 1.01)):
        ref[name], _ = sweep(scaled_stiffness(system.truth, factor), system, f, A, settings)
        print(f"  truth, stiffness {name}: {np.mean(ref[name] == truth):.2%}", flush=True)
    predictable = (ref["+0.1 %"] == truth) & (ref["-0.1 %"] == truth)
    dist = boundary_distance(truth)

    rows, first = [], {}
    models = []
    for seed in args.seeds:
        recs = g.systems.make_recordings(system, args.amp, snr_db=60.0, seed=seed)
        t0 = time.perf_counter()
        gmr = g.reconstruct(recs, g.Library(5, 5), designs=system.designs).value
        t_fit = time.perf_counter() - t0
        models.append((f"GMR, seed {seed}", gmr, t_fit, recs))
        if args.refine:
            from refine_kresling import DEPLOY_DURATION, DEPLOY_TRAIN, deployment

            train = [deployment(system.truth, fk, ak, DEPLOY_DURATION, seed=100 * seed + 10 + k)
                     for k, (fk, ak) in enumerate(DEPLOY_TRAIN)]
            train += g.systems.make_recordings(system, args.amp, seed=1000 + seed, duration=10.0)
            t0 = time.perf_counter()
            sol = g.refine(gmr, train, settings=g.RefineSettings(window=1.0, stride=10, max_windows=6,
                                                                 max_iterations=60), throw=False)
            ok = g.RESULTS[sol.result] or "successful"
            print(f"  refined seed {seed}: {ok}, {time.perf_counter() - t0:.0f} s", flush=True)
            models.append((f"GMR refined on {len(DEPLOY_TRAIN)} deployment runs ({ok}), seed {seed}", sol.value,
                           None, None))
        if seed == args.seeds[0]:
            models.append((f"GMC-SINDy(5,5), seed {seed}", g.gmc_sindy(recs, g.Library(5, 5)).value, None, recs))
    if args.model:
        models.append((f"{Path(args.model).name}", g.load_model(args.model), None, None))
    for name, model, t_fit, _ in models:
        conf, t_map = sweep(model, system, f, A, settings)
        agree = float(np.mean(conf == truth))
        rest = [100 * g.metrics.restoring_error(model, system.truth, i, system.x_range[i]) for i in range(5)]
        damp = [100 * g.metrics.damping_error(model, system.truth, i, system.x_range[i], system.v_range[i])
                for i in range(5)]
        row = {"name": name, "agree": agree, "agree_pred": float(np.mean(conf[predictable] == truth[predictable])),
               "dist": distance_summary(dist, conf != truth), "n_dis": int(np.sum(conf != truth)),
               "unsettled": float(np.mean(conf < 0)), "rest": rest, "damp": damp, "t_map": t_map}
        rows.append(row)
        print(f"{name}: agreement {agree:.2%} (predictable points {row['agree_pred']:.2%}), map {t_map:.0f} s; "
              f"disagreements {row['n_dis']}: {row['dist']}; restoring % "
              + ", ".join(f"{e:.2f}" for e in rest), flush=True)
        if not first and name.startswith("GMR, "):
            first = {"name": name, "conf": conf}

    FIGURES.mkdir(parents=True, exist_ok=True)
    basin_figure(f, A, truth, 5, FIGURES / f"kresling_basins_{tag}_truth.png",
                 title=f"5-cell Kresling chain (damping ratio {args.zeta:g}), truth")
    basin_figure(f, A, first["conf"], 5, FIGURES / f"kresling_basins_{tag}_gmr.png",
                 title=f"5-cell Kresling chain (damping ratio {args.zeta:g}), {first['name']}")
    difference_figure(f, A, truth, first["conf"], FIGURES / f"kresling_basins_{tag}_difference.png",
                      f"{first['name']} vs truth: {np.mean(first['conf'] == truth):.1%} agree")

    gmr_rows = [r for r in rows if r["name"].startswith("GMR, ")]
    ref_rows = [r for r in rows if r["name"].startswith("GMR refined")]
    lines = [
        f"# Kresling 5-cell deployment basins (damping ratio {args.zeta:g}): reconstructed models vs truth", "",
        f"Command: `{cmd}` ({time.perf_counter() - t_start:.0f} s on {len(jax.devices())} CPU devices). "
        f"Grid {args.n} x {args.n}: f in [0.1, {args.fmax:g}] Hz, A in [0.02, {args.amax:g}] N; tip half-sine "
        f"(Eq. 25) from all folded, settle {args.settle:g} s, `basin_map` defaults (rtol 1e-6, joint batching). "
        f"Models from {args.amp * 1e3:g} mm base sweeps (0.5-10 Hz, 30 s, 60 dB) in the folded and deployed "
        "configurations only; GMR `reconstruct(recs, Library(5, 5))` with the defaults.", "",
        "## Agreement with the truth's map", "",
        "| model | agreement | on predictable points | disagreements: distance to a truth boundary (cells) | "
        "unsettled | restoring error per cell (%) | damping error per cell (%) |",
        "|---|---:|---:|---|---:|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['name']} | **{r['agree']:.2%}** | {r['agree_pred']:.2%} | {r['dist']} | "
                     f"{r['unsettled']:.2%} | " + ", ".join(f"{e:.2f}" for e in r["rest"]) + " | "
                     + ", ".join(f"{e:.2f}" for e in r["damp"]) + " |")
    ag = np.array([r["agree"] for r in gmr_rows])
    lines += [
        "",
        f"GMR over {len(ag)} seed(s): agreement min {ag.min():.2%}, median {np.median(ag):.2%}, max {ag.max():.2%}."
        + (f" Refined: min {min(r['agree'] for r in ref_rows):.2%}, max {max(r['agree'] for r in ref_rows):.2%}."
           if ref_rows else ""),
        "",
        "## How predictable is the truth's map?", "",
        "| truth compared with | agreement |", "|---|---:|",
    ]
    lines += [f"| truth, every stiffness {k} | {np.mean(v == truth):.2%} |" for k, v in ref.items()]
    lines += [
        "",
        f"Predictable points (truth = truth +-0.1 % stiffness): {np.mean(predictable):.1%} of the grid. "
        f"Every grid point's distance to a truth boundary: {distance_summary(dist, np.ones_like(truth, bool))}.",
        "",
        f"Configurations in the truth map ({len(np.unique(truth))}): "
        + ", ".join(f"{config_label(int(c), 5)} ({np.sum(truth == c)})" for c in np.unique(truth)),
        "",
        f"Figures: [truth](figures/kresling_basins_{tag}_truth.png), "
        f"[GMR](figures/kresling_basins_{tag}_gmr.png) ({first['name']}), "
        f"[difference](figures/kresling_basins_{tag}_difference.png). Sweep time per map: truth {t_truth:.0f} s, GMR "
        f"{np.median([r['t_map'] for r in gmr_rows]):.0f} s.",
    ]
    text = "\n".join(lines) + "\n"
    (RESULTS / f"kresling_basins_{tag}.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
