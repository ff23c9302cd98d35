"""Issue 15: the paper cases before and after the issue-15 work, GMC-SINDy beside every row.

"Before" is commit 47c727d, the last commit before the auto-coordination / joint-route work
(e13ec6c started it); "after" is the working tree. The same cases, data and measures as
`studies/paper_cases.py` (`run_case`): each code version runs in its own process with its
own `gmr_jax` first on PYTHONPATH, so the two never mix.

    git worktree add /tmp/before 47c727d
    git worktree add /tmp/after HEAD     # optional: 'after' without other people's uncommitted edits
    python studies/paper_cases_before_after.py --before /tmp/before --after /tmp/after --seeds 3 \
        --kresling-seeds 1 [--cases single,kresling] [--reuse] [--out results/paper_cases_before_after.md]

`--worker JSON` is the per-version process (it writes the rows of every case and seed).
"""

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BEFORE_COMMIT = "47c727d"


KRESLING = ("kresling3", "kresling5")


def kresling_rows(seeds: int, record) -> list:
    """The Kresling chains of the paper (Sec. 3.2 five cells, Sec. 4 three cells) at their nominal
    base amplitude: per cell, GMR (default orders 5, 5) and GMC-SINDy (the system's orders)."""
    import gmr_jax as g

    rows = []
    for name in KRESLING:
        system = getattr(g.systems, name)()
        amp = {"kresling3": g.systems.KRESLING3_AMPLITUDE, "kresling5": g.systems.KRESLING5_AMPLITUDE}[name]
        for s in range(seeds):
            t0 = time.time()
            recs = g.systems.make_recordings(system, amp, seed=s)
            sol = record(recs, g.Library(*system.orders["gmr"]))
            gmr = sol.value
            gmc = g.gmc_sindy(recs, g.Library(*system.orders["gmc"])).value
            for i in range(system.truth.n_dof):
                row = {"description": f"{name} cell {i}", "label": f"{amp * 1e3:g} mm", "seed": s,
                       "route": str(sol.stats["dofs"][i].stats.get("coordination", "-")), "secs": time.time() - t0,
                       "gmr_jax": _where(),
                       "amplitude_ratio": float(max(np.percentile(np.abs(r.x[:, i] - r.x[:, i].mean()), 99.9)
                                                    for r in recs) / float(np.ptp(system.equilibria[:, i])))}
                for meth, model in (("gmr", gmr), ("gmc", gmc)):
                    row[meth] = {"restoring_error": g.metrics.restoring_error(model, system.truth, i, system.x_range[i]),
                                 "damping_error": g.metrics.damping_error(model, system.truth, i, system.x_range[i],
                                                                          system.v_range[i]),
                                 "equilibria_ok": None}
                rows.append(row)
            print(f"{name} seed {s}: GMR cells " + ", ".join(f"{100 * r['gmr']['restoring_error']:.3g} %"
                                                              for r in rows[-system.truth.n_dof:])
                  + f" ({time.time() - t0:.0f} s)", flush=True)
    return rows


def _where() -> str:
    """The folder of the gmr_jax this process imported."""
    import importlib.util

    return str(Path(importlib.util.find_spec("gmr_jax").origin).parent)


def worker(path: str, seeds: int, kresling: bool = False) -> None:
    import warnings

    import gmr_jax as g
    import paper_cases as pc

    routes = []
    plain = g.reconstruct

    def recording(*a, **k):  # note the route each DOF's coordination took (stats of "after" only)
        sol = plain(*a, **k)
        routes.append(",".join(str(d.stats.get("coordination", "-")) for d in sol.stats["dofs"]))
        return sol

    g.reconstruct = recording
    rows = []
    if kresling:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rows = kresling_rows(seeds, recording)
        return Path(path).write_text(json.dumps(rows))
    for factory, amp, label in pc.default_cases():
        for s in range(seeds):
            t0 = time.time()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                row = pc.run_case(factory(), amp, label, seed=s)
            row |= {"route": routes[-1], "label": label, "seed": s, "secs": time.time() - t0, "gmr_jax": _where()}
            rows.append(row)
            print(f"{row['description'][:40]:40s} {label:7s} seed {s} GMR {100 * row['gmr']['restoring_error']:.4g} % "
                  f"GMC {100 * row['gmc']['restoring_error']:.4g} % ({row['secs']:.0f} s)", flush=True)
    Path(path).write_text(json.dumps(rows))


def _run(tree: Path, seeds: int, out: Path, part: str, reuse: bool) -> list:
    if not (reuse and out.exists()):
        env = dict(os.environ, PYTHONPATH=f"{tree}{os.pathsep}{ROOT / 'studies'}", JAX_PLATFORMS="cpu")
        subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker", str(out), "--seeds", str(seeds)]
                       + (["--kresling"] if part == "kresling" else []), env=env, check=True, cwd=str(tree))
    return json.loads(out.read_text())


def _commit(tree) -> str:
    """The short commit a checkout is at (what its rows were computed with)."""
    return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=tree, capture_output=True,
                          text=True).stdout.strip()


def _stat(rows, meth, key):
    v = np.array([r[meth][key] for r in rows]) * 100
    return f"{np.median(v):.3g} % [{v.max():.3g} %]"


def _eq(rows, meth):
    if any(r[meth]["equilibria_ok"] is None for r in rows):
        return "-"
    return f"{sum(r[meth]['equilibria_ok'] for r in rows)}/{len(rows)}"


def table(before: list, after: list, args, secs: float, commit: str = "", worktree: bool = False) -> str:
    seeds = args.seeds
    lines = [
        "# Paper cases before and after (GMR, GMC-SINDy beside every row)", "",
        f"`python studies/paper_cases_before_after.py --before /tmp/before{' --after /tmp/after' if worktree else ''} "
        f"--seeds {seeds} --kresling-seeds {args.kresling_seeds}` ({secs / 60:.1f} min on the shared 2-core dev "
        f"machine{', rows of earlier runs reused' if args.reuse else ''}); /tmp/before is a `git worktree` of "
        f"{_commit(args.before)}, the last commit before the auto-coordination / joint-route work; 'after' is "
        f"{commit}{' (a clean worktree of it)' if worktree else ''}.", "",
        f"Single-DOF cases, data and measures of `studies/paper_cases.py` ({seeds} noise seeds at 60 dB, median "
        f"[max]); the Kresling chains (paper Secs. 3.2 and 4) at their nominal base amplitude, per cell, "
        f"{args.kresling_seeds} seed(s), metrics box of the system: "
        "restoring error relative L2 over the box, damping error relative L2 over the phase-plane box, "
        "equilibria = all zeros of F_r and their stability reproduced (seeds ok / total). GMC-SINDy's code is the "
        "same before and after; it is run by both versions and its 'after' value is shown.", "",
        "| case | amplitude | GMR restoring before | GMR restoring after | GMR damping before | GMR damping after | "
        "GMR equilibria before / after | GMC-SINDy restoring | GMC-SINDy damping | GMC-SINDy equilibria | "
        "route after | worse? |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    keys = sorted({(r["description"], r["label"]) for r in after}, key=lambda k: [r["description"] for r in after]
                  .index(k[0]) * 100 + [r["label"] for r in after].index(k[1]))
    worse_rows = []
    for desc, label in keys:
        b = [r for r in before if (r["description"], r["label"]) == (desc, label)]
        a = [r for r in after if (r["description"], r["label"]) == (desc, label)]
        routes = sorted({x.get("route", "-") for x in a})
        worse = []
        for key in ("restoring_error", "damping_error"):
            vb, va = (np.array([r["gmr"][key] for r in rows]) for rows in (b, a))
            # worse: the median or the max more than 10 % (relative) and 1e-5 (absolute) above before
            if any(y > 1.1 * x and y - x > 1e-5 for x, y in ((np.median(vb), np.median(va)), (vb.max(), va.max()))):
                worse.append(key.split("_")[0])
        if sum(bool(r["gmr"]["equilibria_ok"]) for r in a) < sum(bool(r["gmr"]["equilibria_ok"]) for r in b):
            worse.append("equilibria")
        gmc_same = all(abs(x["gmc"]["restoring_error"] - y["gmc"]["restoring_error"]) < 1e-12 for x, y in zip(b, a))
        lines.append(
            f"| {desc} | {label} ({100 * a[0]['amplitude_ratio']:.1f} %) | {_stat(b, 'gmr', 'restoring_error')} | "
            f"{_stat(a, 'gmr', 'restoring_error')} | {_stat(b, 'gmr', 'damping_error')} | "
            f"{_stat(a, 'gmr', 'damping_error')} | {_eq(b, 'gmr')} / {_eq(a, 'gmr')} | "
            f"{_stat(a, 'gmc', 'restoring_error')}{'' if gmc_same else ' (differs before)'} | "
            f"{_stat(a, 'gmc', 'damping_error')} | {_eq(a, 'gmc')} | {', '.join(routes)} | "
            f"{', '.join(worse) if worse else 'no'} |")
        if worse:
            worse_rows.append((desc, label, worse, b, a))
    lines.append("")
    if not worse_rows:
        lines.append("No row got worse (median and max within 10 % or 1e-5 absolute of before).")
    for desc, label, worse, b, a in worse_rows:
        per = "; ".join(f"seed {x['seed']}: restoring {100 * x['gmr']['restoring_error']:.3g} % -> "
                        f"{100 * y['gmr']['restoring_error']:.3g} %, damping {100 * x['gmr']['damping_error']:.3g} % -> "
                        f"{100 * y['gmr']['damping_error']:.3g} %" for x, y in zip(b, a))
        lines.append(f"- Worse: {desc}, {label} ({', '.join(worse)}): {per}.")
    return "\n".join(lines) + "\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", default="/tmp/before", help=f"a checkout of {BEFORE_COMMIT}")
    ap.add_argument("--after", default=str(ROOT), help="the checkout to run as 'after' (default: this tree; a "
                    "`git worktree add /tmp/after HEAD` keeps other people's uncommitted edits out)")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "results" / "paper_cases_before_after.md"))
    ap.add_argument("--cases", default="single,kresling", help="single: the single-DOF paper cases of "
                    "studies/paper_cases.py; kresling: the 3- and 5-cell Kresling chains at their nominal amplitude")
    ap.add_argument("--kresling-seeds", type=int, default=1)
    ap.add_argument("--reuse", action="store_true", help="reuse the rows a previous run left in --json-dir")
    ap.add_argument("--json-dir", default=os.environ.get("TMPDIR", "/tmp"))
    ap.add_argument("--kresling", action="store_true", help="internal: the worker runs the Kresling part")
    ap.add_argument("--worker", help="internal: run the cases with the gmr_jax on PYTHONPATH, rows to this JSON")
    args = ap.parse_args()
    if args.worker:
        return worker(args.worker, args.seeds, args.kresling)
    t0 = time.time()
    tmp = Path(args.json_dir)
    before, after = [], []
    for part in args.cases.split(","):
        seeds = args.seeds if part == "single" else args.kresling_seeds
        before += _run(Path(args.before), seeds, tmp / f"paper_cases_{part}_before_s{seeds}.json", part,
                       args.reuse)
        after += _run(Path(args.after), seeds, tmp / f"paper_cases_{part}_after_s{seeds}.json", part,
                      args.reuse)
    assert all(r["gmr_jax"].startswith(str(Path(args.after).resolve())) for r in after)
    assert all(r["gmr_jax"].startswith(str(Path(args.before).resolve())) for r in before)
    commit = _commit(args.after)
    text = table(before, after, args, time.time() - t0, commit, args.after != str(ROOT))
    Path(args.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
