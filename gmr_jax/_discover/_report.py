"""The readable summary of a `DiscoveryReport` (its figures: `gmr_jax.plots.discovery_figures`)."""

from ._catalogue import PLAIN


#: with no finding, a re-calibration larger than this share of the model's coefficient (and outside its interval)
#: is said in the headline: hand-made Duffing with 0.1 v|v| left out, 20 dB: no finding, the viscous term +26 %
LARGE_CORRECTION = 0.10


def _cell(report, i):
    return f"cell {i}" if report.given.topology.name == "chain" else ("DOF 0" if report.given.n_dof == 1 else f"DOF {i}")


def _g(x):
    return f"{x:.4g}"


def _range(vals) -> str:
    lo, hi = f"{min(vals):.3g}", f"{max(vals):.3g}"
    return lo if lo == hi else f"{lo}-{hi}"


def _moved(c) -> bool:
    """A re-calibration of a term the model has (nonzero) whose 95 % interval excludes 0."""
    return c["model_value"] != 0 and not (c["ci95"][0] <= 0 <= c["ci95"][1])


def _term(c) -> str:
    """A correction's term in words: "mass", or "physics (family order)"."""
    return "mass" if c["physics"] == "mass" else f"{c['physics']} ({c.get('family')} {c.get('order')})"


def _split(report) -> list:
    """(dof, candidate, its forward step, its bootstrap share, {other candidate: share}) for each candidate the
    forward selection accepted that failed only the bootstrap stability, where it and the candidates selected
    instead in at least a tenth of the replicates together reach the rule's stability share: the data show a
    missing term, not which (hand-made Duffing, x only, 30 dB, the cubic left out: x^3 p = 1e-21, validation
    gain 67 %, then x^3 in 60 % and x^5 in 40 % of the replicates; it read "Nothing missing")."""
    need = float((report.settings.get("rule") or {}).get("stability", 0.8))
    found = {(f["dof"], f.get("basis")) for f in report.findings}
    out = []
    for s in report.selection:
        unstable = {r["term"] for r in s.get("rejected", []) if "bootstrap replicates" in r["reason"]}
        for step in s.get("steps", []):
            c = step["candidate"]
            if not step["accepted"] or c not in unstable:
                continue
            others = {k: v for k, v in s["stability"].items()
                      if k != c and v >= 0.1 and (s["dof"], k) not in found}
            if others and s["stability"][c] + sum(others.values()) >= need:
                out.append((s["dof"], c, step, s["stability"][c], others))
    return out


def summary(report) -> str:
    """Plain-words summary: one sentence per finding, with evidence and uncertainty."""
    b, a = report.before, report.after
    kind = "simulation (output) error" if b["kind"] == "output" else "equation (force) error"
    err = f"{b['on']} {kind} NRMSE {100 * b['nrmse']:.3g} % -> {100 * a['nrmse']:.3g} %"
    lines = []
    for f in report.findings:
        lo, hi = f["ci95"]
        unit = f.get("unit", "")
        order = f" (order {f['order']})" if "order" in f else ""
        lines.append(
            f"{_cell(report, f['dof'])}: {PLAIN.get(f['physics'], f['physics'])}{order}, "
            f"{f.get('basis', '')} coefficient {_g(f['coefficient'])} {unit} "
            f"(95 % CI {_g(lo)} to {_g(hi)}), was left out; with the re-calibrated terms it explains "
            f"{100 * f['explained_fraction']:.0f} % of the model's equation-error residual on its own "
            f"(drop-one); {f['where']}; kept in {100 * f['stability']:.0f} % of bootstrap replicates, "
            f"p = {f['p_value']:.2g}, validation gain {100 * f['cv_gain']:.1f} %; {err}.")
    big = [c for c in report.corrections
           if _moved(c) and abs(c["coefficient"]) > LARGE_CORRECTION * abs(c["model_value"])]
    split = _split(report)
    for dof, c, step, share, others in split:
        lines.append(f"A term is missing on {_cell(report, dof)}, but these data do not say which: {c} passed the "
                     f"forward selection (p = {step['p_value']:.2g}, validation gain {100 * step['cv_gain']:.1f} %), "
                     f"and the bootstrap replicates split it: {c} in {100 * share:.0f} %, "
                     + ", ".join(f"{k} in {100 * v:.0f} %" for k, v in others.items())
                     + " of them; candidates that stand in for each other in these data (longer or larger records "
                       f"separate them), none reported; the re-calibrated terms absorb it meanwhile; {err}.")
    if not report.findings and not big and not split:
        lines.append(f"Nothing missing that these data resolve: no candidate physics passed the selection rule on any "
                     f"{'cell' if report.given.topology.name == 'chain' else 'DOF'} (an effect too small for this "
                     f"noise, or one these records do not excite, would not show: it is not ruled out); {err}.")
    elif not report.findings and not split:  # the terms moved a lot: they may stand in for what the rule did not admit
        worst = max(big, key=lambda c: abs(c["coefficient"] / c["model_value"]))
        what = _term(worst)
        held = sorted({r["physics"] for s in report.selection for r in s["rejected"]})
        lines.append(f"No new term passed the selection rule, but the model's own terms had to move: {what} by "
                     f"{100 * worst['coefficient'] / worst['model_value']:+.3g} % (more than "
                     f"{100 * LARGE_CORRECTION:g} %, outside its 95 % CI): either the model was mis-calibrated "
                     f"there, or the term stands in for physics the data could not admit on their own"
                     + (f" (not reported below: {', '.join(held)})" if held else "")
                     + f"; not a confirmation that nothing is missing; {err}.")
    for c in report.corrections:
        lo, hi = c["ci95"]
        mv = c["model_value"]
        if _moved(c):
            lines.append(f"  re-calibration, {_cell(report, c['dof'])}: {_term(c)} {_g(mv)} -> "
                         f"{_g(mv + c['coefficient'])} (correction {_g(c['coefficient'])}, 95 % CI "
                         f"{_g(lo)} to {_g(hi)})")
    integ = report.settings.get("integrated") or {}
    for src in sorted({i["from"] for i in integ.values()}):
        names = [n for n, i in integ.items() if i["from"] == src]
        cuts = [c for n in names for c in integ[n]["f_highpass_hz"]]
        lines.append(f"  x integrated from {'velocity' if src == 'v' else 'acceleration'} ({', '.join(names)}): "
                     f"content below {_range(cuts)} Hz removed as drift; the equilibrium offset "
                     + ("was given" if all(integ[n]["equilibrium"] == "given" for n in names) else
                        "is unobservable and was placed by each model's force balance"))
    if b["kind"] == "output" and "horizon_nrmse" in b and "horizon_nrmse" in a:
        why = (f"the {b['on']} crosses between wells ({b['crossings_measured']} crossings; the free runs: "
               f"{b['crossings_model']} before, {a['crossings_model']} after)" if b["crossings_measured"] else
               f"the given model's free run leaves the {b['on']} ({100 * b['nrmse']:.3g} %)")
        lines.append(f"  {why}: a free run can leave a sensitive (chaotic) response even with an exact model, so the "
                     f"models are compared over runs of {b['horizon_s']:.3g} s from the recorded state: NRMSE "
                     f"{100 * b['horizon_nrmse']:.3g} % -> {100 * a['horizon_nrmse']:.3g} %")
    estimated = report.settings.get("derivative_windows")  # estimated derivatives: the intervals are the noise's
    if estimated and (report.findings or any(_moved(c) for c in report.corrections)):
        lines.append("  the 95 % intervals are the noise's (block bootstrap); they leave out the bias that "
                     "derivatives estimated from a noisy signal give least squares (errors in variables): a "
                     "correction of a few % whose interval excludes 0 can be that bias (or stand in for a term the "
                     "rule did not admit), not a mis-calibration (the exact model on x-only records at 20 dB: linear "
                     "stiffness and mass -1 to -2 %)")
    if b["kind"] == "equation" and b.get("why_not_output"):
        lines.append(f"  error measure: equation (force) error, not simulation (output) error: {b['why_not_output']}")
    for w in report.warnings:
        lines.append(f"  warning: {w}")
    for d in report.identifiability:
        if d.mass == "held":
            lines.append(f"  held, {_cell(report, d.dof)}: mass: {d.why}")
        for e in d.not_separable:
            lines.append(f"  not separable, {_cell(report, d.dof)}: {e['physics']} ({e['term']}): {e['reason']}")
    for s in report.selection:
        for r in s["rejected"]:
            lines.append(f"  not reported, {_cell(report, s['dof'])}: {r['physics']} ({r['term']}): {r['reason']}")
    return "\n".join(lines)
