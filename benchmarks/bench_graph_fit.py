"""Wall time of the graph fit against the number of elements: 2 x n ladders of bistable trusses with
linear rungs (`gmr.systems.ladder(n)`, 3 n elements, two designs), four configurations, 50 dB, 60 s
records at 50 Hz; `gmr.reconstruct(..., topology=graph, coordination="evidence", designs=...)`.

Per size: the first call (with compilation) and the median of `--repeat` warm calls; the growth
exponent is the slope of log(warm time) on log(elements). No peer tool fits a lattice's element laws
from small vibrations, so there is no ratio to report.

Run: python benchmarks/bench_graph_fit.py [--levels 3 5 11 21] [--repeat 3]
(writes results/bench_graph_fit.md)
"""

import argparse
import platform
import time
import warnings
from pathlib import Path

import numpy as np

import gmr_jax as gmr

RESULTS = Path(__file__).resolve().parents[1] / "results"


def fit(system, recs):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gmr.GMRDataWarning)
        t0 = time.perf_counter()
        gmr.reconstruct(recs, topology=system.truth.topology, coordination="evidence", designs=system.designs,
                        throw=False)
        return time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--levels", type=int, nargs="+", default=[3, 5, 11, 21])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rows = []
    for n in args.levels:
        system = gmr.systems.ladder(levels=n)
        span = np.ptp(system.x_range[0]) / 1.5
        recs = gmr.systems.make_recordings(system, 0.02 * span, snr_db=50.0, seed=0, duration=60.0)
        first = fit(system, recs)
        warm = float(np.median([fit(system, recs) for _ in range(args.repeat)]))
        rows.append((system.truth.topology.n_elements, system.truth.topology.nodes, first, warm))
        print(rows[-1], flush=True)
    e = np.array([r[0] for r in rows], float)
    w = np.array([r[3] for r in rows])
    slope = float(np.polyfit(np.log(e), np.log(w), 1)[0])
    lines = ["# Graph fit: wall time against the number of elements", "",
             f"Command: `python benchmarks/bench_graph_fit.py --levels {' '.join(map(str, args.levels))} "
             f"--repeat {args.repeat}`; {platform.processor() or platform.machine()}, "
             f"{__import__('os').cpu_count()} CPUs (shared with other work while it ran).", "",
             "| elements | nodes | first call (s, with compilation) | warm (s, median) |", "|---|---|---|---|"]
    lines += [f"| {a} | {b} | {c:.2f} | {d:.2f} |" for a, b, c, d in rows]
    lines += ["", f"Growth exponent of the warm time (slope of log time on log elements): {slope:.2f}."]
    (RESULTS / "bench_graph_fit.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
