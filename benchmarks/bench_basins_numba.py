"""`basin_map` against a hand-written numba Dormand-Prince sweep, same grids, one run.

The peer (`numba_peer.py`): scalar DOPRI5 with FSAL and an integral controller, stop and restart
at the switch-off time, the right-hand side generated from the model with every coefficient a
literal, `prange` over the points (all cores). gmr_jax: `basin_map` with each batching
("lanes", the default: diffrax's `Tsit5.step` and `PIDController` per point in lanes fed from a
queue; "native": the opt-in C kernel generated from the model; "joint", with `--batchings`: one
step size per chunk), all CPU cores (threads for native, JAX devices for the others). Both integrate the same chain (`bench_basins`'s: cells
k1 x + k3 x^3 + c v, wells at +-3 cm, graded stiffness, 50 g masses) under the Eq. (25) tip
half-sine, settle 10 s, rtol 1e-6 / atol 1e-8, over a 100 x 100 (f, A) grid (f 0.1-5 Hz,
A 0.02-0.6 N), and their final states go through the same classification (`basin_map`'s).

Reported per chain (3, 5, 10 cells) and damping (c = 1.0 and a lightly damped 0.3 N s/m):
compile time (first call minus run), run time (best of `--reps` rounds on new grid values, each
round running every method in turn so that a shared machine's load falls on all alike),
steps per point (attempts, accepted and rejected), cost per trajectory-step per core
(run time x cores / total steps), the ratio to numba's run time and the classification
agreement. The end-to-end part times `gmr basins` in fresh processes (cold: empty compilation
cache; warm: the second process, cache filled) against the numba script end to end.

    python benchmarks/bench_basins_numba.py              # ~5 min on 2 cores
    python benchmarks/bench_basins_numba.py --quick      # 3 cells only, 40 x 25 grid
    taskset -c 0,1 python benchmarks/bench_basins_numba.py   # 2 pinned cores of a larger machine

Needs numba (`pip install -e ".[bench]"`); writes results/bench_basins_numba.md.
"""

import os

os.environ.setdefault("EQX_ON_ERROR", "nan")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))  # this checkout's gmr_jax

import gmr_jax as g  # noqa: E402

# a fresh cache folder: the native kernel's C compile and XLA's compile are both measured cold
os.environ["GMR_CACHE_DIR"] = tempfile.mkdtemp(prefix="gmr_bench_cache_")

N_CORES = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
g.use_cpu_cores(N_CORES)
os.environ.setdefault("NUMBA_NUM_THREADS", str(N_CORES))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numba  # noqa: E402

import bench_basins as bb  # noqa: E402
import numba_peer  # noqa: E402
from gmr_jax import SweepSettings, basin_map, stable_wells  # noqa: E402

RESULTS = HERE.parent / "results"
PEER_CODES = {0: "successful", 1: "diverged", 2: "max_steps_reached", 3: "simulation_failed"}


def chain(n, damping):
    bb.DAMPING = damping
    model = bb.make_model(n)
    wells = np.asarray(stable_wells(model, (-0.1, 0.1)))
    return model, wells


def grid(nf, na, shift):
    df = (bb.F_RANGE[1] - bb.F_RANGE[0]) / (nf - 1)
    da = (bb.A_RANGE[1] - bb.A_RANGE[0]) / (na - 1)
    f = np.linspace(bb.F_RANGE[0] + shift * df, bb.F_RANGE[1] - shift * df, nf)
    a = np.linspace(bb.A_RANGE[0] + shift * da, bb.A_RANGE[1] - shift * da, na)
    return f, a


def peer_sweep(model, wells, settings):
    span = np.nanmax(wells, 1) - np.nanmin(wells, 1)
    centre = 0.5 * (np.nanmax(wells, 1) + np.nanmin(wells, 1))
    box = settings.box_spans * span
    return numba_peer.build(model, settings.settle_time, settings.integrator.rtol, settings.integrator.atol,
                            settings.integrator.max_steps, centre - box, centre + box)


def peer_configs(out, wells, settings):
    x1, v1, code, steps = out
    w = jnp.asarray(wells)
    span = jnp.nanmax(w, 1) - jnp.nanmin(w, 1)
    value = {k: getattr(g.RESULTS, name)._value for k, name in PEER_CODES.items()}
    codes = np.asarray([value[int(c)] for c in code])
    _, cfg, _ = jax.vmap(lambda x, v, c: bb.classify(x, v, c, w, span, settings))(
        jnp.asarray(x1), jnp.asarray(v1), jnp.asarray(codes))
    return np.asarray(cfg)


def peer_runner(model, wells, settings):
    sweep = peer_sweep(model, wells, settings)
    x0 = wells[:, 0].copy()

    def run(f, a):
        ff, aa = np.meshgrid(f, a)
        return sweep(ff.ravel(), aa.ravel(), x0)

    return run


def gmr_runner(model, wells, settings, chunk=None):
    return lambda f, a: basin_map(model, f, a, wells, settings=settings, chunk=chunk, throw=False)


def time_interleaved(runners, nf, na, reps):
    """Each runner's first call (compile included) on one grid, then `reps` rounds in which every
    runner sweeps the same new grid in turn: the load of a shared machine falls on all of them
    alike. Per runner: first call, best run and the output of the last round."""
    f, a = grid(nf, na, 0.0)
    out = {}
    for name, run in runners.items():
        t = time.perf_counter()
        run(f, a)
        out[name] = {"first": time.perf_counter() - t, "run": np.inf}
    for r in range(reps):
        f, a = grid(nf, na, 0.1 * (r + 1))
        for name, run in runners.items():
            t = time.perf_counter()
            res = run(f, a)
            out[name]["run"] = min(out[name]["run"], time.perf_counter() - t)
            out[name]["out"] = res
    return out


def row(name, r, steps, n_points, peer_run=None):
    cost = r["run"] * N_CORES / (n_points * steps) * 1e9
    out = {"method": name, "compile_s": r["first"] - r["run"], "run_s": r["run"], "steps": steps,
           "ns_per_step_core": cost}
    if peer_run is not None:
        out["ratio_to_numba"] = r["run"] / peer_run
    return out


def end_to_end(n, damping, nf, na, settings):
    """`gmr basins` twice in fresh processes (cold, then warm from the persistent compilation
    cache) and the numba script end to end (import, compile, run), in fresh processes."""
    model, wells = chain(n, damping)
    tmp = Path(tempfile.mkdtemp(prefix="gmr_e2e_"))
    path = tmp / "model.json"
    g.save_model(model, path)
    f, a = grid(nf, na, 0.0)
    env = dict(os.environ, GMR_CACHE_DIR=str(tmp / "cache"), PYTHONPATH=str(HERE.parent))
    cmd = [sys.executable, "-m", "gmr_jax", "basins", str(path), "--f", f"{f[0]}:{f[-1]}:{nf}",
           "--A", f"{a[0]}:{a[-1]}:{na}", "--out", str(tmp / "map.json")]
    times = {}
    for label in ("cold", "warm", "warm2"):
        t = time.perf_counter()
        p = subprocess.run(cmd, env=env, capture_output=True, text=True)
        times[label] = time.perf_counter() - t
        if p.returncode != 0:
            raise RuntimeError(f"gmr basins failed: {p.stderr[-2000:]}")
    script = (f"import sys; sys.path.insert(0, {str(HERE)!r}); import time, numpy as np; "
              f"import gmr_jax as g, bench_basins_numba as b; "
              f"m, w = b.chain({n}, {damping}); s = b.peer_sweep(m, w, b.SweepSettings()); "
              f"f, a = b.grid({nf}, {na}, 0.0); ff, aa = np.meshgrid(f, a); "
              f"s(ff.ravel(), aa.ravel(), w[:, 0].copy())")
    t = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True)
    times["numba_script"] = time.perf_counter() - t
    if p.returncode != 0:
        raise RuntimeError(f"numba script failed: {p.stderr[-2000:]}")
    return times


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--cells", type=int, nargs="*", default=None)
    ap.add_argument("--dampings", type=float, nargs="*", default=[1.0, 0.3])
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--batchings", nargs="*", default=["lanes", "native"])
    ap.add_argument("--lanes", type=int, nargs="*", default=[None],
                    help="lane counts to try for the lanes batching (default: basin_map's own)")
    ap.add_argument("--unrolls", type=int, nargs="*", default=[None],
                    help="step attempts per loop pass to try (default: the library's)")
    ap.add_argument("--no-e2e", action="store_true")
    ap.add_argument("--out", default=str(RESULTS / "bench_basins_numba.md"))
    args = ap.parse_args()
    cells = args.cells or ([3] if args.quick else [3, 5, 10])
    nf, na = (40, 25) if args.quick else (100, 100)
    n_points = nf * na
    settings = SweepSettings()
    rows = []
    for damping in args.dampings:
        for n in cells:
            model, wells = chain(n, damping)
            variants = [(b, lanes, u) for b in args.batchings
                        for lanes in (args.lanes if b == "lanes" else [None])
                        for u in (args.unrolls if b == "lanes" else [None])]
            runners = {"peer": peer_runner(model, wells, settings)}
            for v in variants:
                batching, lanes, unroll = v
                st = SweepSettings(batching=batching, **({} if unroll is None else {"attempts_per_pass": unroll}))
                runners[v] = gmr_runner(model, wells, st, chunk=lanes)
            timed = time_interleaved(runners, nf, na, args.reps)
            peer = timed["peer"]
            peer_steps = float(np.mean(peer["out"][3]))
            cfg_peer = peer_configs(peer["out"], wells, settings)
            entry = {"cells": n, "damping": damping, "points": n_points,
                     "methods": [row("numba DOPRI5", peer, peer_steps, n_points)]}
            for v in variants:
                batching, lanes, unroll = v
                r = timed[v]
                bm, stats = r["out"].value, r["out"].stats
                steps = float(np.mean(np.asarray(bm.steps)))
                assert stats["batching"] == batching, stats
                label = (f"basin_map ({'default: diffrax ' + stats['solver'] + ' ' if batching == 'lanes' else ''}"
                         f"{batching}" + (f", {stats['chunk']} lanes" if batching in ("lanes", "native") else ""))
                label += (f", {unroll} attempts/pass" if unroll is not None else "") + ")"
                m = row(label, r, steps, n_points, peer["run"])
                m["agreement"] = float(np.mean(np.asarray(bm.config).ravel() == cfg_peer))
                m["chunk"] = stats["chunk"]
                entry["methods"].append(m)
            rows.append(entry)
            print(json.dumps(entry), flush=True)
    e2e = None
    if not args.no_e2e:
        e2e = end_to_end(cells[0], args.dampings[0], nf, na, settings)
        print(json.dumps(e2e), flush=True)
    write(args, rows, e2e, nf, na)


def write(args, rows, e2e, nf, na):
    lines = ["# Basin sweeps: gmr_jax `basin_map` vs a hand-written numba DOPRI5", "",
             f"Command: `python benchmarks/bench_basins_numba.py{' --quick' if args.quick else ''}`"
             f" ({platform.processor() or platform.machine()}, {N_CORES} cores visible, "
             f"jax {jax.__version__}, numba {numba.__version__}, {time.strftime('%Y-%m-%d')}).", "",
             f"Grid {nf} x {na} (f {bb.F_RANGE[0]}-{bb.F_RANGE[1]} Hz, A {bb.A_RANGE[0]}-{bb.A_RANGE[1]} N), "
             "tip half-sine, settle 10 s, rtol 1e-6 / atol 1e-8. Run time: best of "
             f"{args.reps} rounds on new grid values, every method in turn in each round (compile apart). Cost: run time x cores / (points x steps).",
             "", "| cells | c (N s/m) | method | compile s | run s | steps/point | ns/step/core | run / numba | agreement |",
             "|---|---|---|---|---|---|---|---|---|"]
    for e in rows:
        for m in e["methods"]:
            lines.append(f"| {e['cells']} | {e['damping']} | {m['method']} | {m['compile_s']:.2f} | {m['run_s']:.3f} | "
                         f"{m['steps']:.0f} | {m['ns_per_step_core']:.0f} | "
                         f"{m.get('ratio_to_numba', 1.0):.2f} | {m.get('agreement', 1.0) * 100:.2f} % |")
    if e2e:
        lines += ["", "End to end, fresh processes (import, compile or cache load, run, write): "
                  f"`gmr basins` cold {e2e['cold']:.2f} s, warm (second process, compilation cache filled) "
                  f"{e2e['warm']:.2f} s / {e2e['warm2']:.2f} s; the numba script (import, compile, run) "
                  f"{e2e['numba_script']:.2f} s (warm gmr basins / numba script: "
                  f"{min(e2e['warm'], e2e['warm2']) / e2e['numba_script']:.2f}x)."]
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("wrote", args.out)


if __name__ == "__main__":
    main()
