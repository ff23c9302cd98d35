"""Wall time of `gmr fit` from the shell, cold and warm, next to a plain pysindy script (issue 16).

Two recordings of the bistable joint (paper case, 5 deg, 60 dB, 8001 samples each, NPZ) are
written to a temporary folder; then, each in a fresh process:

- `gmr fit` cold: an empty cache folder (`GMR_CACHE_DIR`), everything traced and compiled;
- `gmr fit` warm: the same command again (`--reps` times; median), compiled programs and traced
  fits loaded from the cache;
- `python -c "import gmr_jax"`: the import alone;
- a pysindy script: load both files, fit a SINDy model (PolynomialLibrary degree 5 on (x, v),
  STLSQ) to each, print the equations: what a pysindy user would write for the local fits.

    python benchmarks/bench_fit_cli.py [--reps 3] [--out results/bench_fit_cli.md]

The machine's load average is recorded with the times: on a shared machine they are an upper
bound of what a quiet one gives.
"""

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

PYSINDY_SCRIPT = """
import sys, time
t0 = time.perf_counter()
import numpy as np
import pysindy as ps
t1 = time.perf_counter()
for path in sys.argv[1:]:
    d = np.load(path)
    X = np.column_stack([d["x"][:, 0], d["v"][:, 0]])
    xdd = d["a"][:, 0] - (np.ravel(d["base_acc"]) if "base_acc" in d.files else 0.0)  # relative acceleration
    Xd = np.column_stack([d["v"][:, 0], xdd])
    m = ps.SINDy(feature_library=ps.PolynomialLibrary(degree=5), optimizer=ps.STLSQ(threshold=0.05))
    m.fit(X, t=float(d["t"][1] - d["t"][0]), x_dot=Xd)
    m.print()
print(f"pysindy import {t1 - t0:.3f} s, fits {time.perf_counter() - t1:.3f} s", file=sys.stderr)
"""


def gmr_command() -> list[str]:
    exe = Path(sys.executable).with_name("gmr")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "gmr_jax"]


def timed(cmd, env) -> tuple[float, float]:
    """(wall, CPU) seconds of one run in a fresh process; CPU = the child's user + system time,
    which a busy machine inflates far less than the wall time."""
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    r = subprocess.run(cmd, env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({r.returncode}):\n{r.stderr[-2000:]}")
    return dt, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def median_run(cmd, env, reps):
    runs = [timed(cmd, env) for _ in range(reps)]
    return statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs), runs


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--reps", type=int, default=3, help="warm runs (median reported)")
    p.add_argument("--out", default="results/bench_fit_cli.md")
    args = p.parse_args()

    import numpy as np

    import gmr_jax as gmr

    work = Path(tempfile.mkdtemp(prefix="gmr_bench_fit_"))
    recs = gmr.systems.make_recordings(gmr.systems.bistable_joint(), float(np.deg2rad(5.0)), seed=0)
    files = []
    for i, r in enumerate(recs):
        files.append(str(work / f"joint_S{i + 1}.npz"))
        gmr.save_recording(r, files[-1])
    n = recs[0].t.shape[0]
    env = dict(os.environ, GMR_CACHE_DIR=str(work / "cache"), GMR_PROGRESS="0")
    fit = gmr_command() + ["fit", *files, "--out", str(work / "model.json")]
    load0 = os.getloadavg()[0]
    rows = []
    rows.append(("`gmr fit` cold (empty cache)", *timed(fit, env)))
    w, wc, warm = median_run(fit, env, args.reps)
    rows.append((f"`gmr fit` warm (median of {args.reps})", w, wc))
    nf, nfc, _ = median_run(fit + ["--no-figure"], env, args.reps)
    rows.append((f"`gmr fit --no-figure` warm (median of {args.reps})", nf, nfc))
    im, imc, _ = median_run([sys.executable, "-c", "import gmr_jax"], env, args.reps)
    rows.append(("`import gmr_jax` alone", im, imc))
    ps, psc, _ = median_run([sys.executable, "-c", PYSINDY_SCRIPT, *files], env, args.reps)
    rows.append((f"pysindy script: import + 2 local fits (median of {args.reps})", ps, psc))
    load1 = os.getloadavg()[0]
    shutil.rmtree(work, ignore_errors=True)

    lines = [
        "# `gmr fit` from the shell: cold and warm, next to a pysindy script",
        "",
        f"Command: `python benchmarks/bench_fit_cli.py --reps {args.reps}` ({os.cpu_count()} CPUs, load average "
        f"{load0:.1f} at start, {load1:.1f} at end; each row a fresh process). Wall time, and CPU time (user + "
        "system of the process): on a busy machine the wall time is inflated by waiting for a core, the CPU "
        "time much less; on a quiet machine a mostly single-threaded run's wall time is about its CPU time.",
        "",
        f"Data: two recordings of the bistable joint (5 deg, 60 dB, {n} samples each, NPZ). `gmr fit` runs "
        "the default reconstruction (one posterior of both wells' records, its hyperparameters and degree by the "
        "evidence, the covariance, the sanity checks), writes the model and its figure (PNG and PDF); the pysindy "
        "script fits PolynomialLibrary(5) on (x, v) with STLSQ(0.05) to each file (the two local fits only: no "
        "global law, no threshold search, no figure).",
        "",
        "| run | wall time (s) | CPU time (s) |",
        "|---|---:|---:|",
        *[f"| {name} | {t:.2f} | {c:.2f} |" for name, t, c in rows],
        "",
        f"Warm `gmr fit` / pysindy script: {rows[1][1] / rows[4][1]:.2f}x wall, {rows[1][2] / rows[4][2]:.2f}x CPU. "
        "Warm runs (wall, CPU): " + ", ".join(f"{t:.2f}/{c:.2f}" for t, c in warm) + " s.",
        "",
    ]
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
