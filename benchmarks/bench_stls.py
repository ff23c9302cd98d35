"""Side-by-side timing of gmr_jax's jitted STLS and pysindy's STLSQ on the same data.

(a) one fit of the 17-term local library Library(5,5) at 2k, 10k and 50k samples of
    small-vibration data (bistable joint, 0.5° base sweep, 60 dB noise);
(b) a 100-threshold sweep over both local datasets (one per equilibrium, 8001 samples each):
    gmr_jax in one jitted call (vmap over datasets and thresholds), pysindy in a Python loop.

gmr_jax's compile time (lower + compile, once per shape/configuration) is reported apart from
its run time; run times are medians of several runs after a warm-up. Both use the package's
default physics solver (normalised columns, no ridge, unbiased refit, max_iter 20), and the
supports and coefficients of every fit are compared.

    python benchmarks/bench_stls.py [--repeats 7] [--out results/bench_stls.md]
"""

import os

os.environ.setdefault("EQX_ON_ERROR", "nan")
# One BLAS thread for both sides: on a small, shared machine a multi-threaded OpenBLAS stalls
# on small least-squares problems (pysindy's lstsq ~100x slower when another process runs).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pysindy as ps  # noqa: E402

import gmr_jax as g  # noqa: E402

RESULTS = Path(__file__).resolve().parents[1] / "results"
# the local fits' solver of `reconstruct`'s paper route; threshold replaced per case; alpha 0, normalised, unbiased
SOLVER = g.STLS(threshold=0.1, alpha=0.0, normalize_columns=True, unbias=True)
LIB = g.Library(5, 5)


def default_thresholds(theta, y, n: int = 40, lo: float = 1e-6):
    """Threshold grid of the automatic rule (`AutoThreshold`): geometric from `lo` to 1 times
    ||y|| (a normalised coefficient is the norm of that term's contribution to y)."""
    return jnp.sqrt(jnp.sum(y**2)) * jnp.geomspace(lo, 1.0, n)


def local_datasets(duration: float):
    """(Θ, y) around each equilibrium of the bistable joint, Θ = Library(5,5)(x - x̄, v)."""
    system = g.systems.bistable_joint("position_independent")
    recs = g.systems.make_recordings(system, np.deg2rad(0.5), duration=duration)
    out = []
    for rec in recs:
        y = g.regression_targets(rec, np.array([1.0]), "independent")[:, 0]
        x, v = rec.x[:, 0], rec.v[:, 0]
        theta = np.asarray(LIB(jnp.asarray(x - x.mean()), jnp.asarray(v)))
        out.append((theta, np.asarray(y)))
    return out


def pysindy_fit(theta, y, threshold):
    opt = ps.STLSQ(threshold=float(threshold), alpha=float(SOLVER.alpha),
                   normalize_columns=SOLVER.normalize_columns, max_iter=SOLVER.max_iter,
                   unbias=SOLVER.unbias)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "eliminated all coefficients" at the top of the sweep
        opt.fit(theta, y[:, None])
    return opt.coef_[0]


def _solver(th):
    return g.STLS(th, jnp.asarray(SOLVER.alpha, float), SOLVER.max_iter, SOLVER.normalize_columns,
                  SOLVER.unbias)


@jax.jit
def gmr_fit(theta, y, th):
    sol = g.stls(theta, y, _solver(th), throw=False)
    return sol.value, sol.stats["support"], sol.result._value


@jax.jit
def gmr_sweep(thetas, ys, ths):
    """Θ (datasets, samples, terms), y (datasets, samples), thresholds (datasets, grid):
    every (dataset, threshold) fit in one call."""

    def one_dataset(theta, y, th_grid):
        def one(th):
            sol = g.stls(theta, y, _solver(th), throw=False)
            return sol.value, sol.stats["support"], sol.result._value

        return jax.vmap(one)(th_grid)

    return jax.vmap(one_dataset)(thetas, ys, ths)


def median_time(fn, repeats: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def compile_time(jitted, *args):
    t0 = time.perf_counter()
    compiled = jitted.lower(*args).compile()
    return time.perf_counter() - t0, compiled


def block(tree):
    return jax.block_until_ready(tree)


def compare(coef_g, support_g, coef_p):
    coef_g = np.asarray(coef_g)
    same_support = np.array_equal(np.asarray(support_g), coef_p != 0)
    scale = max(np.max(np.abs(coef_p)), 1e-300)
    return same_support, float(np.max(np.abs(coef_g - coef_p)) / scale)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--grid", type=int, default=100)
    ap.add_argument("--out", default=str(RESULTS / "bench_stls.md"))
    args = ap.parse_args()
    rows = []

    # ---------------------------------------------------------------- (a) one fit
    t0 = time.perf_counter()
    long = local_datasets(50.0)  # 50001 samples per equilibrium
    theta_all, y_all = long[1]
    print(f"simulated data in {time.perf_counter() - t0:.1f} s")

    for n in (2_000, 10_000, 50_000):
        theta, y = jnp.asarray(theta_all[:n]), jnp.asarray(y_all[:n])
        # the threshold a real local fit would use: blocked CV with the 1-SE rule on these data
        # (normalised coefficients grow like sqrt(n), so one threshold does not fit all sizes)
        sel = g.select_threshold(theta, y, default_thresholds(theta, y, 40), SOLVER)
        threshold = jnp.asarray(sel.value)
        tc, compiled = compile_time(gmr_fit, theta, y, threshold)
        coef, support, code = block(compiled(theta, y, threshold))
        t_g = median_time(lambda: block(compiled(theta, y, threshold)), args.repeats)
        th_np, y_np = theta_all[:n], y_all[:n]
        ref = pysindy_fit(th_np, y_np, threshold)
        t_p = median_time(lambda: pysindy_fit(th_np, y_np, threshold), args.repeats)
        ok, err = compare(coef, support, ref)
        assert int(code) == g.RESULTS.successful._value
        kept = int(np.sum(np.asarray(support)))
        case = f"(a) one fit (threshold {float(threshold):.3g}, {kept}/17 terms kept)"
        rows.append(dict(case=case, n=n, fits=1, compile=tc, run_g=t_g, run_p=t_p,
                         agree=f"{int(ok)}/1", err=err))
        print(rows[-1])

    # ---------------------------------------------------------------- (b) threshold sweep
    local = local_datasets(8.0)  # the paper's recordings: 8 s at 1 kHz around each equilibrium
    thetas = jnp.asarray(np.stack([t for t, _ in local]))
    ys = jnp.asarray(np.stack([y for _, y in local]))
    grids = jnp.stack([default_thresholds(thetas[k], ys[k], args.grid) for k in range(len(local))])
    tc, compiled = compile_time(gmr_sweep, thetas, ys, grids)
    coefs, supports, codes = block(compiled(thetas, ys, grids))
    t_g = median_time(lambda: block(compiled(thetas, ys, grids)), args.repeats)
    grids_np = np.asarray(grids)

    def pysindy_sweep():
        return [[pysindy_fit(theta, y, th) for th in grids_np[k]]
                for k, (theta, y) in enumerate(local)]

    refs = pysindy_sweep()
    t_p = median_time(pysindy_sweep, max(3, args.repeats // 2))
    n_ok, worst = 0, 0.0
    for k in range(len(local)):
        for j in range(args.grid):
            ok, err = compare(coefs[k, j], supports[k, j], refs[k][j])
            n_ok += ok
            worst = max(worst, err)
    n_fits = len(local) * args.grid
    n_distinct = len({tuple(np.asarray(s)) for s in np.asarray(supports).reshape(-1, 17)})
    case = (f"(b) {args.grid}-threshold sweep x {len(local)} datasets "
            f"({n_distinct} distinct supports)")
    rows.append(dict(case=case, n=local[0][0].shape[0], fits=n_fits, compile=tc, run_g=t_g,
                     run_p=t_p, agree=f"{n_ok}/{n_fits}", err=worst))
    print(rows[-1])

    table = render(rows, args.repeats)
    print()
    print(table)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(table)
    print(f"written to {args.out}")
    if any(r["agree"].split("/")[0] != r["agree"].split("/")[1] for r in rows):
        raise SystemExit("supports differ between gmr_jax and pysindy")


def render(rows, repeats):
    def ms(s):
        return f"{1e3 * s:.3g}"

    lines = [
        "# STLS: gmr_jax (jitted) vs pysindy STLSQ",
        "",
        "Generated by `python benchmarks/bench_stls.py`. Data: Library(5,5) (17 terms) on "
        "small-vibration recordings of the bistable joint (0.5° base sweep, 60 dB noise). "
        f"Solver: normalised columns, alpha = {float(SOLVER.alpha)}, unbiased refit, "
        f"max_iter = {SOLVER.max_iter} "
        "(pysindy `STLSQ` with the same settings). Run times are medians of "
        f"{repeats} runs after a warm-up; gmr_jax compile time (lower + compile, paid once per "
        "shape and configuration) is listed apart. Speed-up = pysindy run / gmr_jax run; "
        "'cold' counts gmr_jax's compile as well.",
        "",
        "| case | samples | fits | gmr_jax compile (ms) | gmr_jax run (ms) | pysindy run (ms) "
        "| speed-up | speed-up cold | supports agree | max rel. coef. diff |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['case']} | {r['n']} | {r['fits']} | {ms(r['compile'])} | {ms(r['run_g'])} "
            f"| {ms(r['run_p'])} "
            f"| {r['run_p'] / r['run_g']:.3g}x | {r['run_p'] / (r['run_g'] + r['compile']):.3g}x "
            f"| {r['agree']} | {r['err']:.1e} |"
        )
    load = os.getloadavg() if hasattr(os, "getloadavg") else ("?",)
    lines += [
        "",
        f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs "
        f"(load average {load[0]:.2f} at the end), "
        f"JAX {jax.__version__} on {jax.devices()[0].platform}, "
        f"pysindy {ps.__version__}, numpy {np.__version__}, "
        f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}, "
        f"EQX_ON_ERROR={os.environ.get('EQX_ON_ERROR')}.",
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
