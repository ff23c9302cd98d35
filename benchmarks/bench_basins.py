"""Side-by-side timing of gmr_jax's `basin_map` and a loop of scipy `solve_ivp` on deployment-basin
sweeps (paper Fig. 11) of polynomial double-well chains with 3, 5 and 10 cells.

Both sides integrate the same problem: chain topology, cell i with
F_i(x, v) = k1_i x + k3_i x^3 + c v (k1_i < 0 < k3_i, graded from cell to cell), masses m, the
paper's Eq. (25) tip load A sin(2 pi f t) for t <= 1/(2f) and 0 after, from rest in every
cell's first well, up to t1 = 1/(2f) + settle_time, at rtol 1e-6 / atol 1e-8. gmr_jax uses Tsit5
with PID control and the switch-off time declared to the controller (its only method); scipy
integrates in two pieces, [0, 1/(2f)] with the load and [1/(2f), t1] without, with RK45 and
with DOP853. Both final states go through the same classifier
(`gmr_jax.basins._sweep.classify`, vmapped) into wells and a configuration code.

Measured:
- scipy on a random subset of the grid (per point, both methods), the classification
  agreement with the gmr_jax sweep on the same points, and the per-point speed ratio;
- gmr_jax: compile time apart from run time (a cold call, then a warm call with different f/A
  values on a grid of the same size), throughput, cost vs grid size (1e2 .. 1e5 points, 5
  cells), vs number of cells (3, 5, 10; 1e4 points) and vs `chunk` (256, 512, 1024), plus one
  experiment with the points ordered by f (short t1 together) through the private
  `_sweep_points`, to size the lockstep cost.

    python benchmarks/bench_basins.py            # full, ~10 min on a 2-core machine
    python benchmarks/bench_basins.py --quick    # ~2 min: 1e2/1e3 grids, 50 scipy points/system
"""

import os

os.environ["EQX_ON_ERROR"] = "nan"

import argparse  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

import gmr_jax as g  # noqa: E402  (enables float64)
from gmr_jax.basins import _sweep  # noqa: E402
from gmr_jax.basins._sweep import SweepSettings, basin_map, classify  # noqa: E402
from gmr_jax.basins._wells import stable_wells  # noqa: E402

# ---------------------------------------------------------------------------------------------
# Systems: n-cell chains, stiffness graded linearly from the base (softest) to the tip (stiffest).
MASS = 0.05  # kg, every cell
DAMPING = 1.0  # N s/m, viscous, every cell (enough for the 10-cell chain's slow mode to settle)
WELL = 0.03  # m: wells at x = ±WELL in every cell (k3 = -k1 / WELL^2)
K1 = (8.0, 24.0)  # -k1 from the base cell to the tip cell, N/m
F_RANGE = (0.1, 5.0)  # Hz
A_RANGE = (0.02, 0.6)  # N
SETTINGS = SweepSettings()  # settle_time 10 s, rtol 1e-6, atol 1e-8, x_tol 0.1, v_tol 0.05
CELLS = (3, 5, 10)
SCALING_CELLS = 5
FC = 2.0 / (3.0 * np.sqrt(3.0))  # static snap-through load = FC * |k1| * WELL


def chain_coefficients(n):
    k1 = -np.linspace(*K1, n)
    return k1, -k1 / WELL**2


def make_model(n):
    k1, k3 = chain_coefficients(n)
    terms = []
    for i in range(n):
        terms += [{"dof": i, "physics": "stiffness", "order": 1, "coefficient": float(k1[i])},
                  {"dof": i, "physics": "stiffness", "order": 3, "coefficient": float(k3[i])},
                  {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": DAMPING}]
    return g.from_terms([MASS] * n, terms, "chain")


def grid(n_points, shift=0.0):
    """(f, A) axes with n_points points; `shift` > 0 moves the ends inwards by that fraction of
    a grid step (same size, different values: the warm call)."""
    shapes = {100: (10, 10), 1000: (40, 25), 10_000: (100, 100), 100_000: (400, 250)}
    nf, na = shapes[n_points]
    df = (F_RANGE[1] - F_RANGE[0]) / (nf - 1)
    da = (A_RANGE[1] - A_RANGE[0]) / (na - 1)
    f = np.linspace(F_RANGE[0] + shift * df, F_RANGE[1] - shift * df, nf)
    a = np.linspace(A_RANGE[0] + shift * da, A_RANGE[1] - shift * da, na)
    return jnp.asarray(f), jnp.asarray(a)


# ---------------------------------------------------------------------------------------------
# scipy side
def numpy_rhs(n):
    """dy/dt for y = (x, v) of the chain under a tip force P (same equations as
    `GlobalModel.accelerations` for the chain topology, no base motion)."""
    k1, k3 = chain_coefficients(n)
    m = np.full(n, MASS)
    c = DAMPING

    def rhs(t, y, f, amp, on):
        x, v = y[:n], y[n:]
        p = amp * np.sin(2.0 * np.pi * f * t) if on else 0.0
        gg = p - (k1 * x + k3 * x**3 + c * v)  # sum_{k>=i} force_k - F_i, tip load only
        a = np.empty(n)
        a[:-1] = (gg[:-1] - gg[1:]) / m[:-1]
        a[-1] = gg[-1] / m[-1]
        xdd = a.copy()
        xdd[1:] -= a[:-1]
        return np.concatenate((v, xdd))

    return rhs


def check_rhs(model, n):
    rhs = numpy_rhs(n)
    rng = np.random.default_rng(1)
    for _ in range(5):
        x, v, t = rng.normal(0, WELL, n), rng.normal(0, 0.3, n), rng.uniform(0, 0.1)
        f, amp = 2.0, 0.3
        exc = g.HalfSineTip(f, amp, n_dof=n)
        b, force = exc(t)
        want = np.asarray(model.accelerations(jnp.asarray(x), jnp.asarray(v), b, force))
        got = rhs(t, np.concatenate([x, v]), f, amp, True)[n:]
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)


def scipy_final(rhs, n, x0, f, amp, method):
    """Final (x, v, code) and wall time of one point, integrated in two pieces."""
    t_off = 0.5 / f
    t1 = t_off + SETTINGS.settle_time
    y0 = np.concatenate([x0, np.zeros(n)])
    kw = dict(method=method, rtol=SETTINGS.rtol, atol=SETTINGS.atol)
    t, c = time.perf_counter(), time.process_time()
    s1 = solve_ivp(rhs, (0.0, t_off), y0, args=(f, amp, True), **kw)
    s2 = solve_ivp(rhs, (t_off, t1), s1.y[:, -1], args=(f, amp, False), **kw) if s1.status == 0 else s1
    dt, dc = time.perf_counter() - t, time.process_time() - c
    ok = s1.status == 0 and s2.status == 0
    y = s2.y[:, -1]
    return y[:n], y[n:], ok, dt, dc, s1.nfev + (s2.nfev if s2 is not s1 else 0)


# ---------------------------------------------------------------------------------------------
# gmr_jax side
def run_map(model, wells, n_points, chunk, shift=0.0):
    f, a = grid(n_points, shift)
    t, c = time.perf_counter(), time.process_time()
    bm = basin_map(model, f, a, wells, settings=SETTINGS, chunk=chunk)
    jax.block_until_ready(bm)
    run_map.cpu = time.process_time() - c  # CPU seconds of this process (all threads)
    return bm, time.perf_counter() - t


def padded_points(f, a, chunk):
    """The flat, padded point list and batch size that `basin_map` builds (one device)."""
    ff, aa = jnp.meshgrid(f, a)
    flat_f, flat_a = ff.ravel(), aa.ravel()
    n = flat_f.shape[0]
    per = -(-n // chunk) * chunk if n > chunk else n
    pad = per - n
    flat_f = jnp.concatenate([flat_f, jnp.full(pad, flat_f[0])])
    flat_a = jnp.concatenate([flat_a, jnp.full(pad, flat_a[0])])
    return flat_f, flat_a, n, min(chunk, per)


def aot_compile(model, wells, n_points, chunk):
    """lower + compile of the jitted sweep for this size (fills the cache `basin_map` uses)."""
    f, a = grid(n_points)
    flat_f, flat_a, _, c = padded_points(f, a, chunk)
    w = jnp.asarray(wells, float)
    t = time.perf_counter()
    _sweep._sweep_points.lower(model, SETTINGS, w[:, 0], flat_f, flat_a, w, c).compile()
    return time.perf_counter() - t


def cache_size():
    return _sweep._sweep_points._cached._cache_size()


def size_row(model, wells, n_points, chunk, rows, label, cold=True):
    """Cold call (compile + run), then a warm call on a shifted grid of the same size."""
    if cold:
        bm, t_cold = run_map(model, wells, n_points, chunk)
        mid = cache_size()
        bm2, t_warm = run_map(model, wells, n_points, chunk, shift=0.5)
        compile_s = t_cold - t_warm
    else:  # too large to pay twice: AOT compile, then one call
        compile_s = aot_compile(model, wells, n_points, chunk)
        t_cold = None
        mid = cache_size()
        bm2, t_warm = run_map(model, wells, n_points, chunk, shift=0.5)
        bm = bm2
    recompiled = cache_size() - mid
    n = int(np.prod(bm.config.shape))
    cfg = np.asarray(bm2.config)
    rows.append(dict(label=label, n=n, shape=f"{bm.config.shape[0]} x {bm.config.shape[1]}", chunk=chunk,
                     cold=t_cold, warm=t_warm, compile=compile_s, per=t_warm / n, tps=n / t_warm,
                     cpu_per=run_map.cpu / n,
                     recompiled=recompiled, n_cfg=len(np.unique(cfg[cfg >= 0])),
                     unsettled=float(np.mean(cfg < 0)), warm_map=bm2))
    print(f"  {label}: {n} pts chunk {chunk}: cold {t_cold if t_cold is None else round(t_cold, 2)} s, "
          f"warm {t_warm:.2f} s ({1e6 * t_warm / n:.0f} us/traj), compile {compile_s:.2f} s, "
          f"recompiled on warm call: {recompiled}", flush=True)
    return bm


def ordered_experiment(model, wells, n_points, chunk, warm_map):
    """The warm grid's points through `_sweep_points`, sorted by f so that each lockstep chunk
    holds similar t1; compared with `warm_map` (the same points in `basin_map`'s order)."""
    f, a = grid(n_points, shift=0.5)
    flat_f, flat_a, n, c = padded_points(f, a, chunk)
    order = jnp.argsort(flat_f[:n])
    sf = jnp.concatenate([flat_f[:n][order], flat_f[n:]])
    sa = jnp.concatenate([flat_a[:n][order], flat_a[n:]])
    w = jnp.asarray(wells, float)
    before = cache_size()
    t = time.perf_counter()
    out = _sweep._sweep_points(model, SETTINGS, w[:, 0], sf, sa, w, c)
    jax.block_until_ready(out)
    dt = time.perf_counter() - t
    cfg = np.empty(n, int)
    cfg[np.asarray(order)] = np.asarray(out[1])[:n]
    same = int(np.sum(cfg == np.asarray(warm_map.config).ravel()))
    return dt, same, n, cache_size() - before


# ---------------------------------------------------------------------------------------------
def fmt(x, d=3):
    if x is None:
        return "-"
    return f"{x:.{d}g}"


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true", help="about 2 minutes: 1e2/1e3 grids, 50 scipy points")
    p.add_argument("--scipy-points", type=int, default=None, help="random grid points per system (default 200)")
    p.add_argument("--max-1e5-s", type=float, default=300.0,
                   help="run the 1e5 grid only if predicted to take less than this (s)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="benchmarks/results_basins.md")
    args = p.parse_args()
    cmd = "python " + " ".join(sys.argv)
    quick = args.quick
    n_scipy = args.scipy_points or (50 if quick else 200)
    map_size = 1000 if quick else 10_000  # grid for the per-cell rows and the scipy comparison
    sizes = (100, 1000) if quick else (100, 1000, 10_000)
    chunks_extra = (256, 1024)
    t_start = time.perf_counter()
    load0 = os.getloadavg()

    models, wells = {}, {}
    for n in CELLS:
        models[n] = make_model(n)
        wells[n] = stable_wells(models[n], [[-3 * WELL, 3 * WELL]] * n)
        assert wells[n].shape == (n, 2)
        np.testing.assert_allclose(wells[n], [[-WELL, WELL]] * n, atol=1e-6)
        check_rhs(models[n], n)

    # --- gmr_jax: grid size (5 cells, chunk 512) --------------------------------------------
    print("gmr_jax: grid size", flush=True)
    size_rows = []
    maps = {}
    m5 = models[SCALING_CELLS]
    for s in sizes:
        bm = size_row(m5, wells[SCALING_CELLS], s, 512, size_rows, f"{SCALING_CELLS} cells")
        if s == map_size:
            maps[SCALING_CELLS] = bm
    skipped_1e5 = None
    if not quick:
        last = size_rows[-1]
        predicted = 10 * last["warm"] + last["compile"]
        if predicted <= args.max_1e5_s:
            size_row(m5, wells[SCALING_CELLS], 100_000, 512, size_rows, f"{SCALING_CELLS} cells", cold=False)
        else:
            skipped_1e5 = predicted
            print(f"  1e5 skipped (predicted {predicted:.0f} s)", flush=True)

    # --- gmr_jax: number of cells -------------------------------------------------------------
    print("gmr_jax: number of cells", flush=True)
    cell_rows = []
    for n in CELLS:
        if n == SCALING_CELLS:
            cell_rows.append(next(r for r in size_rows if r["n"] == map_size))
            continue
        maps[n] = size_row(models[n], wells[n], map_size, 512, cell_rows, f"{n} cells")
    cell_rows.sort(key=lambda r: int(r["label"].split()[0]))

    # --- gmr_jax: chunk size --------------------------------------------------------------------
    print("gmr_jax: chunk", flush=True)
    base_row = next(r for r in size_rows if r["n"] == map_size)
    chunk_rows = [base_row]
    for c in chunks_extra:
        size_row(m5, wells[SCALING_CELLS], map_size, c, chunk_rows, f"{SCALING_CELLS} cells")
    chunk_rows.sort(key=lambda r: r["chunk"])
    t_ord, same_ord, n_ord, rec_ord = ordered_experiment(m5, wells[SCALING_CELLS], map_size, 512,
                                                         base_row["warm_map"])
    print(f"  ordered by f: {t_ord:.2f} s, same config {same_ord}/{n_ord}, compiled {rec_ord}", flush=True)

    # --- scipy on a random subset of each system's map ------------------------------------------
    print("scipy", flush=True)
    rng = np.random.default_rng(args.seed)
    cmp_rows, disagreements = [], []
    for n in CELLS:
        bm = maps[n]
        w = jnp.asarray(wells[n], float)
        span = jnp.nanmax(w, axis=1) - jnp.nanmin(w, axis=1)
        centre = 0.5 * (jnp.nanmax(w, axis=1) + jnp.nanmin(w, axis=1))
        cls = jax.jit(jax.vmap(lambda x1, v1, code: classify(x1, v1, code, w, span, SETTINGS)))
        ff, aa = np.meshgrid(np.asarray(bm.f), np.asarray(bm.A))
        ff, aa = ff.ravel(), aa.ravel()
        gmr_cfg = np.asarray(bm.config).ravel()
        idx = rng.choice(ff.size, size=min(n_scipy, ff.size), replace=False)
        rhs = numpy_rhs(n)
        x0 = np.asarray(wells[n][:, 0])
        res = {meth: dict(x=[], v=[], code=[], t=[], cpu=[], nfev=[]) for meth in ("RK45", "DOP853")}
        for k in idx:
            for meth in ("RK45", "DOP853"):  # interleaved: both see the same machine load
                x1, v1, ok, dt, dc, nfev = scipy_final(rhs, n, x0, float(ff[k]), float(aa[k]), meth)
                far = np.max(np.abs(x1 - np.asarray(centre)) / np.asarray(span)) > SETTINGS.bound
                code = (g.RESULTS.diverged if far else g.RESULTS.successful) if ok else g.RESULTS.simulation_failed
                r = res[meth]
                r["x"].append(x1), r["v"].append(v1), r["code"].append(code._value)
                r["t"].append(dt), r["cpu"].append(dc), r["nfev"].append(nfev)
        gr = next(r for r in cell_rows if r["label"] == f"{n} cells")
        row = dict(n=n, points=len(idx), gmr_per=gr["per"], gmr_cpu=gr["cpu_per"])
        cfgs = {}
        for meth, r in res.items():
            _, cfg, _ = cls(jnp.asarray(np.array(r["x"])), jnp.asarray(np.array(r["v"])),
                            jnp.asarray(np.array(r["code"], dtype=np.int32)))
            cfg = np.asarray(cfg)
            cfgs[meth] = cfg
            t = np.array(r["t"])
            row[meth] = dict(mean=t.mean(), median=np.median(t), nfev=float(np.mean(r["nfev"])),
                             agree=int(np.sum(cfg == gmr_cfg[idx])), ratio=t.mean() / row["gmr_per"],
                             cpu=float(np.mean(r["cpu"])), cpu_ratio=float(np.mean(r["cpu"])) / row["gmr_cpu"])
            for j in np.nonzero(cfg != gmr_cfg[idx])[0]:
                disagreements.append((n, meth, ff[idx[j]], aa[idx[j]], int(gmr_cfg[idx[j]]), int(cfg[j])))
        row["rk_vs_dop"] = int(np.sum(cfgs["RK45"] == cfgs["DOP853"]))
        row["gmr_unsettled"] = int(np.sum(gmr_cfg[idx] < 0))
        cmp_rows.append(row)
        print(f"  {n} cells: RK45 {1e3 * row['RK45']['mean']:.1f} ms/pt (agree {row['RK45']['agree']}/{len(idx)}), "
              f"DOP853 {1e3 * row['DOP853']['mean']:.1f} ms/pt (agree {row['DOP853']['agree']}/{len(idx)}), "
              f"gmr {1e6 * row['gmr_per']:.0f} us/pt", flush=True)

    total = time.perf_counter() - t_start
    load1 = os.getloadavg()

    # --- report ---------------------------------------------------------------------------------
    L = [f"# Basin sweeps: gmr_jax `basin_map` vs a loop of scipy `solve_ivp`", "",
         f"Generated by `{cmd}` ({'quick' if quick else 'full'} run, {total:.0f} s in all).", ""]
    L += ["## Problem", "",
          "Polynomial double-well chains (`gmr_jax.from_terms`, topology \"chain\"), cell i (numbered from the "
          f"base): F_i(x, v) = k1_i x + k3_i x^3 + c v with -k1_i graded linearly from {K1[0]:g} N/m (base cell) "
          f"to {K1[1]:g} N/m (tip cell), k3_i = -k1_i / {WELL:g}^2 (wells at x = ±{WELL:g} m in every cell), "
          f"c = {DAMPING:g} N s/m, masses {MASS:g} kg. Static snap-through loads 2/(3√3)·|k1_i|·{WELL:g} = "
          f"{FC * K1[0] * WELL:.3g} .. {FC * K1[1] * WELL:.3g} N; small-vibration frequencies in a well "
          f"sqrt(2|k1|/m)/2π = {np.sqrt(2 * K1[0] / MASS) / 2 / np.pi:.2f} .. {np.sqrt(2 * K1[1] / MASS) / 2 / np.pi:.2f} Hz "
          "per cell. Load: Eq. (25) tip half-sine A sin(2πft), t <= 1/(2f), on the last mass; start at rest with "
          f"every cell in its first well (x = -{WELL:g}). Grid: f linear in [{F_RANGE[0]:g}, {F_RANGE[1]:g}] Hz, "
          f"A linear in [{A_RANGE[0]:g}, {A_RANGE[1]:g}] N; t1 = 1/(2f) + {SETTINGS.settle_time:g} s; "
          f"rtol {SETTINGS.rtol:g}, atol {SETTINGS.atol:g}. Classification (both sides: "
          "`gmr_jax.basins._sweep.classify`): a cell is in a well when |x - x_well| < "
          f"{SETTINGS.x_tol:g}·span and |v| < {SETTINGS.v_tol:g}·span/s (span = {2 * WELL:g} m); "
          "configuration = bit i set when cell i ended in its second well, -1 when some cell has not settled.", "",
          "gmr_jax: `basin_map` (Tsit5 + PID, switch-off time in `jump_ts`, divergence event, vmapped in "
          "lockstep chunks via `lax.map(batch_size=chunk)`), one CPU device. scipy: `solve_ivp` per point in two "
          "pieces [0, 1/(2f)] and [1/(2f), t1] (the restart at the switch-off is scipy's equivalent of "
          "`jump_ts`), numpy right-hand side checked against `GlobalModel.accelerations`, no events (this "
          "hardening chain cannot diverge; leaving the event out only favours scipy).", ""]

    L += ["## Per point: scipy vs gmr_jax", "",
          f"scipy on {cmp_rows[0]['points']} random points of each system's {map_size:,}-point grid (the same points "
          "for both methods, run interleaved); gmr_jax per trajectory = warm `basin_map` time over the whole grid / "
          "points (chunk 512). Speed ratio = scipy mean per point / gmr_jax per trajectory. Agreement = same "
          "configuration code as the gmr_jax map on the same point.", "",
          "| cells | scipy points | gmr_jax wall (us/traj) | gmr_jax CPU (us/traj) | RK45 mean (ms) | RK45 median (ms) | "
          "DOP853 mean (ms) | DOP853 median (ms) | ratio RK45 | ratio DOP853 | CPU-time ratio RK45 | "
          "CPU-time ratio DOP853 |",
          "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in cmp_rows:
        rk, dp, k = r["RK45"], r["DOP853"], r["points"]
        L.append(f"| {r['n']} | {k} | {1e6 * r['gmr_per']:.0f} | {1e6 * r['gmr_cpu']:.0f} | {1e3 * rk['mean']:.1f} | "
                 f"{1e3 * rk['median']:.1f} | {1e3 * dp['mean']:.1f} | {1e3 * dp['median']:.1f} | "
                 f"**{rk['ratio']:.0f}x** | **{dp['ratio']:.0f}x** | {rk['cpu_ratio']:.0f}x | {dp['cpu_ratio']:.0f}x |")
    L += ["", "CPU-time ratio: the same with process CPU seconds (all threads) on both sides; less sensitive to "
          "the other jobs on this shared machine, and it charges gmr_jax for the second core XLA uses.", "",
          "| cells | scipy points | RK45 fevals/point | DOP853 fevals/point | agree RK45 | agree DOP853 | "
          "RK45 = DOP853 | gmr_jax unsettled on these points |",
          "|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in cmp_rows:
        rk, dp, k = r["RK45"], r["DOP853"], r["points"]
        L.append(f"| {r['n']} | {k} | {rk['nfev']:.0f} | {dp['nfev']:.0f} | "
                 f"{rk['agree']}/{k} ({100 * rk['agree'] / k:.1f} %) | {dp['agree']}/{k} ({100 * dp['agree'] / k:.1f} %) | "
                 f"{r['rk_vs_dop']}/{k} | {r['gmr_unsettled']} |")
    tot = sum(r["points"] for r in cmp_rows)
    for meth in ("RK45", "DOP853"):
        a = sum(r[meth]["agree"] for r in cmp_rows)
        L.append("")
        L.append(f"All systems, {meth}: {a}/{tot} points agree ({100 * a / tot:.2f} %).")
    if disagreements:
        L += ["", "Disagreements (cells, method, f, A, gmr_jax config, scipy config):", ""]
        L += [f"- {n}, {meth}, f = {f:.4g} Hz, A = {a:.4g} N: {cg} vs {cs}" for n, meth, f, a, cg, cs in disagreements]
    L.append("")

    def size_table(rows, title, note):
        out = [f"## {title}", "", note, "",
               "| system | points | grid (A x f) | chunk | cold call (s) | warm call (s) | compile (s) | us/traj | "
               "CPU us/traj | traj/s | recompiled on warm call | configs seen | unsettled |",
               "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in rows:
            out.append(f"| {r['label']} | {r['n']:,} | {r['shape']} | {r['chunk']} | {fmt(r['cold'])} | "
                       f"{fmt(r['warm'])} | {fmt(r['compile'])} | {1e6 * r['per']:.0f} | {1e6 * r['cpu_per']:.0f} | {r['tps']:.0f} | "
                       f"{r['recompiled']} | {r['n_cfg']} | {100 * r['unsettled']:.1f} % |")
        return out + [""]

    note = ("Cold call = first `basin_map` call at that size (trace + compile + run); warm call = second call on a "
            "grid of the same size with every f and A moved by half a grid step (no recompile, checked on the jit "
            "cache); compile = cold - warm. The 1e5 row, where run, pays one call only: its compile is an AOT "
            "`lower().compile()` of the same jitted function (which fills the cache `basin_map` then hits), its "
            "run the one call. 'configs seen' and 'unsettled' are read off the warm call's map.")
    L += size_table(size_rows, f"gmr_jax: cost vs grid size ({SCALING_CELLS} cells, chunk 512)", note)
    if skipped_1e5 is not None:
        L += [f"1e5 points skipped: predicted {skipped_1e5:.0f} s > {args.max_1e5_s:g} s.", ""]
    if quick:
        r = size_rows[-1]
        L += [f"Quick run: 1e4 and 1e5 not run; linear extrapolation from {r['n']:,} points: "
              f"~{1e4 * r['per']:.0f} s and ~{1e5 * r['per']:.0f} s.", ""]
    L += size_table(cell_rows, f"gmr_jax: cost vs number of cells ({map_size:,} points, chunk 512)", "")
    L += size_table(chunk_rows, f"gmr_jax: cost vs chunk ({SCALING_CELLS} cells, {map_size:,} points)", "")
    base = next(r for r in chunk_rows if r["chunk"] == 512)
    L += [f"Lockstep experiment: the same {n_ord:,} points (the warm grid) with chunk 512 but sorted by f, so "
          f"each chunk holds similar t1 = 1/(2f) + {SETTINGS.settle_time:g} s, through the private "
          f"`_sweep_points` (new compilations: {rec_ord}): {t_ord:.2f} s ({1e6 * t_ord / n_ord:.0f} us/traj) vs "
          f"{base['warm']:.2f} s in `basin_map`'s order (f varying fastest, so every chunk holds the slowest "
          f"point) = {base['warm'] / t_ord:.2f}x; configurations identical on {same_ord}/{n_ord} points.", ""]
    L += [f"Machine: {platform.machine()}, {os.cpu_count()} CPUs, load average {load0[0]:.2f} at the start and "
          f"{load1[0]:.2f} at the end (the machine is shared: other jobs ran meanwhile, so absolute times are "
          f"noisy; scipy RK45/DOP853 were interleaved point by point). JAX {jax.__version__} on "
          f"{jax.devices()[0].platform} ({len(jax.devices())} device), diffrax "
          f"{__import__('diffrax').__version__}, equinox {__import__('equinox').__version__}, scipy "
          f"{scipy.__version__}, numpy {np.__version__}, Python {platform.python_version()}, "
          f"EQX_ON_ERROR={os.environ['EQX_ON_ERROR']}, float64.", ""]
    text = "\n".join(L)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
