"""Explore GMR and GMC-SINDy on the Kresling chain benchmarks (issue "Multi-DOF chains").

For each amplitude: base-sweep recordings around the fully folded and fully deployed
configurations (`make_recordings`), then `reconstruct` (GMR) and `gmc_sindy`, and per cell:

- the amplitude ratio (half peak-to-peak of the vibration / interwell distance L), per well;
- the relative L2 error of the restoring force over the folding range x in [-0.1 L, 1.1 L];
- the relative L2 error of the damping force over that range x the v box of the system;
- the model's equilibria in that range and their stability against the truth's (folded 0,
  saddle, deployed L), and the energy barrier.

Usage:
    python studies/explore_kresling.py [--system kresling5|kresling3]
        [--twist linear|torque_free]
        [--amp 3e-4 5e-4] [--snr 60] [--r 5 --d 5] [--gmc-r 7 --gmc-d 7] [--seeds 0 1 2]
        [--coordination evidence|hermite|gls] [--screen 3] [--interleave 50] [--origin folded|base]
        [--duration 60] [--quiet] [--json results/data/explore_kresling.json]

It prints its log (tables of errors per cell); `--json` keeps every number.

`--screen Z` and `--interleave N` emulate two changes to the local fits of the paper's route
without touching the library (see `screened` and `interleave`); both variants run on that route
(`coordination="gls"`) whatever `--coordination` gives the plain GMR row. The numbers reported
for the issue:
    python studies/explore_kresling.py --amp 2e-4 3e-4 5e-4 1e-3 --seeds 0 1 2 --screen 3 \
        --interleave 50 --quiet
    python studies/explore_kresling.py --amp 3e-4 1e-3 --gmc-r 7 --gmc-d 7 --screen 3 --quiet
    python studies/explore_kresling.py --snr 40 --amp 5e-4 1e-3 --seeds 0 1 --screen 3 \
        --interleave 50 --quiet
    python studies/explore_kresling.py --snr 0 --amp 3e-4          # noise free
    python studies/explore_kresling.py --origin base --amp 3e-4 1e-3 --quiet
    python studies/explore_kresling.py --system kresling3 --amp 3e-4 5e-4 1e-3 --screen 3
    python studies/explore_kresling.py --twist torque_free --amp 3e-4 5e-4 1e-3 --screen 3
"""

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import gmr_jax
from gmr_jax.systems import cell_equilibria, kresling3, kresling5


def model_equilibria(stiffness_coef, lo, hi, n=4001):
    """Zeros of a global restoring polynomial in [lo, hi] and their stability (F' > 0)."""
    x = np.linspace(lo, hi, n)
    p = np.polynomial.Polynomial(stiffness_coef)
    f = p(x)
    roots = []
    for i in np.nonzero(np.sign(f[1:]) != np.sign(f[:-1]))[0]:
        a, b = x[i], x[i + 1]
        for _ in range(60):
            m = 0.5 * (a + b)
            if np.sign(p(m)) == np.sign(p(a)):
                a = m
            else:
                b = m
        roots.append(0.5 * (a + b))
    dp = p.deriv()
    return [(float(r), bool(dp(r) > 0)) for r in roots]


def barrier_of_poly(coef, x0, xu):
    P = np.polynomial.Polynomial(coef).integ()
    return float(P(xu) - P(x0))


def shift_recordings(recs, offset):
    """Measure each cell's deformation from another origin: x -> x + offset (per cell)."""
    from dataclasses import replace

    return [replace(r, x=r.x + offset[None, :]) for r in recs]


def screened(rec, z: float):
    """GMR with a significance screen (a proposed change, done here outside the library): after
    the local fits, a coefficient with |c| < z * stderr is set to zero (a known zero; a dropped
    top order lowers r_i), then the coordination is redone. Only the model is rebuilt.
    `rec`: the `Solution` of `reconstruct`."""
    lib, m = rec.stats["library"], rec.value
    stiff, vdamp, pdamp, orders = [], [], [], []
    for dof in rec.stats["dofs"]:
        coef = np.where(np.abs(dof.local_coef) < z * dof.local_stderr, 0.0, dof.local_coef)
        n = coef.shape[0]
        fits = gmr_jax.LocalFit(
            equilibrium=jnp.asarray(dof.equilibria),
            coef=jnp.asarray(coef),
            covariance=jnp.asarray(np.stack([np.diag(se**2) for se in dof.local_stderr])),
            threshold=jnp.asarray(dof.thresholds),
            rss=jnp.zeros(n),
            n_samples=jnp.ones(n),
        )
        sol = gmr_jax.coordinate(fits, lib)
        gc = sol.value
        stiff.append(np.asarray(gc.stiffness)), vdamp.append(np.asarray(gc.velocity_damping))
        pdamp.append(np.asarray(gc.position_damping))
        orders.append(np.asarray(sol.stats["r_i"]).tolist())  # local restoring order per well

    def pad(arrs):
        size = max(a.shape[0] for a in arrs)
        return jnp.asarray(np.stack([np.pad(a, (0, size - a.shape[0])) for a in arrs]))

    model = gmr_jax.GlobalModel(
        masses=m.masses,
        stiffness=pad(stiff),
        velocity_damping=pad(vdamp),
        position_damping=pad(pdamp),
        topology=m.topology,
    )
    return model, orders


def interleave(recs, n_chunks: int, n_folds: int = 5):
    """Reorder the samples so that each of the `n_folds` contiguous CV blocks of the local fits
    holds every n_folds-th of `n_chunks` chunks, i.e. spans the whole sweep (a proposed change
    of the CV fold design, emulated here: the fits use x, v, a and inputs sample by sample, so
    only the CV blocks see the order)."""
    from dataclasses import replace

    out = []
    for r in recs:
        n = r.x.shape[0]
        chunks = np.array_split(np.arange(n), n_chunks)
        order = np.concatenate(
            [chunks[k] for f in range(n_folds) for k in range(f, n_chunks, n_folds)]
        )
        fields = {
            k: getattr(r, k)[order]
            for k in ("x", "v", "a", "base_acc", "force")
            if getattr(r, k) is not None
        }
        out.append(replace(r, **fields))
    return out


def evaluate(system, rec_model, n_grid=801, n_v=41, offset=None):
    truth = system.truth
    d = truth.n_dof
    eq = cell_equilibria(truth)
    out = []
    for i in range(d):
        lo, hi = system.x_range[i]
        xs = np.linspace(lo, hi, n_grid)
        cell = jax.tree_util.tree_map(lambda a, i=i: a[i], truth.cells)
        f_true = np.asarray(jax.vmap(cell.force)(jnp.asarray(xs)))
        off = 0.0 if offset is None else float(offset[i])
        coef = np.asarray(rec_model.stiffness[i])
        if off:  # express the model in the truth's coordinate: F(x) = P(x + off)
            coef = np.polynomial.Polynomial(coef)(np.polynomial.Polynomial([off, 1.0])).coef
        f_mod = np.polynomial.Polynomial(coef)(xs)
        err_r = float(np.linalg.norm(f_mod - f_true) / np.linalg.norm(f_true))
        # damping over the (x, v) box
        vs = np.linspace(*system.v_range[i], n_v)
        X, V = np.meshgrid(xs[::10], vs, indexing="ij")
        fd_true = np.asarray(jax.vmap(cell.damping)(jnp.asarray(X.ravel()), jnp.asarray(V.ravel())))
        xx = jnp.zeros((X.size, d)).at[:, i].set(jnp.asarray(X.ravel()))
        vv = jnp.zeros((X.size, d)).at[:, i].set(jnp.asarray(V.ravel()))
        fd_mod = np.asarray(jax.vmap(rec_model.damping)(xx + off, vv))[:, i]
        err_d = float(np.linalg.norm(fd_mod - fd_true) / np.linalg.norm(fd_true))
        roots = model_equilibria(coef, lo, hi)
        stable = [r for r, s in roots if s]
        unstable = [r for r, s in roots if not s]
        L = eq["stable"][i, 1]
        # match: exactly 2 stable (near 0 and L) and 1 unstable between them
        ok = (
            len(stable) == 2
            and len(unstable) == 1
            and abs(stable[0]) < 0.1 * L
            and abs(stable[1] - L) < 0.1 * L
            and stable[0] < unstable[0] < stable[1]
        )
        barrier = barrier_of_poly(coef, stable[0], unstable[0]) if ok else float("nan")
        out.append(
            {
                "cell": i + 1,
                "restoring_rel_l2": err_r,
                "damping_rel_l2": err_d,
                "stable": stable,
                "unstable": unstable,
                "equilibria_match": bool(ok),
                "stable_err_over_L": [float(stable[0] / L), float((stable[1] - L) / L)]
                if ok
                else None,
                "saddle_err_over_L": float((unstable[0] - eq["unstable"][i]) / L) if ok else None,
                "barrier_rel_err": float(barrier / eq["barrier"][i] - 1) if ok else None,
            }
        )
    return out


def _line(e):
    if e["equilibria_match"]:
        eq = f"(saddle {100 * e['saddle_err_over_L']:+.2f}% L, barrier {100 * e['barrier_rel_err']:+.1f}%)"
    else:
        eq = (
            f"stable {np.round(np.array(e['stable']) * 1e3, 2)} mm "
            f"unstable {np.round(np.array(e['unstable']) * 1e3, 2)} mm"
        )
    return (
        f"    cell {e['cell']}: F_r err {100 * e['restoring_rel_l2']:7.3f}%  F_d err "
        f"{100 * e['damping_rel_l2']:9.3f}%  equilibria match {e['equilibria_match']} {eq}"
    )


def run_one(system, amp, seed, args, L):
    t0 = time.time()
    recs = gmr_jax.systems.make_recordings(
        system, amp, snr_db=args.snr if args.snr > 0 else None, seed=seed, duration=args.duration
    )
    t_sim = time.time() - t0
    ratios = [(0.5 * np.ptp(r.x, axis=0) / L).tolist() for r in recs]
    offset = None
    if args.origin == "base":
        offset = np.asarray(system.truth.cells.h_folded)
        recs = shift_recordings(recs, offset)
    print(
        f"\n=== amplitude {amp * 1e3:.3g} mm, SNR {args.snr} dB, seed {seed}, origin {args.origin} "
        f"(simulation {t_sim:.1f} s)"
    )
    for r, q in zip(recs, ratios):
        print(f"  amplitude ratio {r.name}: " + " ".join(f"{100 * v:.2f}%" for v in q))
    entry = {
        "origin": args.origin,
        "amplitude": amp,
        "seed": seed,
        "snr_db": args.snr,
        "amplitude_ratio": ratios,
    }
    lib = gmr_jax.Library(args.r, args.d)
    methods = [("GMR", lambda: gmr_jax.reconstruct(recs, lib, coordination=args.coordination))]
    if args.interleave:  # a change to the local fits' CV folds: the paper's route
        methods.append(
            (
                f"GMR gls+interleave{args.interleave}",
                lambda: gmr_jax.reconstruct(interleave(recs, args.interleave), lib, coordination="gls"),
            )
        )
    if not args.no_gmc:
        gr, gd = args.gmc_r or args.r, args.gmc_d or args.d
        methods.append(
            (f"GMC-SINDy({gr},{gd})", lambda: gmr_jax.gmc_sindy(recs, gmr_jax.Library(gr, gd)))
        )
    for name, fn in methods:
        t0 = time.time()
        try:
            rec = fn()
        except Exception as e:  # noqa: BLE001  (report any failure and go on)
            print(f"  {name}: failed: {e}")
            entry[name] = {"error": str(e)}
            continue
        dt = time.time() - t0
        variants = [(name, rec.value, None)]
        if name.startswith("GMR"):
            variants[0] = (name, rec.value, [d.stats.get("r_i") for d in rec.stats["dofs"]])
            if args.screen > 0:  # a screen of the local fits: the paper's route
                paper = rec if rec.stats["dofs"][0].stats["coordination"] != "evidence" else \
                    gmr_jax.reconstruct(recs, lib, coordination="gls")
                model, orders = screened(paper, args.screen)
                variants.append((f"{name} gls+screen{args.screen:g}", model, orders))
        for vname, model, orders in variants:
            ev = evaluate(system, model, offset=offset)
            worst = max(e["restoring_rel_l2"] for e in ev)
            extra = f" local orders r_i: {orders}" if orders is not None else ""
            print(
                f"  {vname} ({dt:.1f} s) worst F_r err {100 * worst:.2f}%, all equilibria match "
                f"{all(e['equilibria_match'] for e in ev)}{extra}"
            )
            if not args.quiet:
                for e in ev:
                    print(_line(e))
            entry[vname] = {
                "cells": ev,
                "seconds": dt,
                "model": model.terms(),
                "local_orders": orders,
            }
    return entry


def main():
    ap = argparse.ArgumentParser(description="Explore GMR and GMC-SINDy on the Kresling chain benchmarks")
    ap.add_argument("--system", default="kresling5")
    ap.add_argument("--twist", default="linear")
    ap.add_argument("--amp", type=float, nargs="+", default=[3e-4, 5e-4, 1e-3])
    ap.add_argument("--snr", type=float, default=60.0, help="dB; <= 0 for noise free")
    ap.add_argument("--r", type=int, default=5)
    ap.add_argument("--d", type=int, default=5)
    ap.add_argument("--gmc-r", type=int, default=None)
    ap.add_argument("--gmc-d", type=int, default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-gmc", action="store_true")
    ap.add_argument("--coordination", default="evidence", choices=["evidence", "hermite", "gls"],
                    help="reconstruct's route for the GMR row (default: evidence)")
    ap.add_argument(
        "--origin",
        default="folded",
        choices=["folded", "base"],
        help="coordinate origin given to the fits: the folded state (x = h - h_f, the "
        "system's own) or the cell's base plate (x = h, absolute height)",
    )
    ap.add_argument("--json", default=None, help="write every number here (e.g. results/data/explore_kresling.json)")
    ap.add_argument(
        "--screen",
        type=float,
        default=0.0,
        help="also report GMR with local coefficients |c| < SCREEN * stderr zeroed",
    )
    ap.add_argument(
        "--interleave",
        type=int,
        default=0,
        help="also report GMR with CV folds interleaved over this many chunks",
    )
    ap.add_argument("--duration", type=float, default=None, help="s (default: the system's)")
    ap.add_argument("--seeds", type=int, nargs="+", default=None, help="several noise seeds")
    ap.add_argument("--quiet", action="store_true", help="one summary line per method")
    args = ap.parse_args()
    system = {"kresling5": kresling5, "kresling3": kresling3}[args.system](twist=args.twist)
    L = np.asarray(system.truth.interwell)
    eq = cell_equilibria(system.truth)
    print(
        f"{system.name}: L = {np.round(L * 1e3, 2)} mm, saddle = {np.round(eq['unstable'] * 1e3, 2)} mm, "
        f"barrier = {np.round(eq['barrier'] * 1e3, 3)} mJ, well stiffness = {np.round(eq['stiffness'], 1).tolist()} N/m"
    )
    results = []
    seeds = args.seeds or [args.seed]
    for amp in args.amp:
        for seed in seeds:
            results.append(run_one(system, amp, seed, args, L))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        with open(args.json, "w") as f:
            json.dump({"system": system.name, "args": vars(args), "results": results}, f, indent=1)


if __name__ == "__main__":
    main()
