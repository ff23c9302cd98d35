"""Concealed-physics benchmark of `gmr discover`: 12 scenarios + 3 controls.

In each scenario the truth has an effect the simulation model lacks, and the simulation model
was calibrated to the (noisy) estimation recordings without it (equation-error least squares),
so the effect hides inside its coefficients. `discover` gets the calibrated model, two
estimation recordings and one holdout recording (different multisine phases). Controls: the
model has every term of the truth. Writes benchmarks/results_discover.md.

    python benchmarks/discover_scenarios.py [--only NAME ...]
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import gmr_jax
from gmr_jax.discover._catalogue import Term
from gmr_jax.discover._discover import holdout_errors
from gmr_jax.discover._scenarios import Scenario, build

S, V, P = "stiffness", "velocity_damping", "position_damping"
K = (2 * np.pi * 2.0) ** 2
C = 2 * 0.05 * np.sqrt(K)


def t(dof, fam, order, c):
    return {"dof": dof, "physics": fam, "order": order, "coefficient": c}


SDOF = (t(0, S, 1, K), t(0, V, 1, C))
DUFF = SDOF + (t(0, S, 3, 0.2 * K / 0.27**2),)
CH2 = (t(0, S, 1, 300.0), t(0, V, 1, 1.5), t(1, S, 1, 200.0), t(1, V, 1, 1.0))
CH3 = (t(0, S, 1, 400.0), t(0, V, 1, 1.5), t(1, S, 1, 300.0), t(1, V, 1, 1.2), t(2, S, 1, 200.0),
       t(2, V, 1, 1.0))


def sd(name, eff, ratio, host, snr, meas, terms=SDOF):
    e = None if eff is None else (Term(0, *eff), ratio, Term(0, *host))
    return Scenario(name, (1.0,), "independent", terms, e, snr_db=snr, measured=meas, amplitude=20.0)


def ch(name, masses, terms, eff, ratio, host, snr, meas, excite, amp):
    e = None if eff is None else (Term(*eff), ratio, Term(*host))
    return Scenario(name, masses, "chain", terms, e, snr_db=snr, measured=meas, excite=excite, amplitude=amp)


SCENARIOS = [
    sd("sdof_coulomb_in_viscous_xva_60dB", (V, 0), 0.10, (V, 1), 60, "xva"),
    sd("sdof_coulomb_in_viscous_x_40dB", (V, 0), 0.15, (V, 1), 40, "x"),
    sd("sdof_cubic_in_linear_xva_50dB", (S, 3), 0.10, (S, 1), 50, "xva"),
    sd("sdof_cubic_in_linear_x_40dB", (S, 3), 0.15, (S, 1), 40, "x"),
    sd("sdof_quadratic_drag_in_viscous_xva_50dB", (V, 2), 0.15, (V, 1), 50, "xva"),
    sd("sdof_cubic_damping_in_viscous_x_60dB", (V, 3), 0.20, (V, 1), 60, "x"),
    sd("sdof_preload_xva_40dB", (S, 0), 0.05, (S, 1), 40, "xva"),
    sd("sdof_x2v_damping_in_viscous_xva_60dB", (P, 2), 0.20, (V, 1), 60, "xva"),
    sd("sdof_quadratic_stiffness_x_50dB", (S, 2), 0.10, (S, 1), 50, "x"),
    ch("chain2_coulomb_cell1_base_xva_50dB", (1.0, 1.0), CH2, (1, V, 0), 0.15, (1, V, 1), 50, "xva", "base", 5.0),
    ch("chain3_cubic_cell2_tip_x_50dB", (1.0, 1.0, 1.0), CH3, (2, S, 3), 0.10, (2, S, 1), 50, "x", "force", 5.0),
    ch("chain2_quadratic_drag_cell0_base_xva_40dB", (1.0, 1.0), CH2, (0, V, 2), 0.20, (0, V, 1), 40, "xva", "base", 5.0),
]
CONTROLS = [
    sd("control_sdof_duffing_x_40dB", None, 0, None, 40, "x", terms=DUFF),
    ch("control_chain2_base_xva_50dB", (1.0, 1.0), CH2, None, 0, None, 50, "xva", "base", 5.0),
    sd("control_sdof_with_coulomb_xva_60dB", None, 0, None, 60, "xva", terms=SDOF + (t(0, V, 0, 1.0),)),
]


def run_one(sc: Scenario):
    t0 = time.time()
    truth, model, est, hold, c_true = build(sc)
    rep = gmr_jax.discover(model, est, hold)
    hc = [r.complete(sc.topology) for r in hold]
    floor = holdout_errors(truth, hc, rep.settings, rep.before["kind"])
    floor = floor.get("output_nrmse", floor["equation_nrmse"]) if rep.before["kind"] == "output" else floor["equation_nrmse"]
    found = [(f["dof"], f["physics"] + (f"_{f['order']}" if "order" in f else "")) for f in rep.findings]
    row = {"name": sc.name, "found": found, "before": rep.before["nrmse"], "after": rep.after["nrmse"],
           "kind": rep.before["kind"], "truth_floor": floor, "seconds": time.time() - t0,
           "form": rep.settings["form"], "summary": rep.summary()}
    if sc.effect is not None:
        term = sc.effect[0]
        name = term.physics + (f"_{term.order}" if term.family == P else "")
        row["expected"] = (term.dof, name)
        row["c_true"] = c_true
        hit = [f for f in rep.findings if (f["dof"], f["physics"]) == (term.dof, term.physics)]
        row["c_found"] = hit[0]["coefficient"] if hit else float("nan")
        row["ci95"] = hit[0]["ci95"] if hit else None
        row["coef_err"] = abs(row["c_found"] - c_true) / abs(c_true) if hit else float("nan")
        row["right"] = found == [row["expected"]]
    else:
        row["right"] = not found
    return row


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--only", nargs="*", default=None)
    ap.add_argument("--out", default=str(Path(__file__).with_name("results_discover.md")))
    args = ap.parse_args(argv)
    rows = []
    for sc in SCENARIOS + CONTROLS:
        if args.only and sc.name not in args.only:
            continue
        r = run_one(sc)
        rows.append(r)
        print(f"{r['name']:45s} right={r['right']} found={r['found']} coef_err={r.get('coef_err', float('nan')):.3f} "
              f"{r['kind']} {100 * r['before']:.2f}% -> {100 * r['after']:.2f}% (truth {100 * r['truth_floor']:.2f}%) "
              f"{r['seconds']:.0f}s", flush=True)
    eff = [r for r in rows if "expected" in r]
    ctl = [r for r in rows if "expected" not in r]
    lines = ["# gmr discover: concealed-physics benchmark", "",
             "Command: `python benchmarks/discover_scenarios.py` (2 estimation + 1 holdout recordings per "
             "scenario, 40 s at 200 Hz, random-phase multisine 0.3-6 Hz; the simulation model is the truth "
             "without the effect, calibrated by equation-error least squares on the estimation recordings; "
             "effect size = RMS of its force / RMS of the host term's force). `xva`: x, v, a and inputs "
             "recorded; `x`: displacement and inputs only (v by Savitzky-Golay, weak form, no acceleration). "
             "Holdout NRMSE: output (simulation) error ||x_sim - x|| / ||x - mean||, measured against the "
             "noisy holdout x; 'truth' is the truth model's own holdout NRMSE (the noise floor).", "",
             "| scenario | expected (cell, physics) | found | right | coef true | coef found (95 % CI) | error | "
             "holdout NRMSE before -> after | ratio | truth | time |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        ci = r.get("ci95")
        cf = (f"{r['c_found']:.4g} ({ci[0]:.4g}, {ci[1]:.4g})" if ci else "-") if "expected" in r else "-"
        lines.append(
            f"| {r['name']} | {r.get('expected', 'none (control)')} | {r['found'] or 'none'} | "
            f"{'yes' if r['right'] else 'NO'} | {r.get('c_true', float('nan')):.4g} | {cf} | "
            f"{100 * r.get('coef_err', float('nan')):.1f} % | {100 * r['before']:.2f} % -> "
            f"{100 * r['after']:.2f} % ({r['kind']}) | {r['before'] / r['after']:.1f}x | "
            f"{100 * r['truth_floor']:.2f} % | {r['seconds']:.0f} s |")
    n_right = sum(r["right"] for r in eff)
    n_coef = sum(r.get("coef_err", 1.0) <= 0.2 for r in eff)
    n_2x = sum(r["before"] >= 2 * r["after"] for r in eff)
    lines += ["", f"Right physics on the right cell (and nothing else): {n_right}/{len(eff)}; "
              f"coefficient within 20 %: {n_coef}/{len(eff)}; holdout NRMSE better by >= 2x: {n_2x}/{len(eff)}; "
              f"controls with no finding: {sum(r['right'] for r in ctl)}/{len(ctl)}.", "",
              "## Summaries", ""]
    for r in rows:
        lines += [f"**{r['name']}**", "", "```", r["summary"], "```", ""]
    Path(args.out).write_text("\n".join(lines))
    print(lines[-len(rows) * 5 - 3] if rows else "")
    return 0


if __name__ == "__main__":
    sys.exit(main())
