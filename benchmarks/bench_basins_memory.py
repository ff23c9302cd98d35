"""Memory of a basin sweep vs grid size: is it bounded for 1e5-1e6 points?

Each grid size runs in its own process (peak RSS only grows within a process) on the 5-cell
polynomial chain of `bench_basins.py`, with the default chunk and all CPU cores, once as one
call (`progress=None`) and once in blocks (`progress=...`, as `gmr basins` runs). Reports wall
time (compile included), peak resident memory of the process, and the part of it that is the
returned map itself (`BasinMap` arrays).

Run: python benchmarks/bench_basins_memory.py [--sizes 10000 100000 1000000]
Writes results/bench_basins_memory.md.
"""

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE.parent / "results"


def child(n_points: int, blocks: bool):
    os.environ.setdefault("EQX_ON_ERROR", "nan")
    import gmr_jax as g

    g.use_cpu_cores()
    import jax
    import numpy as np

    sys.path.insert(0, str(HERE))
    from bench_basins import A_RANGE, F_RANGE, SETTINGS, WELL, make_model

    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    model = make_model(5)
    wells = np.tile([-WELL, WELL], (5, 1))
    nf = int(round(np.sqrt(n_points)))
    f = np.linspace(*F_RANGE, nf)
    a = np.linspace(*A_RANGE, n_points // nf)
    t = time.perf_counter()
    bm = g.basin_map(model, f, a, wells, settings=SETTINGS, progress=(lambda d, n: None) if blocks else None).value
    jax.block_until_ready(bm)
    wall = time.perf_counter() - t
    out_mb = sum(np.asarray(x).nbytes for x in jax.tree.leaves(bm)) / 2**20
    conf = np.asarray(bm.config)
    print(json.dumps({"points": int(conf.size), "blocks": blocks, "wall_s": wall,
                      "rss_start_mb": rss0 / 1024, "rss_peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      "map_mb": out_mb, "unclassified": float(np.mean(conf < 0)), "devices": len(jax.devices())}))


def main():
    p = argparse.ArgumentParser(description="Memory of a basin sweep vs grid size")
    p.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    p.add_argument("--out", default=str(RESULTS / "bench_basins_memory.md"))
    p.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--blocks", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child is not None:
        child(args.child, args.blocks)
        return
    rows = []
    for n in args.sizes:
        for blocks in (False, True):
            cmd = [sys.executable, __file__, "--child", str(n)] + (["--blocks"] if blocks else [])
            out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout.strip().splitlines()[-1]
            rows.append(json.loads(out))
            print(rows[-1], flush=True)
    lines = [
        "# Basin sweep memory vs grid size", "",
        f"Command: `python benchmarks/bench_basins_memory.py --sizes {' '.join(map(str, args.sizes))}`. "
        "5-cell polynomial chain of `bench_basins.py` (Eq. 25 tip half-sine, settle 10 s, rtol 1e-6), "
        "default chunk (256 points), all CPU cores; each row a fresh process. 'one call': `basin_map(..., "
        "progress=None)`; 'blocks': with a progress callback (up to ~20 calls of one compiled function, "
        "as `gmr basins` runs). Peak RSS includes the Python/JAX runtime (the start value) and the "
        "returned map. Wall times are cold single calls on the shared 2-core dev machine: a memory "
        "measurement, not the speed benchmark (that is `bench_basins.md`, warm calls, side by side with "
        "scipy).", "",
        "| points | mode | wall incl. compile (s) | us/point | peak RSS (MB) | RSS at start (MB) | "
        "returned map (MB) | peak - start - map (MB) | unclassified |",
        "|---:|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        extra = r["rss_peak_mb"] - r["rss_start_mb"] - r["map_mb"]
        lines.append(f"| {r['points']:,} | {'blocks' if r['blocks'] else 'one call'} | {r['wall_s']:.1f} | "
                     f"{1e6 * r['wall_s'] / r['points']:.0f} | {r['rss_peak_mb']:.0f} | {r['rss_start_mb']:.0f} | "
                     f"{r['map_mb']:.0f} | {extra:.0f} | {r['unclassified']:.2%} |")
    per_point = [(b["rss_peak_mb"] - a["rss_peak_mb"]) * 1024 / (b["points"] - a["points"])
                 for a, b in zip(rows, rows[2:]) if b["points"] > a["points"]]
    if per_point:  # needs two sizes
        lines += ["", f"Growth of the peak per extra point: {min(per_point):.2f}-{max(per_point):.2f} kB (the "
                  "returned map is 0.14 kB per point; the rest is its transient copies on the way out: device "
                  "arrays, NumPy copies, the reordering to grid order). The integrator's working memory is per "
                  "chunk and does not grow with the grid."]
    lines += ["", f"Machine: {platform.machine()}, {os.cpu_count()} CPUs, {rows[0]['devices']} JAX devices."]
    text = "\n".join(lines) + "\n"
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
