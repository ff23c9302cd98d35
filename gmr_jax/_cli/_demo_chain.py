"""`gmr demo --system kresling5|kresling3`: a Kresling chain, GMR beside GMC-SINDy beside the
truth, per cell (paper Figs. 8-10)."""

import json
import time
from pathlib import Path

from matplotlib.figure import Figure
import numpy as np

from .. import Library, gmc_sindy, reconstruct, resonance_peaks, save_model, stable_wells
from ..metrics import damping_error, energy_barriers, equilibria, restoring_error
from ..plots import case_figure
from ..systems import KRESLING3_AMPLITUDE, KRESLING5_AMPLITUDE, kresling3, kresling5, make_recordings
from ._demo import _quiet

CHAINS = {"kresling5": (kresling5, KRESLING5_AMPLITUDE, 10.0), "kresling3": (kresling3, KRESLING3_AMPLITUDE, 12.0)}
#: Base displacement amplitude of the transmissibility runs (m).
TRANS_AMPLITUDE = 1e-4


def _cell_metrics(model, truth, i, xr, vr, span):
    got, want = equilibria(model, i, xr), equilibria(truth, i, xr)
    eq_ok = len(got) == len(want) and all(abs(a[0] - b[0]) < 0.02 * span and a[1] == b[1]
                                          for a, b in zip(got, want))
    b_got = [b for _, b in energy_barriers(model, i, xr)]
    b_want = [b for _, b in energy_barriers(truth, i, xr)]
    barrier = (max(abs(a - b) / b for a, b in zip(b_got, b_want))
               if len(b_got) == len(b_want) and b_want else float("nan"))
    return {"restoring_error": restoring_error(model, truth, i, xr),
            "damping_error": damping_error(model, truth, i, xr, vr),
            "equilibria_ok": bool(eq_ok), "barrier_error": float(barrier),
            "equilibria": [[round(x, 7), s] for x, s in got]}


def _transmissibility(system, models, out, f_max, log):
    freqs = np.linspace(0.5, f_max, 60)
    res = {}
    fig = Figure(figsize=(12, 4.2))
    axes = fig.subplots(1, 2, sharey=True)
    d = system.truth.n_dof
    for ax, (label, bit) in zip(axes, (("folded", 0), ("deployed", 1))):
        res[label] = {}
        for name, m in models.items():
            wells = stable_wells(m, system.x_range)
            x_eq = wells[np.arange(d), bit] if wells.shape[1] > bit else np.full(d, np.nan)
            if np.any(~np.isfinite(x_eq)):
                res[label][name] = {"peaks": [], "ok": False}
                continue
            td, peaks, ok = resonance_peaks(m, freqs, TRANS_AMPLITUDE, x_eq)
            res[label][name] = {"peaks": peaks, "ok": ok}
            ax.plot(freqs, td, {"truth": "k-", "GMR": "C0--", "GMC-SINDy": "C3:"}[name], label=name)
        truth_peaks = res[label]["truth"]["peaks"]
        for name in ("GMR", "GMC-SINDy"):
            p = res[label][name]["peaks"]
            errs = [min(abs(q - f) for q in p) / f for f in truth_peaks] if p else [float("nan")]
            res[label][name]["max_peak_error"] = float(max(errs))
        log(f"  transmissibility {label}: truth peaks {np.round(truth_peaks, 3).tolist()} Hz; max peak error "
            f"GMR {100 * res[label]['GMR']['max_peak_error']:.2f} %, "
            f"GMC-SINDy {100 * res[label]['GMC-SINDy']['max_peak_error']:.2f} %")
        ax.set_title(f"{label} configuration")
        ax.set_xlabel("base frequency f [Hz]")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("T_d = 20 log10(X_tip / X_b) [dB]")
    axes[0].legend()
    fig.suptitle(f"{system.name}: tip transmissibility (Eq. 24), base {TRANS_AMPLITUDE * 1e3:g} mm")
    fig.tight_layout()
    fig.savefig(out / f"transmissibility_{system.name}.png", dpi=110)
    return res


def run_chain_demo(name="kresling5", out="gmr_out", *, log=print) -> dict:
    factory, amplitude, f_max = CHAINS[name]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    system = factory()
    d = system.truth.n_dof
    log(f"gmr demo --system {name}: {system.description}")
    log(f"[1/4] base-sweep recordings, folded and deployed configurations ({amplitude * 1e3:g} mm, 60 dB) ...")
    recs = make_recordings(system, amplitude, seed=0)
    log("[2/4] GMR (local Library(5,5)) and GMC-SINDy (Library(5,5)) ...")
    gmr, gmr_said = _quiet(reconstruct, recs, Library(*system.orders["gmr"]))
    gmc, gmc_said = _quiet(gmc_sindy, recs, Library(*system.orders["gmc"]))
    gmr, gmc = gmr.value, gmc.value
    models = {"truth": system.truth, "GMR": gmr, "GMC-SINDy": gmc}
    log("[3/4] per-cell errors and figures ...")
    cells = []
    for i in range(d):
        xr, vr = system.x_range[i], system.v_range[i]
        span = float(np.ptp(system.equilibria[:, i]))
        row = {"cell": i + 1, "amplitude_ratio": [float(np.ptp(r.x[:, i]) / 2 / span) for r in recs]}
        for key, model in (("gmr", gmr), ("gmc", gmc)):
            row[key] = _cell_metrics(model, system.truth, i, xr, vr, span)
        cells.append(row)
        case_figure(system, {"GMR": gmr, "GMC-SINDy": gmc}, recs, out / f"cell{i + 1}_{name}.png",
                    dof=i, title=f"{name}, cell {i + 1} (from the base)")
        log(f"  cell {i + 1}: restoring GMR {100 * row['gmr']['restoring_error']:.2f} % / GMC-SINDy "
            f"{100 * row['gmc']['restoring_error']:.2f} %; damping GMR {100 * row['gmr']['damping_error']:.1f} % "
            f"/ GMC-SINDy {100 * row['gmc']['damping_error']:.1f} %; equilibria "
            f"{'ok' if row['gmr']['equilibria_ok'] else 'WRONG'} / {'ok' if row['gmc']['equilibria_ok'] else 'WRONG'}")
    log("[4/4] transmissibility in the folded and deployed configurations ...")
    trans = _transmissibility(system, models, out, f_max, log)
    save_model(gmr, out / f"model_gmr_{name}.json", method="GMR")
    save_model(gmc, out / f"model_gmc_{name}.json", method="GMC-SINDy")
    lines = [f"# gmr demo: {name}", "", system.description, "",
             "| cell | amplitude ratio | GMR restoring | GMR damping | GMR equilibria | GMR barrier | "
             "GMC-SINDy restoring | GMC-SINDy damping | GMC-SINDy equilibria | GMC-SINDy barrier |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for c in cells:
        g_, m_ = c["gmr"], c["gmc"]
        lines.append(
            f"| {c['cell']} | {', '.join(f'{100 * a:.1f} %' for a in c['amplitude_ratio'])} | "
            f"{100 * g_['restoring_error']:.2f} % | {100 * g_['damping_error']:.1f} % | "
            f"{'ok' if g_['equilibria_ok'] else 'WRONG'} | {100 * g_['barrier_error']:.1f} % | "
            f"{100 * m_['restoring_error']:.2f} % | {100 * m_['damping_error']:.1f} % | "
            f"{'ok' if m_['equilibria_ok'] else 'WRONG'} | {100 * m_['barrier_error']:.1f} % |")
    lines += ["", "Resonance frequencies (transmissibility peaks, Hz):", ""]
    for label, res in trans.items():
        lines.append(f"- {label}: truth {np.round(res['truth']['peaks'], 3).tolist()}; GMR "
                     f"{np.round(res['GMR']['peaks'], 3).tolist()} (max error "
                     f"{100 * res['GMR']['max_peak_error']:.2f} %); GMC-SINDy "
                     f"{np.round(res['GMC-SINDy']['peaks'], 3).tolist()} (max error "
                     f"{100 * res['GMC-SINDy']['max_peak_error']:.2f} %)")
    lines += ["", "Global models (GMR):", ""] + [f"- `{e}`" for e in gmr.equations()]
    lines += ["", "Warnings of the fits (what `reconstruct` and `gmc_sindy` emit as GMRDataWarning):", ""]
    lines += [f"- {label}: {w}" for label, said in (("GMR", gmr_said), ("GMC-SINDy", gmc_said)) for w in said] or ["- none"]
    md = "\n".join(lines) + "\n"
    (out / f"report_{name}.md").write_text(md)
    report = {"system": name, "description": system.description, "cells": cells, "transmissibility": trans,
              "warnings": {"gmr": gmr_said, "gmc": gmc_said}, "seconds": time.perf_counter() - t0}
    (out / f"report_{name}.json").write_text(json.dumps(report, indent=1, default=float))
    log("")
    log("\n".join(lines[4:4 + d + 2]))
    log(f"\nwrote {out}/report_{name}.md/.json, cell*_{name}.png, transmissibility_{name}.png, "
        f"model_*_{name}.json in {time.perf_counter() - t0:.0f} s")
    return report
