"""`gmr demo`: the paper's single-DOF cases, GMR beside GMC-SINDy beside the truth."""

import json
import time
import warnings
from pathlib import Path

import numpy as np

from .. import Library, gmc_sindy, reconstruct, save_model
from .._errors import GMRDataWarning
# metrics, plots (matplotlib) and systems are imported where used: every command imports this
# module to register `gmr demo`, and `gmr fit` need not pay for them at start-up


def register(sub):
    d = sub.add_parser("demo", help="run the built-in paper cases (GMR vs GMC-SINDy), write figures and a report")
    d.add_argument("--out", default="gmr_out", help="output folder (default gmr_out)")
    d.add_argument("--system", choices=["paper", "kresling5", "kresling3"], default="paper",
                   help="paper: the single-DOF cases (default); kresling5/kresling3: a Kresling chain, per cell, "
                   "with transmissibility")
    d.set_defaults(fn=run)
    return d


def run(args) -> int:
    from ._args import output_dir
    from ._progress import stage

    output_dir(args.out)
    stage(f"running the {args.system} demo (progress per case on stdout)")
    if args.system == "paper":
        run_demo(args.out)
    else:
        from ._demo_chain import run_chain_demo

        run_chain_demo(args.system, args.out)
    stage("done")
    return 0


def default_cases():
    """(system factory, amplitude, label): bistable joint, both damping models, base sweeps of
    5, 1 and 0.5 degrees; tri-stable NES, base sweep of 0.5 mm."""
    from ..systems import bistable_joint, tristable_nes

    cases = []
    for damping in ("position_independent", "position_dependent"):
        for deg in (5.0, 1.0, 0.5):
            cases.append((lambda d=damping: bistable_joint(d), np.deg2rad(deg), f"{deg:g} deg"))
    cases.append((tristable_nes, 5e-4, "0.5 mm"))
    return cases


def _equilibria_match(model, truth, x_range, tol):
    from ..metrics import equilibria

    got, want = equilibria(model, 0, x_range), equilibria(truth, 0, x_range)
    if len(got) != len(want):
        return False
    return all(abs(a[0] - b[0]) < tol and a[1] == b[1] for a, b in zip(got, want))


def run_case(system, amplitude, label, *, snr_db=60.0, seed=0, out: Path | None = None, log=print):
    """Generate the data of one case, reconstruct with GMR and GMC-SINDy, measure both."""
    from ..metrics import damping_error, restoring_error
    from ..plots import case_figure
    from ..systems import make_recordings

    t0 = time.perf_counter()
    recs = make_recordings(system, amplitude, snr_db=snr_db, seed=seed)
    t_data = time.perf_counter() - t0
    r_gmr, d_gmr = system.orders["gmr"]
    r_gmc, d_gmc = system.orders["gmc"]
    t0 = time.perf_counter()
    gmr, gmr_said = _quiet(lambda *a: reconstruct(*a, designs=system.designs), recs, Library(r_gmr, d_gmr))
    gmr_model, gmr_dofs = gmr.value, gmr.stats["dofs"]
    t_gmr = time.perf_counter() - t0
    t0 = time.perf_counter()
    gmc, gmc_said = _quiet(gmc_sindy, recs, Library(r_gmc, d_gmc))
    gmc = gmc.value
    t_gmc = time.perf_counter() - t0
    xr, vr = system.x_range[0], system.v_range[0]
    span = np.ptp(system.equilibria[:, 0])
    ratio = max(np.ptp(r.x[:, 0]) / 2 for r in recs) / span
    row = {"system": system.name, "description": system.description, "amplitude": label,
           "amplitude_ratio": float(ratio), "seconds": {"data": t_data, "gmr": t_gmr, "gmc": t_gmc}}
    for name, model, said in (("gmr", gmr_model, gmr_said), ("gmc", gmc, gmc_said)):
        row[name] = {
            "restoring_error": restoring_error(model, system.truth, 0, xr),
            "damping_error": damping_error(model, system.truth, 0, xr, vr),
            "equilibria_ok": _equilibria_match(model, system.truth, xr, 0.02 * span),
            "equations": model.equations(),
            "warnings": said,
        }
    row["gmr"]["global_orders"] = {"K_r": gmr_dofs[0].stats["K_r"], "K_d": gmr_dofs[0].stats["K_d"]}
    row["truth"] = system.truth.equations()
    if out is not None:
        tag = f"{system.name}_{label.replace(' ', '')}"
        save_model(gmr_model, out / f"model_gmr_{tag}.json")
        save_model(gmc, out / f"model_gmc_{tag}.json")
        case_figure(system, {"GMR": gmr_model, "GMC-SINDy": gmc}, recs, out / f"case_{tag}.png",
                    title=f"{system.description}, base sweep {label}")
        row["figure"] = f"case_{tag}.png"
    log(f"  {system.description:48s} {label:>7s}  GMR {row['gmr']['restoring_error']:.2e} / "
        f"{row['gmr']['damping_error']:.2e}   GMC-SINDy {row['gmc']['restoring_error']:.2e} / "
        f"{row['gmc']['damping_error']:.2e}   ({t_data + t_gmr + t_gmc:.1f} s)")
    return row


def _quiet(fn, *args):
    """(fn(*args), the GMRDataWarning messages it emitted): the demo writes them into its report (the baseline's
    inadmissible models, `gmc_sindy`) instead of printing them between the table's lines."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", GMRDataWarning)
        out = fn(*args)
    for w in caught:
        if not issubclass(w.category, GMRDataWarning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return out, [str(w.message) for w in caught if issubclass(w.category, GMRDataWarning)]


def warning_lines(rows, what=lambda r: f"{r['description']}, {r['amplitude']}") -> list[str]:
    """The report's list of the warnings each method's fit gave, case by case (none: one line that says so)."""
    lines = []
    for r in rows:
        for key, label in (("gmr", "GMR"), ("gmc", "GMC-SINDy")):
            lines += [f"- {what(r)}, {label}: {w}" for w in r[key].get("warnings", [])]
    return lines or ["- none"]


def table(rows) -> str:
    lines = [
        "| case | amplitude (dyn/static) | GMR restoring err | GMR damping err | GMR equilibria | "
        "GMC-SINDy restoring err | GMC-SINDy damping err | GMC-SINDy equilibria |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        g, c = r["gmr"], r["gmc"]
        lines.append(
            f"| {r['description']} | {r['amplitude']} ({100 * r['amplitude_ratio']:.1f} %) | "
            f"{100 * g['restoring_error']:.3g} % | {100 * g['damping_error']:.3g} % | "
            f"{'ok' if g['equilibria_ok'] else 'WRONG'} | {100 * c['restoring_error']:.3g} % | "
            f"{100 * c['damping_error']:.3g} % | {'ok' if c['equilibria_ok'] else 'WRONG'} |"
        )
    return "\n".join(lines)


def run_demo(out="gmr_out", *, log=print) -> list[dict]:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    log("gmr demo: global model reconstruction from small vibrations (GMR) vs GMC-SINDy")
    log("  errors: relative L2 of restoring force over 1.5x the equilibria span / of damping force")
    log("  over the phase-plane box (x_range, v_range of each system); 60 dB noise, seed 0")
    rows = []
    t0 = time.perf_counter()
    for k, (factory, amp, label) in enumerate(default_cases()):
        log(f"[{k + 1}/{len(default_cases())}] {label} ...")
        rows.append(run_case(factory(), amp, label, out=out, log=log))
    md = table(rows)
    lines = ["# gmr demo report", "", md, "", "Global models (GMR):", ""]
    for r in rows:
        lines.append(f"- {r['description']}, {r['amplitude']}: `{'; '.join(r['gmr']['equations'])}`"
                     f" (truth `{'; '.join(r['truth'])}`)")
    lines += ["", "Warnings of the fits (what `reconstruct` and `gmc_sindy` emit as GMRDataWarning):", ""]
    lines += warning_lines(rows)
    (out / "report.md").write_text("\n".join(lines) + "\n")
    (out / "report.json").write_text(json.dumps({"cases": rows}, indent=1, default=float))
    log("")
    log(md)
    said = {k: sum(len(r[k]["warnings"]) for r in rows) for k in ("gmr", "gmc")}
    log(f"\nwarnings: GMR {said['gmr']}, GMC-SINDy {said['gmc']} (listed in report.md)")
    log(f"\nwrote {out}/report.md, report.json, case_*.png, model_*.json in {time.perf_counter() - t0:.0f} s")
    return rows
