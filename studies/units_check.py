"""The units checks (`gmr.unit_checks`, which `reconstruct` runs) over the built-in systems.

Every built-in system's base-sweep records (noise-free, 60, 45 and 30 dB; seeds 0-1; x, v, a measured or x
alone), rewritten as the same motion driven by a force on each mass (force_k = -m_k base_acc, a relative to the
base: the equation of motion is unchanged), are checked as given (a false alarm is any report) and with their
lengths in the wrong unit: x, v, a scaled by 1000 (mm written as m) and by 1e-3 (m written as mm), the force and
the masses as they were (each must be reported, with the factor named). The margin: the smallest of the
factors `MARGINS` at which the check still says nothing about a clean record (the default is 3).

    python -m studies.units_check            # writes results/units_check.md
"""

import argparse
import time
from pathlib import Path

import numpy as np

import gmr_jax as g

#: the factor the check uses by default, and the stricter ones the clean records are also tried at
DEFAULT_FACTOR = 3.0
MARGINS = (1.01, 1.02, 1.05, 1.1, 1.25, 1.5, 2.0, DEFAULT_FACTOR)


def cases():
    """(label, system, base amplitude): the paper's cases at the demo's amplitudes, the non-polynomial bistables
    at 0.45 % of their interwell distance, the Kresling chains at their default amplitudes."""
    from studies.stress_cases import base_amplitude

    out = [(f"bistable joint ({d}), {deg:g} deg", g.systems.bistable_joint(d), np.deg2rad(deg))
           for d in ("position_independent", "position_dependent") for deg in (0.5, 5.0)]
    out.append(("tri-stable NES, 0.5 mm", g.systems.tristable_nes(), 5e-4))
    for name, make in (("shallow arch", g.systems.shallow_arch), ("magnetic bistable", g.systems.magnetic_bistable)):
        s = make()
        out.append((f"{name}, 0.45 %", s, base_amplitude(s, 0.0045)))
    out.append(("Kresling 3-cell chain", g.systems.kresling3(), g.systems.KRESLING3_AMPLITUDE))
    out.append(("Kresling 5-cell chain", g.systems.kresling5(), g.systems.KRESLING5_AMPLITUDE))
    return out


def force_driven(rec, sensing: str, scale: float = 1.0):
    """The record as the same motion under a force on each mass; lengths times `scale`; `sensing` "xva" or "x"."""
    m = np.asarray(rec.masses, float)
    b = np.asarray(rec.base_acc, float)
    a = (np.asarray(rec.a, float) - b[:, None]) * scale
    return g.Recording(t=rec.t, x=np.asarray(rec.x) * scale, v=None if sensing == "x" else np.asarray(rec.v) * scale,
                     a=None if sensing == "x" else a, force=-b[:, None] * m[None, :], masses=m, name=rec.name)


def run(seeds=(0, 1), snrs=(None, 60.0, 45.0, 30.0)):
    rows = []
    for label, system, amp in cases():
        for snr in snrs:
            for seed in seeds:
                recs = g.systems.make_recordings(system, amp, snr_db=snr, seed=seed)
                for sensing in ("xva", "x"):
                    for scale in (1.0, 1e3, 1e-3):
                        for r in recs:
                            rec = force_driven(r, sensing, scale)
                            msgs = g.unit_checks([rec])
                            silent = None if scale != 1.0 else next(
                                (f for f in MARGINS if not g.unit_checks([rec], factor=f)), None)
                            rows.append({"case": label, "snr": snr, "seed": seed, "sensing": sensing, "scale": scale,
                                         "dofs": rec.n_dof, "reported": len(msgs),
                                         "named": sum(f"factor {scale:g})" in m for m in msgs), "msgs": msgs,
                                         "silent_from": silent if scale == 1.0 else None})
    return rows


def _worst(rows) -> str:
    """The strictest factor at which every clean record of `rows` stays silent."""
    got = [r["silent_from"] for r in rows if r["scale"] == 1.0]
    return "never" if any(f is None for f in got) else f"{max(got):g}"


def report(rows, secs: float) -> str:
    lines = ["# Units check: the force balance against the units and masses given", "",
             "`python -m studies.units_check` (" + time.strftime("%Y-%m-%d") + f", {secs:.0f} s on 2 cores). Every "
             "built-in system's base sweeps (seeds 0-1; noise-free, 60, 45, 30 dB; x, v and a measured, or x alone "
             "with v and a estimated), rewritten as the same motion under a force on each mass, checked by "
             "`gmr.unit_checks` (the checks `reconstruct` and `gmr fit` run; the force balance on every force-driven record): as "
             "given, then with x, v and a 1000 times too large (mm written as m) and 1000 times too small (m written "
             "as mm), the force and the masses unchanged. Counts are per DOF (a chain's cells each).", "",
             "| case | records x DOFs checked | clean records silent from factor | false alarms (as given) "
             "| mm as m: named 1000 | m as mm: named 0.001 |",
             "|---|---|---|---|---|---|"]
    tot = {"n": 0, "fa": 0, "up": 0, "down": 0}
    for case in dict.fromkeys(r["case"] for r in rows):
        sub = [r for r in rows if r["case"] == case]
        n = sum(r["dofs"] for r in sub if r["scale"] == 1.0)
        fa = sum(r["reported"] for r in sub if r["scale"] == 1.0)
        up = sum(r["named"] for r in sub if r["scale"] == 1e3)
        down = sum(r["named"] for r in sub if r["scale"] == 1e-3)
        tot = {"n": tot["n"] + n, "fa": tot["fa"] + fa, "up": tot["up"] + up, "down": tot["down"] + down}
        lines.append(f"| {case} | {n} | {_worst(sub)} | {fa} | {up} / {n} | {down} / {n} |")
    lines.append(f"| **all** | {tot['n']} | {_worst(rows)} | {tot['fa']} | {tot['up']} / {tot['n']} | "
                 f"{tot['down']} / {tot['n']} |")
    lines += ["", f"The check reports a force balance whose inertia factor is off by more than {DEFAULT_FACTOR:g} "
              "either way (`unit_checks(factor=...)`); 'silent from' is the strictest factor of "
              f"{', '.join(f'{f:g}' for f in MARGINS)} at which every clean record of the row still passes."]
    example = next((m for r in rows if r["scale"] == 1e3 for m in r["msgs"]), None)
    if example:
        lines += ["", "The sentence, on the first record with mm written as m:", "", f"> {example}"]
    alarms = [m for r in rows if r["scale"] == 1.0 for m in r["msgs"]]
    if alarms:
        lines += ["", "False alarms:", ""] + [f"- {m}" for m in alarms]
    missed = [r for r in rows if r["scale"] != 1.0 and r["named"] < r["dofs"]]
    if missed:
        lines += ["", "Not named (case, SNR, seed, sensing, scale, what was said):", ""]
        lines += [f"- {r['case']}, {r['snr']} dB, seed {r['seed']}, {r['sensing']}, x{r['scale']:g}: "
                  f"{r['msgs'] or 'nothing'}" for r in missed]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default="results/units_check.md")
    p.add_argument("--seeds", type=int, default=2)
    a = p.parse_args()
    t0 = time.time()
    rows = run(seeds=tuple(range(a.seeds)))
    Path(a.out).write_text(report(rows, time.time() - t0))
    print(Path(a.out).read_text())
