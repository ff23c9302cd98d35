"""Work per point of the lanes sweep (diffrax's solver step per lane) with each Runge-Kutta pair.

Same chains, input and grid as `bench_basins_numba.py` (cells k1 x + k3 x^3 + c v, Eq. (25) tip
half-sine, settle 10 s, rtol 1e-6 / atol 1e-8, 100 x 100 (f, A) grid), `basin_map` with
`SweepSettings(batching="lanes", solver=...)` for Tsit5, Dopri5 and Dopri8 (DOP853's tableau).
Reported per chain: step attempts per point, vector-field evaluations per point (attempts x new
stages per step: Tsit5 6, Dopri5 6 with first-same-as-last, Dopri8 12), and the map's agreement
with Tsit5's. These counts do not depend on the machine or its load; the run time is printed too,
run only (a second call), meaningful on a quiet machine only.

    python benchmarks/bench_basins_solvers.py [--cells 3 5 10] [--n 100]

Writes results/bench_basins_solvers.md.
"""

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))  # this checkout's gmr_jax

import gmr_jax as g  # noqa: E402

g.use_cpu_cores()

import bench_basins as bb  # noqa: E402
from gmr_jax import SweepSettings, basin_map, stable_wells  # noqa: E402

#: vector-field evaluations per step attempt (new stages; FSAL pairs reuse the last one)
NEW_STAGES = {"tsit5": 6, "dopri5": 6, "dopri8": 12}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cells", type=int, nargs="*", default=[3, 5, 10])
    ap.add_argument("--dampings", type=float, nargs="*", default=[1.0, 0.3])
    ap.add_argument("--n", type=int, default=100, help="grid points per axis")
    ap.add_argument("--out", default=str(HERE.parent / "results" / "bench_basins_solvers.md"))
    args = ap.parse_args()
    f = np.linspace(*bb.F_RANGE, args.n)
    a = np.linspace(*bb.A_RANGE, args.n)
    rows = []
    for n in args.cells:
        for c in args.dampings:
            bb.DAMPING = c
            model = bb.make_model(n)
            wells = np.asarray(stable_wells(model, (-0.1, 0.1)))
            ref = None
            for solver in ("tsit5", "dopri5", "dopri8"):
                s = SweepSettings(batching="lanes", solver=solver)
                basin_map(model, f, a, wells, settings=s, throw=False)  # compile (and a first run)
                t = time.perf_counter()
                bm = basin_map(model, f * (1 + 1e-9), a, wells, settings=s, throw=False).value
                wall = time.perf_counter() - t  # run only: a second call on new grid values
                cfg = np.asarray(bm.config)
                ref = cfg if ref is None else ref
                steps = float(np.mean(np.asarray(bm.steps)))
                rows.append((n, c, solver, steps, steps * NEW_STAGES[solver], float(np.mean(cfg == ref)), wall))
                print(rows[-1], flush=True)
    lines = [
        "# Lanes sweep: work per point with each Runge-Kutta pair",
        "",
        f"Command: `python benchmarks/bench_basins_solvers.py --n {args.n}` ({os.cpu_count()} CPUs). Chains, "
        "input and tolerances of `bench_basins_numba.py` (rtol 1e-6, atol 1e-8, settle 10 s), "
        f"{args.n} x {args.n} grid. Steps: attempts per point (accepted + rejected); evaluations: attempts x "
        "new stages per step (Tsit5 6, Dopri5 6, Dopri8 12). Machine-independent counts; the wall time "
        "(second call, run only, all cores) means something only on a quiet machine.",
        "",
        "| cells | c (N s/m) | pair | steps/point | evaluations/point | vs Tsit5 evaluations | map = Tsit5's | run s |",
        "|---:|---:|---|---:|---:|---:|---:|---:|",
    ]
    base = {}
    for n, c, solver, steps, evals, agree, wall in rows:
        base.setdefault((n, c), evals)
        lines.append(f"| {n} | {c:g} | {solver} | {steps:.0f} | {evals:.0f} | {evals / base[(n, c)]:.2f}x | "
                     f"{100 * agree:.2f} % | {wall:.2f} |")
    lines.append("")
    Path(args.out).write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
