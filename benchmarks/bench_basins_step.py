"""Cost of one diffrax step per lane: `Tsit5.step` on the lane-batched state (what the default
basin sweep runs: lanes on the last axis, each lane its own t0, t1), `vmap` of the one-point
step (lanes on the first axis), and one evaluation of the field alone, for the chains of
`bench_basins` (one core, `--lanes` lanes, `--reps` loops of 300 steps, best taken).

    python benchmarks/bench_basins_step.py [--cells 3 10] [--lanes 128]
"""

import argparse
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))  # this checkout's gmr_jax

import gmr_jax as g  # noqa: E402, F401  (float64)
import diffrax as dfx  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import bench_basins as bb  # noqa: E402
from gmr_jax._basins._lanes import half_sine_field, lanes_field  # noqa: E402

K = 300


def best(loop, state, reps):
    jax.block_until_ready(loop(*state))
    out = float("inf")
    for _ in range(reps):
        t = time.perf_counter()
        jax.block_until_ready(loop(*state))
        out = min(out, time.perf_counter() - t)
    return out


def measure(d, b, reps):
    model = bb.make_model(d)
    wells = g.stable_wells(model, (-0.1, 0.1))
    solver = dfx.Tsit5(scan_kind="lax")
    f = jnp.linspace(0.5, 2.0, b)
    amp, t_off = jnp.full_like(f, 0.3), 0.5 / f
    out = {"cells": d, "lanes": b}
    with jax.numpy_rank_promotion("allow"):
        # lanes on the last axis, one step for all of them
        term = dfx.ODETerm(lanes_field(model, "tip", d, False))
        args = (model, f, amp, t_off)
        y = (jnp.tile(jnp.asarray(wells[:, 0])[:, None], (1, b)), jnp.zeros((d, b)))
        ss = solver.init(term, jnp.zeros(b), jnp.ones(b), y, args)

        def step(y, ss):
            t0 = jnp.zeros_like(f)
            y1, _, _, ss1, _ = solver.step(term, t0, t0 + 1e-3, y, args, ss, False)
            return y1, ss1

        loop = jax.jit(lambda y, ss: jax.lax.fori_loop(0, K, lambda i, c: step(*c), (y, ss)))
        out["batched_step_ns"] = best(loop, (y, ss), reps) / K / b * 1e9

        def field(y, ss):
            k = term.vf(jnp.zeros_like(f), y, args)
            return jax.tree.map(lambda a, v: a + 1e-3 * v, y, k), ss

        loop = jax.jit(lambda y, ss: jax.lax.fori_loop(0, K, lambda i, c: field(*c), (y, ss)))
        out["field_ns"] = best(loop, (y, ss), reps) / K / b * 1e9
    # the one-point step vmapped over the lanes (lanes on the first axis)
    term1 = dfx.ODETerm(half_sine_field("tip", d))
    y1 = (jnp.tile(jnp.asarray(wells[:, 0]), (b, 1)), jnp.zeros((b, d)))

    def one(y, ss, f, amp, t_off):
        a = (model, f, amp, t_off)
        y2, _, _, ss2, _ = solver.step(term1, 0.0, 1e-3, y, a, ss, False)
        return y2, ss2

    ss1 = jax.vmap(lambda y, f, amp, t_off: solver.init(term1, 0.0, 1.0, y, (model, f, amp, t_off)))(y1, f, amp, t_off)
    vone = jax.vmap(one)
    loop = jax.jit(lambda y, ss: jax.lax.fori_loop(0, K, lambda i, c: vone(c[0], c[1], f, amp, t_off), (y, ss)))
    out["vmapped_step_ns"] = best(loop, (y1, ss1), reps) / K / b * 1e9
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cells", type=int, nargs="*", default=[3, 10])
    ap.add_argument("--lanes", type=int, default=128)
    ap.add_argument("--reps", type=int, default=5)
    args = ap.parse_args()
    for d in args.cells:
        print(json.dumps(measure(d, args.lanes, args.reps)), flush=True)


if __name__ == "__main__":
    main()
