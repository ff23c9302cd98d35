"""`basin_probability` with the drawn models as data (one lanes sweep of models x grid points)
against the loop that sweeps one drawn model after another, same draws, one run.

The 3-cell chain of `bench_basins` (c = 1 N s/m) with a covariance of 1 % (standard deviation)
on every coefficient, 16 draws, a 50 x 50 (f, A) grid, settle 10 s, rtol 1e-6 / atol 1e-8, all
CPU cores. The loop is what `basin_probability` did before: per draw its wells, its passivity
check and one `basin_map` call, here with each batching ("native": the C kernel, the default
before the lanes ran on diffrax; "lanes"). Reported: wall time of each (best of `--reps`,
compile apart), the ratio, whether the probabilities agree (points where they differ lie next
to a basin boundary), and a loop's cost per `basin_map` call beyond the integration (a call on a
2 x 2 grid): the most that sweeping the draws as one batch can save.

    python benchmarks/bench_basins_probability.py            # ~2 min on 2 cores
"""

import os

os.environ.setdefault("EQX_ON_ERROR", "nan")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import gmr_jax as g  # noqa: E402

N_CORES = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
g.use_cpu_cores(N_CORES)

import jax  # noqa: E402

import bench_basins as bb  # noqa: E402


def model_with_covariance(n, rel=0.01):
    base = bb.make_model(n)
    terms = base.terms()
    cov = []
    for i in range(n):
        mine = [t for t in terms if t["dof"] == i]
        cov.append({"dof": i, "terms": [[t["physics"], t["order"]] for t in mine],
                    "matrix": np.diag([(rel * t["coefficient"]) ** 2 for t in mine]).tolist()})
    return g.from_terms([bb.MASS] * n, terms, "chain", covariance=cov)


def feeds_energy(model, wells, x_range, n=21):
    """True where the model's damping power F_d v is negative somewhere on the x_range x |v| <= 1 grid."""
    lo, hi = np.broadcast_to(np.asarray(x_range, float), (model.n_dof, 2)).T
    grid = np.linspace(lo, hi, n)  # (n, dof)
    for v in np.linspace(-1.0, 1.0, n):
        vv = np.full(grid.shape[1], v)
        power = np.asarray(jax.vmap(lambda x: model.damping(x, vv))(grid)) * v
        if np.any(power < -1e-12):
            return True
    return False


def loop(model, f, a, key, n, x_range, settings):
    """The per-draw loop: wells, passivity and one basin_map per draw (what basin_probability did)."""
    samples = g.sample_models(model, key, n)
    w0 = g.stable_wells(model, x_range)
    mean = g.basin_map(model, f, a, w0, settings=settings, throw=False)
    configs = []
    for k in range(n):
        m = jax.tree.map(lambda q, k=k: q[k] if hasattr(q, "shape") else q, samples)
        w = g.stable_wells(m, x_range)
        if w.shape != w0.shape or feeds_energy(m, np.asarray(w), x_range):
            continue
        configs.append(np.asarray(g.basin_map(m, f, a, w, settings=settings, throw=False).value.config))
    return np.asarray(mean.value.config), np.stack(configs)


def probabilities(stack, values):
    return np.stack([np.mean(stack == c, axis=0) for c in values], axis=-1)


def timed(fn, reps):
    t = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t
    runs = []
    for _ in range(reps):
        t = time.perf_counter()
        out = fn()
        runs.append(time.perf_counter() - t)
    return out, first - min(runs), min(runs)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, default=3)
    ap.add_argument("--draws", type=int, default=16)
    ap.add_argument("--grid", type=int, default=50)
    ap.add_argument("--reps", type=int, default=2)
    ap.add_argument("--loops", nargs="*", default=["native", "lanes"])
    args = ap.parse_args()
    model = model_with_covariance(args.cells)
    f = np.linspace(*bb.F_RANGE, args.grid)
    a = np.linspace(*bb.A_RANGE, args.grid)
    key = jax.random.key(0)
    x_range = (-0.1, 0.1)
    rows = {}
    sol, comp, run = timed(lambda: g.basin_probability(model, f, a, key, args.draws, x_range=x_range), args.reps)
    bp = sol.value
    rows["batched (lanes, models as data)"] = {"compile_s": comp, "run_s": run, "used": sol.stats["samples_used"]}
    print(json.dumps(rows), flush=True)
    for batching in args.loops:
        (mean, stack), comp, run = timed(lambda b=batching: loop(model, f, a, key, args.draws, x_range,
                                                                 g.SweepSettings(batching=b)), args.reps)
        values = np.asarray(bp.configs)
        prob = probabilities(stack, values)
        same = np.all(np.isclose(prob, np.asarray(bp.probability)), axis=-1)
        rows[f"loop ({batching})"] = {"compile_s": comp, "run_s": run, "used": int(stack.shape[0]),
                                      "batched_speedup": run / rows["batched (lanes, models as data)"]["run_s"],
                                      "points_same_probabilities": float(np.mean(same)),
                                      "mean_map_same": float(np.mean(mean == np.asarray(bp.mean_config))),
                                      "max_probability_difference":
                                          float(np.max(np.abs(prob - np.asarray(bp.probability))))}
        print(json.dumps(rows[f"loop ({batching})"]), flush=True)
    # what a loop pays per basin_map call beyond the integration: 17 calls on a 2 x 2 grid
    w = g.stable_wells(model, x_range)
    for batching in args.loops:
        st = g.SweepSettings(batching=batching)
        g.basin_map(model, f[:2], a[:2], w, settings=st)
        t = time.perf_counter()
        for _ in range(args.draws + 1):
            g.basin_map(model, f[:2], a[:2], w, settings=st)
        rows[f"loop ({batching})"]["call_overhead_s"] = (time.perf_counter() - t) / (args.draws + 1)
    print(json.dumps({"command": "python benchmarks/bench_basins_probability.py", "cores": N_CORES,
                      "jax": jax.__version__, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
