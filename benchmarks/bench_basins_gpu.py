"""Basin-sweep throughput on an accelerator: the 5-cell chain of `bench_basins` at 1e4 .. 1e6
points, float64 and float32, compile apart from run, peak device memory, for the default path
(`batching="lanes"`: diffrax's `Tsit5.step` and `PIDController` driving a queue of points in
lanes) and plain `vmap(diffeqsolve)` on the same device (`batching="member"`: one `diffeqsolve`
per point, vmapped, every point of the grid in one chunk up to `--member-chunk`); the last
column is the lanes' points/s over vmap(diffeqsolve)'s at the same grid size, float64.

Runs on whatever `jax.devices()[0]` is (the numbers in the results index are from a GPU; on a
CPU the same script runs, slowly). Classification agreement is reported against the float64
lanes map of the same grid.

    python benchmarks/bench_basins_gpu.py                     # 1e4, 1e5, 1e6 points
    python benchmarks/bench_basins_gpu.py --points 10000      # a quick check

Writes results/bench_basins_gpu.md (or --out).
"""

import os

os.environ.setdefault("EQX_ON_ERROR", "nan")
os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")  # peak memory is what the sweep needs

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))  # this checkout's gmr_jax

import gmr_jax  # noqa: E402, F401  (enables float64 before jax is used)
import jax  # noqa: E402

import bench_basins as bb  # noqa: E402
from gmr_jax import SweepSettings, basin_map, stable_wells  # noqa: E402

SHAPES = {10_000: (100, 100), 100_000: (400, 250), 1_000_000: (1000, 1000)}


def grid(n, shift):
    nf, na = SHAPES[n]
    df = (bb.F_RANGE[1] - bb.F_RANGE[0]) / (nf - 1)
    da = (bb.A_RANGE[1] - bb.A_RANGE[0]) / (na - 1)
    return (np.linspace(bb.F_RANGE[0] + shift * df, bb.F_RANGE[1] - shift * df, nf),
            np.linspace(bb.A_RANGE[0] + shift * da, bb.A_RANGE[1] - shift * da, na))


def peak_bytes():
    stats = jax.devices()[0].memory_stats() or {}
    return stats.get("peak_bytes_in_use")


def run(model, wells, n, settings, chunk):
    f, a = grid(n, 0.0)
    t = time.perf_counter()
    basin_map(model, f, a, wells, settings=settings, chunk=chunk, throw=False)
    first = time.perf_counter() - t
    f, a = grid(n, 0.25)  # new values, same shapes: no compile
    t = time.perf_counter()
    sol = basin_map(model, f, a, wells, settings=settings, chunk=chunk, throw=False)
    jax.block_until_ready(sol.value.config)
    run_s = time.perf_counter() - t
    return first, run_s, sol


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, nargs="*", default=[10_000, 100_000, 1_000_000])
    ap.add_argument("--cells", type=int, default=5)
    ap.add_argument("--lanes", type=int, nargs="*", default=[None])
    ap.add_argument("--member-chunk", type=int, default=100_000)
    ap.add_argument("--member-max", type=int, default=100_000, help="largest grid for vmap(diffeqsolve)")
    ap.add_argument("--precisions", nargs="*", default=["float64", "float32"])
    ap.add_argument("--out", default=str(HERE.parent / "results" / "bench_basins_gpu.md"))
    args = ap.parse_args()
    model = bb.make_model(args.cells)
    wells = np.asarray(stable_wells(model, (-0.1, 0.1)))
    dev = jax.devices()[0]
    rows, maps = [], {}
    for n in args.points:
        for precision in args.precisions:
            for lanes in args.lanes:
                st = SweepSettings(batching="lanes", precision=precision)
                first, run_s, sol = run(model, wells, n, st, lanes)
                cfg = np.asarray(sol.value.config)
                ref = maps.setdefault(n, cfg)
                rows.append({"points": n, "method": f"lanes ({sol.stats['solver']})", "precision": precision,
                             "lanes": sol.stats["chunk"],
                             "compile_s": first - run_s, "run_s": run_s, "points_per_s": n / run_s,
                             "steps": float(np.mean(np.asarray(sol.value.steps))), "peak_bytes": peak_bytes(),
                             "agreement_vs_f64_lanes": float(np.mean(cfg == ref)), "counts": sol.stats["counts"]})
                print(json.dumps(rows[-1]), flush=True)
        if n <= args.member_max:
            st = SweepSettings(batching="member")
            first, run_s, sol = run(model, wells, n, st, min(n, args.member_chunk))
            cfg = np.asarray(sol.value.config)
            rows.append({"points": n, "method": "vmap(diffeqsolve)", "precision": "float64",
                         "lanes": sol.stats["chunk"], "compile_s": first - run_s, "run_s": run_s,
                         "points_per_s": n / run_s, "steps": float(np.mean(np.asarray(sol.value.steps))),
                         "peak_bytes": peak_bytes(), "agreement_vs_f64_lanes": float(np.mean(cfg == maps[n])),
                         "counts": sol.stats["counts"]})
            print(json.dumps(rows[-1]), flush=True)
            for r in rows:  # lanes over vmap(diffeqsolve), float64, same grid
                if r["points"] == n and r["method"].startswith("lanes") and r["precision"] == "float64":
                    r["vs_member"] = r["points_per_s"] / rows[-1]["points_per_s"]
    lines = ["# Basin sweeps on an accelerator", "",
             f"Command: `python benchmarks/bench_basins_gpu.py` on {dev.device_kind} ({dev.platform}), "
             f"jax {jax.__version__}, {time.strftime('%Y-%m-%d')}. {args.cells}-cell chain of `bench_basins`, "
             "tip half-sine, settle 10 s, rtol 1e-6 / atol 1e-8; run time = second call on new grid values "
             "(compile apart); steps = mean step attempts per point (for vmap(diffeqsolve): each member's "
             "own steps, but a chunk runs as long as its slowest member). Peak = the device allocator's peak "
             "since the start of the script (cumulative).", "",
             "| points | method | precision | lanes / chunk | compile s | run s | points/s | steps | peak GB | "
             "agreement vs float64 lanes | lanes / vmap(diffeqsolve) |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        pk = f"{r['peak_bytes'] / 1e9:.2f}" if r["peak_bytes"] else "n/a"
        lines.append(f"| {r['points']:.0e} | {r['method']} | {r['precision']} | {r['lanes']} | {r['compile_s']:.2f} | "
                     f"{r['run_s']:.3f} | {r['points_per_s']:.3g} | {r['steps']:.0f} | {pk} | "
                     f"{r['agreement_vs_f64_lanes'] * 100:.2f} % | "
                     + (f"{r['vs_member']:.2f}x |" if "vs_member" in r else "|"))
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("wrote", args.out)


if __name__ == "__main__":
    main()
