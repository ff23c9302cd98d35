"""Issue 15: recordings without their velocity channel (displacement and acceleration measured,
v estimated from x), against the same data with v measured.

For the shallow arch and the magnetic bistable (`g.systems`), at 60 dB and 30 dB, at the stress
cases' amplitude (most excited well at 0.45 % of the interwell distance, `stress_cases.py`) and
at a base amplitude of 0.01: `make_recordings(system, amp, snr_db, seed)` for 4 seeds,
`reconstruct` with the defaults on (x, a) and on (x, v, a); restoring error (relative L2 over
the system's metrics box, `metrics.restoring_error`), per seed, and the route taken.

    python studies/sensing_xa.py [--seeds 4] [--json results/data/sensing_xa_<label>.json]
        [--before results/data/sensing_xa_before.json] [--out results/sensing_xa.md]

The "before" JSON: this script run with `--json` (no `--before`) in a worktree of the commit
before the change (f78d53f), `PYTHONPATH` set to that worktree.
"""

import argparse
import json
import time
import warnings
from pathlib import Path

import numpy as np

import gmr_jax as g
from stress_cases import TARGET_RATIO, base_amplitude

SYSTEMS = {"arch": "shallow_arch", "magnet": "magnetic_bistable"}


def run(seeds: int) -> list[dict]:
    rows = []
    for name, maker in SYSTEMS.items():
        s = getattr(g.systems, maker)()
        for snr, amp in ((60.0, 0.01), (30.0, base_amplitude(s, TARGET_RATIO)), (30.0, 0.01)):
            for sensing in ("xa", "xva"):
                errs, routes = [], []
                for seed in range(seeds):
                    recs = g.systems.make_recordings(s, amp, snr_db=snr, seed=seed)
                    if sensing == "xa":
                        recs = [g.Recording(t=r.t, x=r.x, a=r.a, base_acc=r.base_acc, masses=r.masses, name=r.name)
                                for r in recs]
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        res = g.reconstruct(recs)
                    errs.append(100 * float(g.metrics.restoring_error(res.value, s.truth, 0, s.x_range[0])))
                    routes.append(res.stats["dofs"][0].stats["coordination"])
                rows.append(dict(system=name, snr=snr, amp=float(amp), sensing=sensing, errors=errs, routes=routes))
                print(name, snr, f"{amp:.3g}", sensing, " ".join(f"{e:.2f}" for e in errs), flush=True)
    return rows


def table(rows: list[dict], before: list[dict] | None) -> str:
    key = lambda r: (r["system"], r["snr"], round(r["amp"], 12), r["sensing"])  # noqa: E731
    old = {key(r): r for r in before or []}
    head = "| system | SNR | base amplitude | sensing | restoring error per seed (%) | median | routes |"
    sep = "|---|---:|---:|---|---|---:|---|"
    if before is not None:
        head = ("| system | SNR | base amplitude | sensing | before: error per seed (%) | before: median | "
                "after: error per seed (%) | after: median | routes after |")
        sep = "|---|---:|---:|---|---|---:|---|---:|---|"
    out = [head, sep]
    for r in rows:
        cells = [r["system"], f"{r['snr']:g} dB", f"{r['amp']:.3g}", r["sensing"]]
        fmt = lambda e: ", ".join(f"{x:.2f}" for x in e)  # noqa: E731
        if before is not None:
            b = old.get(key(r))
            cells += [fmt(b["errors"]) if b else "-", f"{np.median(b['errors']):.2f}" if b else "-"]
        cells += [fmt(r["errors"]), f"{np.median(r['errors']):.2f}", ", ".join(sorted(set(r["routes"])))]
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out)


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--seeds", type=int, default=4)
    p.add_argument("--json")
    p.add_argument("--before")
    p.add_argument("--out")
    a = p.parse_args()
    t0 = time.perf_counter()
    rows = run(a.seeds)
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps(rows, indent=1))
    before = json.loads(Path(a.before).read_text()) if a.before else None
    text = table(rows, before)
    print(text)
    if a.out:
        Path(a.out).write_text(
            "# Recordings without their velocity channel\n\n"
            f"`python studies/sensing_xa.py --seeds {a.seeds}"
            + (f" --before {a.before}" if a.before else "") + (f" --out {a.out}`" if a.out else "`")
            + f" ({time.perf_counter() - t0:.0f} s on the shared 2-core dev machine). "
            + (__doc__.split("\n\n")[1].replace("\n", " ") + "\n\n") + text + "\n")


if __name__ == "__main__":
    main()
