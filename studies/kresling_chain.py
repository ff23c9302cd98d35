"""Kresling chains (issue "Multi-DOF chains"): transmissibility, deployment and the 3-cell
prototype-like case, reconstructed models against the truth systems.

Parts (all by default):

- `trans`: 5-cell chain, displacement transmissibility of the tip (Eq. 24; equal to the
  acceleration transmissibility of the harmonic steady state) over 0.5-10 Hz in the folded
  (0-0-0-0-0) and deployed (1-1-1-1-1) configurations: truth, GMR and GMC-SINDy (Fig. 10).
  Resonance frequencies: peaks of a 120-point curve, each refined on a +-3 % zoom of 41 points.
- `deploy`: 5-cell chain, Eq. (25) tip half-sine from all-folded at 18 (f, A) points in the
  quasi-static, intermediate and impact regimes: final configuration of truth, GMR and GMC-SINDy,
  and time histories overlaid (Fig. 11d). Each point is also marked *robust* when the truth ends
  in the same configuration on the 5 x 5 stencil of +-2 % in f and A around it.
- `three`: 3-cell chain trained on 0-0-0 and 1-1-1 only; resonance frequencies of the unseen
  configurations 0-0-1 and 1-1-0 predicted by both methods (Fig. 14), and R^2 / NRMSE of the
  fitted force on the training data (Table 2).

Run: python studies/kresling_chain.py [--parts trans deploy three] [--seed 0]
Writes results/kresling_chain.md (results/kresling_chain_<parts>.md for a subset of the parts) and
results/figures/kresling_{transmissibility,deployment,three}.png.
"""

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("EQX_ON_ERROR", "nan")

import jax.numpy as jnp  # noqa: E402
import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import gmr_jax as g  # noqa: E402
from gmr_jax.systems import KRESLING3_AMPLITUDE, KRESLING5_AMPLITUDE  # noqa: E402

RESULTS = Path(__file__).resolve().parents[1] / "results"
FIGURES = RESULTS / "figures"


def config_label(bits) -> str:
    return "-".join(str(int(b)) for b in bits)


TRANS_AMPLITUDE = 1e-4  # m, base displacement for the transmissibility


def models_for(system, amplitude, seed):
    recs = g.systems.make_recordings(system, amplitude, snr_db=60.0, seed=seed)
    gmr = g.reconstruct(recs, g.Library(*system.orders["gmr"]), designs=system.designs)
    gmc = g.gmc_sindy(recs, g.Library(*system.orders["gmc"]))
    return recs, {"truth": system.truth, "GMR": gmr.value, "GMC-SINDy": gmc.value}, {"GMR": gmr, "GMC-SINDy": gmc}


def config_state(model, system, bits):
    """The model's own stable state for a configuration (bit i: cell i in its second well)."""
    wells = g.stable_wells(model, system.x_range)
    x = np.array([wells[i, b] if np.isfinite(wells[i, b]) else np.nan for i, b in enumerate(bits)])
    return x, wells


def refined_peaks(model, x_eq, freqs):
    return g.resonance_peaks(model, freqs, TRANS_AMPLITUDE, x_eq)


def match(truth_peaks, peaks):
    """Relative error of the nearest model peak to each truth peak."""
    out = []
    for f in truth_peaks:
        if not peaks:
            out.append(np.nan)
            continue
        near = min(peaks, key=lambda p: abs(p - f))
        out.append((near - f) / f)
    return np.array(out)


TABLE_HEAD = ["| configuration | truth peaks (Hz) | GMR peaks (Hz) | GMR max error | GMC-SINDy peaks (Hz) | "
              "GMC-SINDy max error |", "|---|---|---|---|---|---|"]


def compare_transmissibility(system, models, configs, freqs, lines, path, title, label=""):
    """Transmissibility of every model in each configuration (bit tuples): one table row and
    one panel per configuration, peaks matched to the truth's."""
    fig, axes = plt.subplots(1, len(configs), figsize=(6 * len(configs), 4.2), sharey=True)
    fmt = lambda p: ", ".join(f"{x:.3f}" for x in p)  # noqa: E731
    for ax, bits in zip(np.atleast_1d(axes), configs):
        row = {}
        for name, m in models.items():
            x_eq, _ = config_state(m, system, bits)
            t0 = time.perf_counter()
            td, peaks, ok = refined_peaks(m, x_eq, freqs)
            row[name] = peaks
            print(f"  transmissibility {config_label(bits)} {name}: {time.perf_counter() - t0:.1f} s, "
                  f"peaks {np.round(peaks, 3).tolist()}{'' if ok else ' (SOLVE FAILED)'}", flush=True)
            ax.plot(freqs, td, {"truth": "k-", "GMR": "C0--", "GMC-SINDy": "C3:"}[name], label=name)
        errs = {n: match(row["truth"], row[n]) for n in ("GMR", "GMC-SINDy")}
        lines.append(f"| {config_label(bits)} | {fmt(row['truth'])} | {fmt(row['GMR'])} | "
                     f"{100 * np.nanmax(np.abs(errs['GMR'])):.2f} % | {fmt(row['GMC-SINDy'])} | "
                     f"{100 * np.nanmax(np.abs(errs['GMC-SINDy'])):.2f} % |")
        ax.set_title(f"{label}configuration {config_label(bits)}")
        ax.set_xlabel("base frequency f [Hz]")
        ax.grid(alpha=0.3)
    np.atleast_1d(axes)[0].set_ylabel("T_d = 20 log10(X_tip / X_b) [dB]")
    np.atleast_1d(axes)[0].legend()
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    lines.append("")


def part_trans(system, models, lines, seed):
    lines += ["## 5-cell chain: transmissibility (Fig. 10)", "",
              f"Tip displacement transmissibility, base amplitude {TRANS_AMPLITUDE * 1e3:g} mm, "
              f"0.5-10 Hz; models from 0.3 mm base sweeps (60 dB, seed {seed}). Resonance peaks "
              "refined on a +-3 % zoom; error = nearest model peak vs each truth peak.", ""] + TABLE_HEAD
    compare_transmissibility(system, models, ((0,) * 5, (1,) * 5), np.linspace(0.5, 10.0, 120), lines,
                             FIGURES / "kresling_transmissibility.png",
                             "5-cell Kresling chain: tip transmissibility, model vs truth (Eq. 24)")


#: (f Hz, A N): quasi-static (slow pulse, the chain follows the load), intermediate, impact
#: (a short strong pulse), over the range of studies/kresling_basins.py.
DEPLOY_POINTS = {
    "quasi-static": [(0.15, 0.1), (0.15, 0.3), (0.2, 0.6), (0.25, 0.9), (0.3, 0.15), (0.3, 0.5)],
    "intermediate": [(0.8, 0.25), (1.0, 0.12), (1.2, 0.35), (1.5, 0.2), (1.8, 0.5), (2.0, 0.3)],
    "impact": [(3.0, 0.2), (3.5, 0.4), (4.0, 0.3), (4.5, 0.6), (5.0, 0.15), (5.0, 0.8)],
}


def part_deploy(system, models, lines, settle=40.0):
    settings = g.SweepSettings(settle_time=settle)
    pts = [(reg, f, a) for reg, lst in DEPLOY_POINTS.items() for f, a in lst]
    final = {}
    for name, m in models.items():
        wells = g.stable_wells(m, system.x_range)
        t0 = time.perf_counter()
        cfg = []
        for _, f, a in pts:
            bm = g.basin_map(m, np.array([f]), np.array([a]), wells, settings=settings)
            cfg.append(int(np.asarray(bm.value.config)[0, 0]))
        final[name] = cfg
        print(f"  deployment {name}: {time.perf_counter() - t0:.1f} s", flush=True)
    # robustness of the truth outcome on a +-2 % stencil
    wells_t = g.stable_wells(system.truth, system.x_range)
    robust = []
    for _, f, a in pts:
        bm = g.basin_map(system.truth, f * np.linspace(0.98, 1.02, 5), a * np.linspace(0.98, 1.02, 5), wells_t,
                         settings=settings)
        conf = np.asarray(bm.value.config)
        robust.append(bool(np.all(conf == conf[2, 2])))
    d = system.truth.n_dof
    lab = lambda c: "unsettled" if c < 0 else config_label([(c >> i) & 1 for i in range(d)])  # noqa: E731
    n = len(pts)
    agree = {k: sum(final[k][i] == final["truth"][i] for i in range(n)) for k in ("GMR", "GMC-SINDy")}
    agree_r = {k: sum(final[k][i] == final["truth"][i] for i in range(n) if robust[i]) for k in agree}
    lines += ["## 5-cell chain: deployment under the Eq. (25) tip half-sine (Fig. 11d)", "",
              f"Start all folded, settle {settle:g} s, same classification as `basin_map`. Robust: the truth "
              "ends in the same configuration over the +-2 % (f, A) stencil around the point.", "",
              f"GMR final configuration = truth at **{agree['GMR']}/{n}** points "
              f"({agree_r['GMR']}/{sum(robust)} robust points); GMC-SINDy {agree['GMC-SINDy']}/{n} "
              f"({agree_r['GMC-SINDy']}/{sum(robust)} robust).", "",
              "| regime | f (Hz) | A (N) | truth | robust | GMR | GMC-SINDy |", "|---|---|---|---|---|---|---|"]
    for i, (reg, f, a) in enumerate(pts):
        t = final["truth"][i]
        mark = lambda c: lab(c) + ("" if c == t else " ✗")  # noqa: E731
        lines.append(f"| {reg} | {f:g} | {a:g} | {lab(t)} | {'yes' if robust[i] else 'no'} | "
                     f"{mark(final['GMR'][i])} | {mark(final['GMC-SINDy'][i])} |")
    lines.append("")
    # time histories at one point per regime
    picks = [next(i for i, p in enumerate(pts) if p[0] == reg) for reg in DEPLOY_POINTS]
    fig, axes = plt.subplots(len(picks), 1, figsize=(11, 3.0 * len(picks)))
    for ax, i in zip(axes, picks):
        reg, f, a = pts[i]
        t1 = 0.5 / f + 15.0
        ts = jnp.linspace(0.0, t1, 3001)
        for name, style in (("truth", "-"), ("GMR", "--")):
            m = models[name]
            sol = g.simulate(m, g.HalfSineTip(f, a, n_dof=d), ts, jnp.zeros(d), throw=False)
            x = np.asarray(sol.value[0])
            for c in range(d):
                ax.plot(ts, 1e3 * x[:, c], style, color=f"C{c}", lw=1.0,
                        label=f"cell {c + 1}" if name == "truth" else None)
        ax.axvline(0.5 / f, color="k", lw=0.6)
        ax.set_title(f"{reg}: f = {f:g} Hz, A = {a:g} N; truth -> {lab(final['truth'][i])}, "
                     f"GMR -> {lab(final['GMR'][i])} (solid truth, dashed GMR)", fontsize=9)
        ax.set_ylabel("x [mm]")
    axes[0].legend(ncol=5, fontsize=8)
    axes[-1].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(FIGURES / "kresling_deployment.png", dpi=110)
    plt.close(fig)


def part_three(lines, seed):
    system = g.systems.kresling3()
    recs, models, recons = models_for(system, KRESLING3_AMPLITUDE, seed)
    lines += ["## 3-cell prototype-like chain: unseen configurations (Fig. 14, Table 2)", "",
              f"Trained on 0-0-0 and 1-1-1 only (0.3 mm base sweeps, 60 dB, seed {seed}); transmissibility "
              f"peaks (base {TRANS_AMPLITUDE * 1e3:g} mm) of configurations never recorded.", ""] + TABLE_HEAD
    compare_transmissibility(system, models, ((0, 0, 1), (1, 1, 0)), np.linspace(0.5, 12.0, 120), lines,
                             FIGURES / "kresling_three.png",
                             "3-cell Kresling chain trained on 0-0-0 and 1-1-1: prediction of unseen configurations",
                             label="unseen ")
    lines += ["Training fit (Table 2): force of each cell, R^2 and NRMSE, worst over cells, per recording.", "",
              "| method | recording | min R^2 | max NRMSE |", "|---|---|---|---|"]
    for name, res in recons.items():
        for rec, sc in res.stats["training"].items():
            lines.append(f"| {name} | {rec} | {min(sc['r2']):.5f} | {100 * max(sc['nrmse']):.2f} % |")
    lines.append("")


def main():
    p = argparse.ArgumentParser(description="Kresling chains: transmissibility, deployment, unseen configurations")
    p.add_argument("--parts", nargs="+", default=["trans", "deploy", "three"])
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--settle", type=float, default=40.0)
    args = p.parse_args()
    lines = ["# Kresling chains: transmissibility, deployment, unseen configurations", "",
             f"Command: `python studies/kresling_chain.py --parts {' '.join(args.parts)} --seed {args.seed}`", ""]
    t0 = time.perf_counter()
    FIGURES.mkdir(parents=True, exist_ok=True)
    if {"trans", "deploy"} & set(args.parts):
        system = g.systems.kresling5()
        _, models, _ = models_for(system, KRESLING5_AMPLITUDE, args.seed)
        if "trans" in args.parts:
            part_trans(system, models, lines, args.seed)
        if "deploy" in args.parts:
            part_deploy(system, models, lines, args.settle)
    if "three" in args.parts:
        part_three(lines, args.seed)
    lines.append(f"Total time {time.perf_counter() - t0:.0f} s.")
    text = "\n".join(lines) + "\n"
    name = "kresling_chain.md" if len(args.parts) == 3 else f"kresling_chain_{'_'.join(args.parts)}.md"
    (RESULTS / name).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
