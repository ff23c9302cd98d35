"""Reconstruction of lattices of bistable elements on a graph (2 x 8 ladders, serial and grounded; 4 x 4 grid).

Each case: `gmr.systems.make_recordings` around the system's four configurations (every bistable
element at each of its wells), white noise at SNR on every channel (x, v, a and the node forces),
then `gmr.reconstruct(recs, topology=graph, coordination="evidence", designs=system.designs)`:
one law per design (the bistable trusses, the linear couplings), fitted from every node's balance.

Per case:
- amplitude: the requested one (RMS-equivalent sine amplitude of the most-moving element, % of
  the interwell distance) and the measured one (sqrt 2 x the largest RMS element vibration);
- restoring error: `metrics.restoring_error` of every bistable element over its interwell span
  (truth's wells), the largest over elements; the couplings' over their `x_range`;
- coverage: `metrics.band_coverage` share of the interwell span where the 95 % band holds the truth
  (the smallest over bistable elements) and the band's median width;
- wells: largest |model - truth| of the element law's zeros (stable wells and saddle), % of the
  interwell distance, and whether their stability matches;
- configurations: Newton on the model's node balance from each true configuration; the largest
  node distance to the truth's (% of the interwell distance) and whether every one is stable
  (stiffness matrix positive definite);
- seconds: the fit's wall time (first call: includes compilation).
An ablation repeats one case with the noise left off x only.

Run: python studies/lattice.py [--quick]   (writes results/lattice.md; --quick: 2 % only)
"""

import argparse
import dataclasses
import sys
import time
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import gmr_jax as gmr

RESULTS = Path(__file__).resolve().parents[1] / "results"


def wells_of(model, e, x_range):
    return [(x, s) for x, s in gmr.metrics.equilibria(model, e, x_range)]


def configurations(model, truth_eq):
    """Node equilibria of the model near the truth's, by Newton; (largest distance, all stable)."""
    graph = model.topology

    def residual(u):
        return graph.node_forces(model.force(u, jnp.zeros_like(u)))

    @jax.jit
    def newton(u):
        for _ in range(30):
            u = u - jnp.linalg.solve(jax.jacfwd(residual)(u), residual(u))
        return u, jnp.min(jnp.linalg.eigvalsh(jax.jacfwd(residual)(u)))

    dist, stable = 0.0, True
    for u0 in truth_eq:
        u, lam = newton(jnp.asarray(u0))
        dist = max(dist, float(jnp.max(jnp.abs(u - u0))))
        stable &= bool(lam > 0)
    return dist, stable


def case(system, frac, snr, seed, clean_x=False):
    truth, graph = system.truth, system.truth.topology
    bist = np.nonzero(system.designs == 0)[0]
    w = gmr.metrics.equilibria(truth, int(bist[0]), tuple(system.x_range[bist[0]]))
    stable = [x for x, s in w if s]
    span = stable[-1] - stable[0]
    recs = gmr.systems.make_recordings(system, frac * span, snr_db=None if clean_x else snr, seed=seed)
    if clean_x:  # noise on every channel but x
        rng = np.random.default_rng(seed)
        recs = [dataclasses.replace(r, **{k: gmr.add_noise(getattr(r, k), snr, rng) for k in ("v", "a", "force")})
                for r in recs]
    vib = max(np.sqrt(2) * np.max(np.std(np.asarray(graph.deformations(r.x)), axis=0)) for r in recs)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", gmr.GMRDataWarning)
        sol = gmr.reconstruct(recs, topology=graph, coordination="evidence", designs=system.designs, throw=False)
    seconds = time.perf_counter() - t0
    model = sol.value
    span_range = (stable[0], stable[-1])
    errs, covs, widths, well_err, well_ok = [], [], [], 0.0, True
    for e in bist:
        errs.append(gmr.metrics.restoring_error(model, truth, int(e), span_range))
        band = gmr.metrics.band_coverage(model, truth, int(e), span_range)
        covs.append(band.share)
        widths.append(band.width)
    # the elements of one design share one law: its wells once
    mw, tw = wells_of(model, int(bist[0]), tuple(system.x_range[bist[0]])), w
    if len(mw) == len(tw):
        well_err = max(abs(a[0] - b[0]) for a, b in zip(mw, tw)) / span
        well_ok = all(a[1] == b[1] for a, b in zip(mw, tw))
    else:
        well_err, well_ok = float("nan"), False
    couplings = [gmr.metrics.restoring_error(model, truth, int(e), tuple(system.x_range[e]))
                 for e in np.nonzero(system.designs != 0)[0]]
    dist, cfg_stable = configurations(model, np.asarray(system.equilibria))
    return {"system": system.name, "amp": 100 * frac, "measured": 100 * vib / span, "snr": snr, "seed": seed,
            "clean_x": clean_x, "degree": sol.stats["degree"], "err": 100 * max(errs), "cov": 100 * min(covs),
            "width": 100 * float(np.median(widths)), "coupling": 100 * max(couplings), "wells": 100 * well_err,
            "wells_ok": well_ok, "config": 100 * dist / span, "config_ok": cfg_stable, "seconds": seconds,
            "result": str(sol.result == gmr.RESULTS.successful)}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    fracs = (0.02,) if args.quick else (0.005, 0.01, 0.02, 0.03)
    rows = []
    ladder, grid, grounded = gmr.systems.ladder(), gmr.systems.grid(), gmr.systems.grounded_ladder()
    plan = [(ladder, f, 50.0, 1, False) for f in fracs] + [(ladder, 0.02, 60.0, 1, False),
                                                           (ladder, 0.02, 50.0, 1, True),
                                                           (grid, 0.02, 50.0, 1, False)]
    plan += [(grounded, f, 50.0, 1, False) for f in (fracs if args.quick else (0.005, 0.02, 0.03))]
    for system, frac, snr, seed, clean_x in plan:
        row = case(system, frac, snr, seed, clean_x)
        print(row, flush=True)
        rows.append(row)
    head = ("| system | amplitude (% interwell) requested / measured | SNR | seed | degree | restoring error, "
            "worst bistable element | 95 % band coverage, worst element | band width (median) | coupling error | "
            "wells (element law) | configurations | fit (s) |")
    lines = ["# Lattices on a graph: reconstruction from small vibrations", "",
             "Command: `python studies/lattice.py` (the script's docstring says what each column measures).", "",
             head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        snr = f"{r['snr']:.0f} dB" + (" (x noise-free)" if r["clean_x"] else "")
        lines.append(
            f"| {r['system']} | {r['amp']:.1f} / {r['measured']:.2f} | {snr} | {r['seed']} | {r['degree']} | "
            f"{r['err']:.2f} % | {r['cov']:.0f} % | {r['width']:.2f} % | {r['coupling']:.2f} % | "
            f"{r['wells']:.2f} % {'(stability right)' if r['wells_ok'] else '(stability WRONG)'} | "
            f"{r['config']:.2f} % {'all stable' if r['config_ok'] else 'NOT all stable'} | {r['seconds']:.1f} |")
    out = RESULTS / ("lattice_quick.md" if args.quick else "lattice.md")
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    sys.exit(main())
