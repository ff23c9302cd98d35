"""How predictable is the 5-cell Kresling basin map at all? (issue: basin sweeps, 95 % target)

The truth's own map is compared with the maps of the *truth* after tiny changes that any
identified model carries (all damping coefficients +1 %; all stiffnesses +0.1 %): their agreement
is the ceiling for any model's agreement on this grid. Then the same comparison, and GMR vs truth,
for a more damped variant of the chain (damping ratio 0.10 instead of 0.04 at the wells).

Run: python benchmarks/kresling_basins_ceiling.py [--n 60]
Writes benchmarks/results_kresling_basins_ceiling.md.
"""

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("EQX_ON_ERROR", "nan")

import equinox as eqx  # noqa: E402
import numpy as np  # noqa: E402

import gmr_jax as g  # noqa: E402
from gmr_jax.systems._kresling import (  # noqa: E402
    KRESLING5_AMPLITUDE,
    KRESLING5_MASSES,
    KRESLING5_STIFFNESS,
    _chain_system,
)


def scaled(chain, damping=1.0, stiffness=1.0):
    c = chain.cells
    cells = eqx.tree_at(lambda c: (c.c0, c.c2, c.k_a, c.k_b), c,
                        (c.c0 * damping, c.c2 * damping, c.k_a * stiffness, c.k_b * stiffness))
    return eqx.tree_at(lambda ch: ch.cells, chain, cells)


def sweep(model, system, f, A, settle):
    wells = g.stable_wells(model, system.x_range)
    t0 = time.perf_counter()
    conf = np.asarray(g.basin_map(model, f, A, wells, settings=g.SweepSettings(settle_time=settle)).config)
    return conf, time.perf_counter() - t0


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--n", type=int, default=60)
    p.add_argument("--settle", type=float, default=40.0)
    args = p.parse_args()
    f = np.linspace(0.1, 5.0, args.n)
    A = np.linspace(0.02, 1.0, args.n)
    lines = ["# Predictability ceiling of the Kresling basin map", "",
             f"Command: `python benchmarks/kresling_basins_ceiling.py --n {args.n} --settle {args.settle:g}`. "
             f"Grid {args.n} x {args.n}, f in [0.1, 5] Hz, A in [0.02, 1] N, tip half-sine (Eq. 25) from all "
             f"folded, settle {args.settle:g} s. Agreement = share of grid points with the same final "
             "configuration as the reference truth.", "",
             "| chain | compared with the truth | agreement | configurations in truth map |", "|---|---|---|---|"]
    for zeta in (0.04, 0.10):
        chain = g.kresling_chain(KRESLING5_STIFFNESS, KRESLING5_MASSES, damping_ratio=zeta)
        system = _chain_system("kresling5", chain, "linear", (0.5, 10.0), KRESLING5_AMPLITUDE)
        truth, t_s = sweep(chain, system, f, A, args.settle)
        print(f"zeta {zeta}: truth map {t_s:.0f} s, {len(np.unique(truth))} configurations", flush=True)
        recs = g.make_recordings(system, KRESLING5_AMPLITUDE, seed=0)
        gmr = g.reconstruct(recs, g.Library(5, 5)).model
        cases = [("truth, all damping +1 %", scaled(chain, damping=1.01)),
                 ("truth, all stiffness +0.1 %", scaled(chain, stiffness=1.001)),
                 ("GMR model (0.3 mm sweeps, 60 dB)", gmr)]
        for name, m in cases:
            conf, _ = sweep(m, system, f, A, args.settle)
            agree = float(np.mean(conf == truth))
            print(f"  {name}: {agree:.1%}", flush=True)
            lines.append(f"| damping ratio {zeta:g} | {name} | {agree:.1%} | {len(np.unique(truth))} |")
    text = "\n".join(lines) + "\n"
    Path(__file__).with_name("results_kresling_basins_ceiling.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
