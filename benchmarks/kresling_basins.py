"""Deployment basins of the 5-cell Kresling chain: reconstructed GMR model vs the truth system
on the same (f, A) grid (paper Fig. 11; issue 4's agreement check).

Run: python benchmarks/kresling_basins.py [--n 100]   (writes benchmarks/results_kresling_basins.md
and benchmarks/kresling_basins.png)
"""

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("EQX_ON_ERROR", "nan")

import numpy as np  # noqa: E402

import gmr_jax as g  # noqa: E402
from gmr_jax.plots._basins import basin_figure, config_label  # noqa: E402
from gmr_jax.systems._kresling import KRESLING5_AMPLITUDE  # noqa: E402


def boundary_distance(config):
    """Chebyshev distance (grid cells) from each cell to the nearest cell of another configuration."""
    na, nf = config.shape
    dist = np.full(config.shape, np.inf)
    for i in range(na):
        for j in range(nf):
            for r in range(1, max(na, nf)):
                win = config[max(0, i - r):i + r + 1, max(0, j - r):j + r + 1]
                if np.any(win != config[i, j]):
                    dist[i, j] = r
                    break
    return dist


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--n", type=int, default=100)
    p.add_argument("--fmax", type=float, default=5.0)
    p.add_argument("--amax", type=float, default=2.0)
    p.add_argument("--settle", type=float, default=40.0)
    p.add_argument("--model", default=None, help="compare this gmr-model/1 file instead of the GMR model "
                   "reconstructed here (e.g. benchmarks/model_gmr_kresling5_refined.json from refine_kresling.py)")
    args = p.parse_args()
    s = g.kresling5()
    if args.model:
        model = g.load_model(args.model)
        tag = "_" + Path(args.model).stem
    else:
        tag = ""
        recs = g.make_recordings(s, KRESLING5_AMPLITUDE, snr_db=60.0, seed=0)
        model = g.reconstruct(recs, g.Library(5, 5)).model
    f = np.linspace(0.1, args.fmax, args.n)
    A = np.linspace(0.02, args.amax, args.n)
    maps = {}
    for name, m in (("truth", s.truth), ("GMR model", model)):
        wells = g.stable_wells(m, s.x_range)
        t0 = time.perf_counter()
        bm = g.basin_map(m, f, A, wells, settings=g.SweepSettings(settle_time=args.settle))
        conf = np.asarray(bm.config)
        maps[name] = conf
        print(f"{name}: {time.perf_counter() - t0:.1f} s, wells {np.round(wells * 1e3, 2).tolist()} mm, "
              f"{len(np.unique(conf))} configurations, unsettled {np.mean(conf < 0):.2%}")
        basin_figure(f, A, conf, 5, Path(__file__).with_name(f"kresling_basins_{name.split()[0].lower()}{tag if name != 'truth' else ''}.png"),
                     title=f"5-cell Kresling chain, {name}")
    np.savez(Path(__file__).with_name(f"kresling_basins{tag}.npz"), f=f, A=A, truth=maps["truth"], model=maps["GMR model"])
    t, mdl = maps["truth"], maps["GMR model"]
    agree = np.mean(t == mdl)
    dist = boundary_distance(t)
    dis = dist[t != mdl]
    lines = [
        "# Kresling 5-cell deployment basins: GMR model vs truth",
        "",
        f"Command: `python benchmarks/kresling_basins.py --n {args.n} --fmax {args.fmax} --amax {args.amax} --settle {args.settle:g}"
        f"{' --model ' + args.model if args.model else ''}`. Grid {args.n} x {args.n}: f in "
        f"[0.1, {args.fmax}] Hz, A in [0.02, {args.amax}] N, tip half-sine (Eq. 25), start all folded, "
        f"settle {args.settle:g} s. " + (f"Model: {args.model}. " if args.model else "GMR model from 0.3 mm base sweeps (60 dB, seed 0) in the folded and deployed "
                                                       "configurations only."),
        "",
        f"- agreement: **{agree:.2%}** of {t.size} grid points",
        f"- disagreements: {int(np.sum(t != mdl))}; distance to the truth map's nearest basin boundary "
        f"(grid cells): " + (f"median {np.median(dis):.0f}, 90th percentile {np.percentile(dis, 90):.0f}, "
                             f"max {dis.max():.0f}" if dis.size else "none"),
        f"- configurations in the truth map: "
        + ", ".join(f"{config_label(int(c), 5)} ({np.sum(t == c)})" for c in np.unique(t)),
        "",
    ]
    text = "\n".join(lines)
    Path(__file__).with_name(f"results_kresling_basins{tag}.md").write_text(text + "\n")
    print(text)


if __name__ == "__main__":
    main()
