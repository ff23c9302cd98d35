"""Issue 15: the local fits' uncertainty where the accelerations are estimated from x.

With x only, a = x'' comes from a Savitzky-Golay filter: its noise is the sensor's noise passed
through a second-derivative filter, almost all of it far above the vibration's band. Two faults
followed (before the change): the filter's centre weight correlated the target's noise with the
regressor x(t) (the local stiffness biased high), and the ordinary least-squares covariance took
that noise as white (standard errors far too large, so F'' was screened out and the resolution
report called even F' unresolved). `reconstruct(..., structured_noise=True)` differentiates with
the centre sample left out and computes the local covariance with the noise's structure
(`_fit/_target_noise.py`); the "after" rows use it (opt-in), the "before" rows are the commit
before it existed (the defaults of both are the same).

This study checks both against the truth over seeds, for the shallow arch and the magnetic
bistable (`g.systems`), x only with the base acceleration measured, 30 dB on every channel, at
the stress cases' amplitude (most excited well at 0.45 % of the interwell distance) and at a
base amplitude of 0.01; and the same at 60 dB. Per well: F' = the local x coefficient (defaults)
and F'' = 2 x the local x^2 coefficient (`keep_restoring_order=3, screen_sigma=None`, so the
term is kept): the mean estimate / truth, the scatter over seeds (sd / truth), the mean reported
standard error (/ truth), and coverage: how often |estimate - truth| <= 2 standard errors. The
restoring error of the defaults (relative L2 over the metrics box) and the resolution report's
verdict on F' and F'' are tabled beside them.

    python studies/derived_noise.py [--seeds 8] [--json results/data/derived_noise_<label>.json]
        [--before results/data/derived_noise_before.json] [--out results/derived_noise.md]

The "before" JSON: this script run with `--json` (no `--before`) in a worktree of the commit
before the change, `PYTHONPATH` set to that worktree.
"""

import argparse
import inspect
import json
import time
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import gmr_jax as g
from stress_cases import TARGET_RATIO, base_amplitude

SYSTEMS = {"arch": "shallow_arch", "magnet": "magnetic_bistable"}


def taylor(system, x0: float, order: int) -> float:
    """The truth's exact d^order F / dx^order at x0."""
    f = lambda x: system.truth.restoring(jnp.array([x]))[0]  # noqa: E731
    for _ in range(order):
        f = jax.grad(f)
    return float(f(float(x0)))


def x_only(recs):
    return [g.Recording(t=r.t, x=r.x, base_acc=r.base_acc, masses=r.masses, name=r.name) for r in recs]


def fit(recs, **kw):
    if "structured_noise" in inspect.signature(g.reconstruct).parameters:  # absent before the change
        kw["structured_noise"] = True
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return g.reconstruct(recs, throw=False, **kw)


def run(seeds: int) -> list[dict]:
    lib = g.Library(5, 5)
    i1, i2 = lib.terms().index(("stiffness", 1)), lib.terms().index(("stiffness", 2))
    rows = []
    for name, maker in SYSTEMS.items():
        s = getattr(g.systems, maker)()
        for snr, amp, label in ((30.0, base_amplitude(s, TARGET_RATIO), "0.45 %"), (30.0, 0.01, "0.01"),
                                (60.0, base_amplitude(s, TARGET_RATIO), "0.45 %")):
            per = {}
            errs = []
            for seed in range(seeds):
                recs = x_only(g.systems.make_recordings(s, amp, snr_db=snr, seed=seed))
                sol = fit(recs)
                errs.append(g.metrics.restoring_error(sol.value, s.truth, 0, s.x_range[0]))
                rep = sol.stats["dofs"][0]
                res = sol.stats["resolution"]
                kept = fit(recs, keep_restoring_order=3, screen_sigma=None).stats["dofs"][0]
                for w, x0 in enumerate(rep.equilibria):
                    d = per.setdefault(w, {"x0": [], "f1": [], "se1": [], "f2": [], "se2": [], "t1": [], "f1_ok": [],
                                           "f2_ok": [], "advised": []})
                    d["x0"].append(float(x0))
                    d["f1"].append(float(rep.local_coef[w][i1]) / taylor(s, x0, 1))
                    d["se1"].append(float(rep.local_stderr[w][i1]) / abs(taylor(s, x0, 1)))
                    d["f2"].append(2.0 * float(kept.local_coef[w][i2]) / taylor(s, x0, 2))
                    d["se2"].append(2.0 * float(kept.local_stderr[w][i2]) / abs(taylor(s, x0, 2)))
                    terms = {t.order: t for t in res.wells[w].terms}
                    d["f1_ok"].append(bool(terms[1].significant and terms[1].bounded))
                    d["f2_ok"].append(bool(terms[2].significant and terms[2].bounded))
                    d["advised"].append(terms[2].advised_ratio)
            rows.append({"system": name, "snr": snr, "amplitude": label, "errors": errs, "wells": per})
    return rows


def cover(est, se):
    est, se = np.asarray(est), np.asarray(se)
    return float(np.mean(np.abs(est - 1.0) <= 2.0 * se))


def _row(label, d):
    f1, se1, f2, se2 = (np.asarray(d[k]) for k in ("f1", "se1", "f2", "se2"))
    adv = [a for a in d["advised"] if a is not None]
    return (f"{label} | {f1.mean():.4f} | {f1.std():.4f} | {se1.mean():.4f} | {cover(f1, se1):.2f} | "
            f"{f2.mean():.3f} | {f2.std():.3f} | {se2.mean():.3g} | {cover(f2, se2):.2f} | "
            f"{np.mean(d['f1_ok']):.2f} / {np.mean(d['f2_ok']):.2f} | "
            f"{(f'{100 * np.median(adv):.2g} %' if adv else '-')}")


def write(rows, before, seeds, secs, out: Path):
    lines = ["# Local fits with estimated accelerations: bias and calibrated uncertainty", "",
             f"`python studies/derived_noise.py --seeds {seeds}" + (" --before ..." if before else "") + "`"
             f" ({secs / 60:.1f} min on the shared 2-core dev machine).", "",
             __doc__.split("\n\n")[2].replace("\n", " "), "",
             "Columns per well (x only, base acceleration measured): F' estimate / truth (mean over seeds), its "
             "scatter (sd / truth), the reported standard error (mean, / truth), coverage of +-2 se; the same for "
             "F'' (x^2 kept, unscreened); how often the resolution report calls F' and F'' resolved (t >= 3 and "
             "bound <= 2 %); the median advised amplitude for F'' (% of the interwell distance). "
             "Rows marked *before* are the commit before the change; the others use `structured_noise=True`.", ""]
    for k, r in enumerate(rows):
        b = before[k] if before else None
        lines += [f"## {r['system']}, {r['snr']:g} dB, amplitude {r['amplitude']}", "",
                  "Restoring error of the defaults (per seed): "
                  + ", ".join(f"{100 * e:.2f} %" for e in r["errors"])
                  + (" (before: " + ", ".join(f"{100 * e:.2f} %" for e in b["errors"]) + ")" if b else ""), "",
                  "| well | F' mean | F' sd | F' se | F' cover | F'' mean | F'' sd | F'' se | F'' cover | "
                  "resolved F' / F'' | advised for F'' |", "|---|---|---|---|---|---|---|---|---|---|---|"]
        for w, d in sorted(r["wells"].items(), key=lambda kv: int(kv[0])):
            x0 = np.mean(d["x0"])
            lines.append("| " + _row(f"x = {x0:.4g}", d) + " |")
            if b:
                lines.append("| " + _row("*before*", b["wells"][str(w)]) + " |")
        lines.append("")
    out.write_text("\n".join(lines) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--before", type=Path)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    t0 = time.time()
    rows = run(args.seeds)
    secs = time.time() - t0
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(rows, indent=1))
    if args.out:
        before = json.loads(args.before.read_text()) if args.before else None
        write(json.loads(json.dumps(rows)), before, args.seeds, secs, args.out)
    for r in rows:
        print(r["system"], r["snr"], r["amplitude"], "errors", [round(100 * e, 2) for e in r["errors"]])
        for w, d in r["wells"].items():
            print("   ", _row(f"well {w}", d))


if __name__ == "__main__":
    main()
