"""Side-by-side timing of gmr_jax's `basin_map` and a loop of scipy `solve_ivp` on
deployment-basin sweeps (paper Fig. 11) of polynomial double-well chains of 3, 5 and 10 cells.

Both sides integrate the same problem: chain topology, cell i with
F_i(x, v) = k1_i x + k3_i x^3 + c v (k1_i < 0 < k3_i, graded along the chain), masses m, the
paper's Eq. (25) tip load A sin(2 pi f t) for t <= 1/(2f) and 0 after, from rest in every cell's
first well, up to t1 = 1/(2f) + settle_time, at rtol 1e-6 / atol 1e-8. gmr_jax uses Tsit5 with
PID control and the switch-off time declared to the controller; scipy integrates in two pieces,
[0, 1/(2f)] with the load and [1/(2f), t1] without, with RK45 and with DOP853. Both final states
go through the same classification rule (`basin_map`'s, written out in `classify` here, vmapped)
into wells and a configuration code.

gmr_jax is measured four ways in the same run: the default sweep (`batching="auto"`, which on a
CPU is "native": the C kernel generated from the model, per-point step control) on every core and
on one, the joint XLA sweep (`batching="joint"`: each chunk of 256 points integrated as one ODE)
sharded over all CPU cores (`gmr.use_cpu_cores()`), and the oldest method (`batching="member"`:
`vmap` of one `diffeqsolve` per point) on one core.

Measured:
- scipy on a random subset of the grid (per point, both methods), the classification agreement
  with the gmr_jax sweep on the same points, and the per-point speed ratios;
- gmr_jax: compile time apart from run time (a cold call, then a warm call with different f/A
  values on a grid of the same size), throughput, cost vs grid size (1e2 .. 1e5 points, 5
  cells), vs number of cells (3, 5, 10; 1e4 points) and vs `chunk`.

    python benchmarks/bench_basins.py          # full: about 10 min on a 2-core machine
    python benchmarks/bench_basins.py --quick  # ~2 min: 1e2/1e3 grids, 50 scipy points/system
"""

import os

os.environ["EQX_ON_ERROR"] = "nan"
# a fresh cache folder: the native kernels' C compile is in the cold calls, as XLA's is
os.environ["GMR_CACHE_DIR"] = __import__("tempfile").mkdtemp(prefix="gmr_bench_cache_")

import argparse  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import diffrax  # noqa: E402
import equinox  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

import gmr_jax as g  # noqa: E402  (enables float64)

g.use_cpu_cores()  # every core a JAX CPU device (before any JAX computation)
from gmr_jax import SweepSettings, basin_map, stable_wells  # noqa: E402

RESULTS = Path(__file__).resolve().parents[1] / "results"

# -------------------------------------------------------------------------------------------
# Systems: n-cell chains, stiffness graded linearly from the base (softest) to the tip.
MASS = 0.05  # kg, every cell
DAMPING = 1.0  # N s/m, viscous, every cell (lets the 10-cell chain's slow mode settle in 10 s)
WELL = 0.03  # m: wells at x = ±WELL in every cell (k3 = -k1 / WELL^2)
K1 = (8.0, 24.0)  # -k1 from the base cell to the tip cell, N/m
F_RANGE = (0.1, 5.0)  # Hz
A_RANGE = (0.02, 0.6)  # N
SETTINGS = SweepSettings()  # settle_time 10 s, rtol 1e-6, atol 1e-8, x_tol 0.1, v_tol 0.05, auto
CHUNK = None  # basin_map's default (joint: 512, 256, 128 points for 3, 5, 10 cells; native: 16 lanes)
CELLS = (3, 5, 10)
SCALING_CELLS = 5
FC = 2.0 / (3.0 * np.sqrt(3.0))  # static snap-through load = FC * |k1| * WELL
METHODS = ("RK45", "DOP853")
GRID_SHAPES = {100: (10, 10), 1000: (40, 25), 10_000: (100, 100), 100_000: (400, 250)}  # (nf, na)


def classify(x1, v1, code, wells, span, settings: SweepSettings):
    """`basin_map`'s classification of one final state (`SweepSettings` docstring): well index
    per cell (-1: not settled, failed, diverged) and the configuration (bit i = cell i in its
    second well; -1 unless every cell settled); a successful solve that did not settle becomes
    `not_settled`."""
    ok, not_settled = g.RESULTS.successful._value, g.RESULTS.not_settled._value
    dist = jnp.abs(x1[:, None] - wells)  # (dof, max_wells)
    dist = jnp.where(jnp.isnan(wells), jnp.inf, dist)
    k = jnp.argmin(dist, axis=1)
    near = jnp.min(dist, axis=1) < settings.x_tol * span
    slow = jnp.abs(v1) < settings.v_tol * span
    settled = near & slow & jnp.isfinite(x1)
    good = code == ok
    idx = jnp.where(settled & good, k, -1)
    code = jnp.where(good & ~jnp.all(settled), not_settled, code)
    bits = jnp.sum(jnp.where(idx == 1, 2 ** jnp.arange(idx.shape[0]), 0))
    return idx, jnp.where(jnp.all(idx >= 0), bits, -1), code


class CompileCounter:
    """Number of XLA backend compilations so far (JAX's monitoring events): a warm call that
    compiles nothing leaves it unchanged."""

    def __init__(self):
        self.n = 0
        jax.monitoring.register_event_duration_secs_listener(self._event)

    def _event(self, event, duration, **kwargs):
        if event == "/jax/core/compile/backend_compile_duration":
            self.n += 1


COMPILES = CompileCounter()


def chain_coefficients(n):
    k1 = -np.linspace(*K1, n)
    return k1, -k1 / WELL**2


def make_model(n):
    k1, k3 = chain_coefficients(n)
    terms = []
    for i in range(n):
        terms += [
            {"dof": i, "physics": "stiffness", "order": 1, "coefficient": float(k1[i])},
            {"dof": i, "physics": "stiffness", "order": 3, "coefficient": float(k3[i])},
            {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": DAMPING},
        ]
    return g.from_terms([MASS] * n, terms, "chain")


def grid(n_points, shift=0.0):
    """(f, A) axes with n_points points; `shift` > 0 moves both ends inwards by that fraction
    of a grid step (same size, different values: the warm call)."""
    nf, na = GRID_SHAPES[n_points]
    df = (F_RANGE[1] - F_RANGE[0]) / (nf - 1)
    da = (A_RANGE[1] - A_RANGE[0]) / (na - 1)
    f = np.linspace(F_RANGE[0] + shift * df, F_RANGE[1] - shift * df, nf)
    a = np.linspace(A_RANGE[0] + shift * da, A_RANGE[1] - shift * da, na)
    return jnp.asarray(f), jnp.asarray(a)


# -------------------------------------------------------------------------------------------
# scipy side
def numpy_rhs(n):
    """dy/dt for y = (x, v) of the chain under a tip force P (the equations of
    `GlobalModel.accelerations` for the chain topology, no base motion)."""
    k1, k3 = chain_coefficients(n)
    m = np.full(n, MASS)
    c = DAMPING

    def rhs(t, y, f, amp, on):
        x, v = y[:n], y[n:]
        p = amp * np.sin(2.0 * np.pi * f * t) if on else 0.0
        gg = p - (k1 * x + k3 * x**3 + c * v)  # sum_{k>=i} force_k - F_i (tip load only)
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
        b, force = g.HalfSineTip(f, amp, n_dof=n)(t)
        want = np.asarray(model.accelerations(jnp.asarray(x), jnp.asarray(v), b, force))
        got = rhs(t, np.concatenate([x, v]), f, amp, True)[n:]
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-9)


def scipy_final(rhs, n, x0, f, amp, method):
    """Final x, v, success, wall and CPU time, fevals of one point (two pieces)."""
    t_off = 0.5 / f
    t1 = t_off + SETTINGS.settle_time
    y0 = np.concatenate([x0, np.zeros(n)])
    kw = {"method": method, "rtol": SETTINGS.integrator.rtol, "atol": SETTINGS.integrator.atol}
    t, c = time.perf_counter(), time.process_time()
    s1 = solve_ivp(rhs, (0.0, t_off), y0, args=(f, amp, True), **kw)
    s2 = None
    if s1.status == 0:
        s2 = solve_ivp(rhs, (t_off, t1), s1.y[:, -1], args=(f, amp, False), **kw)
    dt, dc = time.perf_counter() - t, time.process_time() - c
    ok = s2 is not None and s2.status == 0
    y = (s2 if s2 is not None else s1).y[:, -1]
    nfev = s1.nfev + (s2.nfev if s2 is not None else 0)
    return y[:n], y[n:], ok, dt, dc, nfev


def scipy_compare(n, wells, bm, n_points, rng, gmr_rows):
    """scipy (both methods, interleaved) on random points of the map `bm`; classification
    agreement with `bm` and timings; speed ratios against each gmr_jax mode in `gmr_rows`."""
    w = jnp.asarray(wells, float)
    span = jnp.nanmax(w, axis=1) - jnp.nanmin(w, axis=1)
    centre = np.asarray(0.5 * (jnp.nanmax(w, axis=1) + jnp.nanmin(w, axis=1)))

    def cls_one(x1, v1, code):
        return classify(x1, v1, code, w, span, SETTINGS)

    cls = jax.jit(jax.vmap(cls_one))
    ff, aa = np.meshgrid(np.asarray(bm.f), np.asarray(bm.A))
    ff, aa = ff.ravel(), aa.ravel()
    gmr_cfg = np.asarray(bm.config).ravel()
    idx = rng.choice(ff.size, size=min(n_points, ff.size), replace=False)
    rhs = numpy_rhs(n)
    x0 = np.asarray(wells[:, 0])
    res = {m: {"x": [], "v": [], "code": [], "t": [], "cpu": [], "nfev": []} for m in METHODS}
    for k in idx:
        for meth in METHODS:  # interleaved: both methods see the same machine load
            x1, v1, ok, dt, dc, nfev = scipy_final(rhs, n, x0, float(ff[k]), float(aa[k]), meth)
            far = np.max(np.abs(x1 - centre) / np.asarray(span)) > SETTINGS.box_spans
            code = g.RESULTS.simulation_failed
            if ok:
                code = g.RESULTS.diverged if far else g.RESULTS.successful
            r = res[meth]
            r["x"].append(x1)
            r["v"].append(v1)
            r["code"].append(int(code._value))
            r["t"].append(dt)
            r["cpu"].append(dc)
            r["nfev"].append(nfev)
    row = {"n": n, "points": len(idx), "gmr_per": {m: r["per"] for m, r in gmr_rows.items()},
           "gmr_cpu": gmr_rows["all cores"]["cpu_per"]}
    cfgs, disagreements = {}, []
    for meth, r in res.items():
        _, cfg, _ = cls(jnp.asarray(np.array(r["x"])), jnp.asarray(np.array(r["v"])),
                        jnp.asarray(np.array(r["code"], dtype=np.int32)))
        cfg = cfgs[meth] = np.asarray(cfg)
        t, cpu = np.array(r["t"]), np.array(r["cpu"])
        row[meth] = {"mean": t.mean(), "median": np.median(t), "nfev": float(np.mean(r["nfev"])),
                     "agree": int(np.sum(cfg == gmr_cfg[idx])),
                     "ratio": {m: t.mean() / per for m, per in row["gmr_per"].items()},
                     "cpu_ratio": cpu.mean() / row["gmr_cpu"]}
        for j in np.nonzero(cfg != gmr_cfg[idx])[0]:
            k = idx[j]
            disagreements.append((n, meth, ff[k], aa[k], int(gmr_cfg[k]), int(cfg[j])))
    row["rk_vs_dop"] = int(np.sum(cfgs["RK45"] == cfgs["DOP853"]))
    row["gmr_unsettled"] = int(np.sum(gmr_cfg[idx] < 0))
    rk, dp = row["RK45"], row["DOP853"]
    print(f"  {n} cells: RK45 {1e3 * rk['mean']:.1f} ms/pt (agree {rk['agree']}/{len(idx)}), "
          f"DOP853 {1e3 * dp['mean']:.1f} ms/pt (agree {dp['agree']}/{len(idx)}), "
          f"gmr {1e6 * row['gmr_per']['all cores']:.0f} us/pt", flush=True)
    return row, disagreements


# -------------------------------------------------------------------------------------------
# gmr_jax side
def run_map(model, wells, n_points, chunk, shift=0.0, devices=None, batching="auto"):
    """One `basin_map` call: (map, wall s, CPU s of this process, all threads, its stats)."""
    f, a = grid(n_points, shift)
    settings = eqx_replace(SETTINGS, batching)
    t, c = time.perf_counter(), time.process_time()
    sol = basin_map(model, f, a, wells, settings=settings, chunk=chunk, devices=devices)
    bm = sol.value
    jax.block_until_ready(bm)
    return bm, time.perf_counter() - t, time.process_time() - c, sol.stats


def eqx_replace(settings, batching):
    return settings if batching == settings.batching else SweepSettings(
        settle_time=settings.settle_time, integrator=settings.integrator, batching=batching)


MODES = {  # label: (devices, batching)
    "all cores": (None, "auto"),
    "1 core": ("one", "auto"),
    "all cores, joint": (None, "joint"),
    "1 core, member": ("one", "member"),
}


def size_row(model, wells, n_points, chunk, label, mode="all cores"):
    """Cold call (compile + run), then a warm call on a shifted grid of the same size."""
    devs, batching = MODES[mode]
    devices = jax.devices()[:1] if devs == "one" else None
    bm, t_cold, _, _ = run_map(model, wells, n_points, chunk, devices=devices, batching=batching)
    mid = COMPILES.n
    bm2, t_warm, cpu_warm, stats = run_map(model, wells, n_points, chunk, shift=0.5, devices=devices,
                                           batching=batching)
    recompiled = COMPILES.n - mid
    n = int(np.prod(bm.config.shape))
    cfg = np.asarray(bm2.config)
    st = np.asarray(bm2.steps)
    chunk = stats["chunk"]
    row = {"label": label, "mode": f"{mode} ({stats['batching']})", "n": n, "shape": f"{cfg.shape[0]} x {cfg.shape[1]}", "chunk": chunk,
           "cold": t_cold, "warm": t_warm, "compile": t_cold - t_warm, "per": t_warm / n,
           "cpu_per": cpu_warm / n, "tps": n / t_warm, "recompiled": recompiled, "steps": float(st.mean()),
           "n_cfg": len(np.unique(cfg[cfg >= 0])), "unsettled": float(np.mean(cfg < 0)),
           "map": bm, "warm_map": bm2}
    print(f"  {label} [{mode}]: {n} pts chunk {chunk}: cold {t_cold:.2f} s, warm {t_warm:.2f} s "
          f"({1e6 * t_warm / n:.0f} us/traj, {st.mean():.0f} steps), compile {t_cold - t_warm:.2f} s, "
          f"recompiled on warm call: {recompiled}", flush=True)
    return row


# -------------------------------------------------------------------------------------------
# report
def fmt(x, d=3):
    return "-" if x is None else f"{x:.{d}g}"


def problem_text(map_size, n_scipy):
    s = SETTINGS
    return [
        "## Problem", "",
        "Polynomial double-well chains (`gmr_jax.from_terms`, topology \"chain\"), cell i "
        f"(numbered from the base): F_i(x, v) = k1_i x + k3_i x^3 + c v, with -k1_i graded "
        f"linearly from {K1[0]:g} N/m (base cell) to {K1[1]:g} N/m (tip cell), "
        f"k3_i = -k1_i / {WELL:g}^2 (wells at x = ±{WELL:g} m in every cell), c = {DAMPING:g} "
        f"N s/m, masses {MASS:g} kg. Static snap-through loads 2/(3√3)·|k1_i|·{WELL:g} = "
        f"{FC * K1[0] * WELL:.3g} .. {FC * K1[1] * WELL:.3g} N; small-vibration frequency of a "
        f"cell in a well sqrt(2|k1|/m)/2π = {np.sqrt(2 * K1[0] / MASS) / 2 / np.pi:.2f} .. "
        f"{np.sqrt(2 * K1[1] / MASS) / 2 / np.pi:.2f} Hz. Load: Eq. (25) tip half-sine "
        "A sin(2πft) for t <= 1/(2f), then 0, on the last mass; start at rest with every cell "
        f"in its first well (x = -{WELL:g}). Grid: f linear in [{F_RANGE[0]:g}, {F_RANGE[1]:g}] "
        f"Hz, A linear in [{A_RANGE[0]:g}, {A_RANGE[1]:g}] N; t1 = 1/(2f) + "
        f"{s.settle_time:g} s; rtol {s.integrator.rtol:g}, atol {s.integrator.atol:g}. Classification, "
        "both sides by `basin_map`'s rule: a cell is in a well when |x - x_well| < "
        f"{s.x_tol:g}·span and |v| < {s.v_tol:g}·span/s (span = {2 * WELL:g} m); configuration "
        "= bit i set when cell i ended in its second well, -1 when some cell has not settled.",
        "",
        "gmr_jax: `basin_map` with its defaults (`batching=\"auto\"`: on a CPU the C kernel generated "
        "from the model, Tsit5 with per-point step control, the switch-off time a stop its steps land on, "
        "16 points per vector group, one thread per core), and the joint XLA sweep (points "
        "ordered by (f, A), chunks of `default_chunk(dof)` points (512, 256, 128 for 3, 5, 10 cells) each "
        "integrated as one ODE whose error norm is "
        "the largest member's RMS norm, so every member meets the tolerance it would meet alone; see "
        "`SweepSettings.batching`), sharded with `shard_map` over the CPU devices. "
        "scipy: `solve_ivp` per point in two pieces, [0, 1/(2f)] and [1/(2f), t1] (the restart "
        "at the switch-off is scipy's equivalent of `jump_ts`), numpy right-hand side checked "
        "against `GlobalModel.accelerations`, no event (this hardening chain cannot diverge; "
        "leaving the event out only favours scipy).",
        "",
        f"scipy ran on {n_scipy} random points of each system's {map_size:,}-point grid (the "
        "same points for both methods, run interleaved point by point). gmr_jax per "
        "trajectory = warm `basin_map` wall time over the whole grid / points. "
        "Speed ratio = scipy mean wall time per point / gmr_jax wall time per trajectory. "
        "Agreement = same configuration code as the gmr_jax map at the same (f, A).",
        "",
    ]


def compare_tables(cmp_rows, disagreements):
    modes = list(MODES)
    out = [
        "## Per point: scipy vs gmr_jax", "",
        "| cells | scipy points | RK45 mean (ms) | DOP853 mean (ms) | "
        + " | ".join(f"gmr_jax {m} (us/traj)" for m in modes) + " | "
        + " | ".join(f"ratio RK45, {m}" for m in modes) + " | ratio DOP853, all cores | CPU-time ratio RK45 |",
        "|---:|---:|---:|---:|" + "---:|" * (2 * len(modes) + 2),
    ]
    for r in cmp_rows:
        rk, dp = r["RK45"], r["DOP853"]
        out.append(
            f"| {r['n']} | {r['points']} | {1e3 * rk['mean']:.1f} | {1e3 * dp['mean']:.1f} | "
            + " | ".join(f"{1e6 * r['gmr_per'][m]:.0f}" for m in modes) + " | "
            + " | ".join(f"**{rk['ratio'][m]:.0f}x**" if m == "all cores" else f"{rk['ratio'][m]:.0f}x"
                         for m in modes)
            + f" | {dp['ratio']['all cores']:.0f}x | {rk['cpu_ratio']:.0f}x |")
    out += [
        "",
        "Ratio = scipy mean wall time per point / gmr_jax wall time per trajectory (warm call over the "
        "whole grid). 'all cores': the default sweep (native kernel) on every CPU core; '1 core': the same on "
        "one thread; 'all cores, joint': the joint XLA sweep sharded over every core (`gmr.use_cpu_cores()`); "
        "'1 core, member': the earliest method (`batching=\"member\"`, "
        "`vmap` of one `diffeqsolve` per point). CPU-time ratio: process CPU seconds on both sides (it charges "
        "gmr_jax for every core it used; scipy uses one).",
        "",
        "| cells | scipy points | RK45 fevals/point | DOP853 fevals/point | agree RK45 | "
        "agree DOP853 | RK45 = DOP853 | gmr_jax unsettled on these points |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in cmp_rows:
        rk, dp, k = r["RK45"], r["DOP853"], r["points"]
        out.append(
            f"| {r['n']} | {k} | {rk['nfev']:.0f} | {dp['nfev']:.0f} | {rk['agree']}/{k} "
            f"({100 * rk['agree'] / k:.1f} %) | {dp['agree']}/{k} ({100 * dp['agree'] / k:.1f} %) "
            f"| {r['rk_vs_dop']}/{k} | {r['gmr_unsettled']} |")
    tot = sum(r["points"] for r in cmp_rows)
    out.append("")
    for meth in METHODS:
        a = sum(r[meth]["agree"] for r in cmp_rows)
        out.append(f"All systems, {meth}: {a}/{tot} points agree ({100 * a / tot:.2f} %).  ")
    if disagreements:
        out += ["", "Disagreements (cells, method, f, A: gmr_jax config vs scipy config):", ""]
        out += [f"- {n}, {meth}, f = {f:.4g} Hz, A = {a:.4g} N: {cg} vs {cs}"
                for n, meth, f, a, cg, cs in disagreements]
    return out + [""]


def size_table(rows, title, note=None):
    out = [f"## {title}", ""]
    if note:
        out += [note, ""]
    out += [
        "| system | gmr_jax | points | grid (A x f) | chunk | cold call (s) | warm call (s) | compile (s) | "
        "us/traj | CPU us/traj | traj/s | steps/traj | recompiled on warm call | configs seen | unsettled |",
        "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        out.append(
            f"| {r['label']} | {r['mode']} | {r['n']:,} | {r['shape']} | {r['chunk']} | {fmt(r['cold'])} | "
            f"{fmt(r['warm'])} | {fmt(r['compile'])} | {1e6 * r['per']:.0f} | "
            f"{1e6 * r['cpu_per']:.0f} | {r['tps']:.0f} | {r['steps']:.0f} | {r['recompiled']} | {r['n_cfg']} | "
            f"{100 * r['unsettled']:.1f} % |")
    return out + [""]


SIZE_NOTE = (
    "Cold call = first `basin_map` call at that size (trace + compile + run); warm call = a "
    "second call on a grid of the same size with every f and A value moved (both ends inwards "
    "by half a grid step); no recompile on the warm call (checked: XLA compilations during the warm "
    "call, counted with `jax.monitoring`); compile = "
    "cold - warm (on the largest grids the compile is within the run-to-run noise of the two "
    "calls). CPU us/traj: process CPU time of the warm call (all threads) per trajectory. "
    "'configs seen' and 'unsettled' are read off the warm call's map.")


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--quick", action="store_true",
                   help="about a minute: 1e2/1e3 grids, 50 scipy points per system")
    p.add_argument("--scipy-points", type=int, default=None,
                   help="random grid points per system (default 200; 50 with --quick)")
    p.add_argument("--max-1e5-s", type=float, default=300.0,
                   help="run the 1e5 grid (cold + warm call) only when predicted below this (s)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=str(RESULTS / "bench_basins.md"))
    args = p.parse_args()
    cmd = " ".join(["python benchmarks/bench_basins.py"] + sys.argv[1:])
    quick = args.quick
    n_scipy = args.scipy_points or (50 if quick else 200)
    map_size = 1000 if quick else 10_000  # grid of the per-cell rows and the scipy comparison
    sizes = (100, 1000) if quick else (100, 1000, 10_000)
    t_start = time.perf_counter()
    load0 = os.getloadavg()

    models, wells = {}, {}
    for n in CELLS:
        models[n] = make_model(n)
        wells[n] = stable_wells(models[n], [[-3 * WELL, 3 * WELL]] * n)
        np.testing.assert_allclose(wells[n], [[-WELL, WELL]] * n, atol=1e-6)
        check_rhs(models[n], n)
    m5, w5, lab5 = models[SCALING_CELLS], wells[SCALING_CELLS], f"{SCALING_CELLS} cells"

    print("gmr_jax: grid size", flush=True)
    size_rows = [size_row(m5, w5, s, CHUNK, lab5) for s in sizes]
    base = size_rows[-1]  # map_size points, all cores
    skipped_1e5 = None
    if not quick:
        predicted = 2 * 10 * base["warm"] + base["compile"]  # cold + warm call
        if predicted <= args.max_1e5_s:
            size_rows.append(size_row(m5, w5, 100_000, CHUNK, lab5))
        else:
            skipped_1e5 = predicted
            print(f"  1e5 skipped (predicted {predicted:.0f} s)", flush=True)

    print("gmr_jax: number of cells, three ways", flush=True)
    cell_rows = {}  # (n, mode) -> row
    for n in CELLS:
        for mode in MODES:
            if n == SCALING_CELLS and mode == "all cores":
                cell_rows[n, mode] = base
            else:
                cell_rows[n, mode] = size_row(models[n], wells[n], map_size, CHUNK, f"{n} cells", mode)

    print("gmr_jax: chunk", flush=True)
    chunk_rows = [size_row(m5, w5, map_size, c, lab5, "all cores, joint") for c in (128, 256, 512)]

    print("scipy", flush=True)
    rng = np.random.default_rng(args.seed)
    cmp_rows, disagreements = [], []
    for n in CELLS:
        rows_n = {mode: cell_rows[n, mode] for mode in MODES}
        r, d = scipy_compare(n, wells[n], rows_n["all cores"]["map"], n_scipy, rng, rows_n)
        cmp_rows.append(r)
        disagreements += d
    same = {n: int(np.sum(np.asarray(cell_rows[n, "1 core, member"]["warm_map"].config)
                          == np.asarray(cell_rows[n, "all cores"]["warm_map"].config))) for n in CELLS}

    total = time.perf_counter() - t_start
    load1 = os.getloadavg()

    L = ["# Basin sweeps: gmr_jax `basin_map` vs a loop of scipy `solve_ivp`", "",
         f"Generated by `{cmd}` ({'quick' if quick else 'full'} run, {total:.0f} s in all).", ""]
    tot = sum(r["points"] for r in cmp_rows)
    agree = {m: sum(r[m]["agree"] for r in cmp_rows) for m in METHODS}
    ratios = {mode: ", ".join(f"{r['RK45']['ratio'][mode]:.0f}x" for r in cmp_rows) for mode in MODES}
    head = [cell_rows[n, "all cores"] for n in CELLS]
    L += ["Summary: classification agreement with scipy "
          + ", ".join(f"{m} {agree[m]}/{tot}" for m in METHODS)
          + f"; per-point speed ratio vs scipy RK45 (scipy wall per point / gmr_jax wall per trajectory) for "
          f"{', '.join(str(n) for n in CELLS)} cells: default (native) all cores {ratios['all cores']}; one core "
          f"{ratios['1 core']}; joint XLA sweep, all cores {ratios['all cores, joint']}; earlier per-member "
          f"vmap, one core {ratios['1 core, member']}. gmr_jax "
          f"throughput at {map_size:,} points (all cores): "
          + ", ".join(f"{r['tps']:.0f}" for r in head) + " trajectories/s; compile "
          f"{min(r['compile'] for r in head):.1f}-{max(r['compile'] for r in head):.1f}"
          " s per grid size and configuration. The default and per-member batching give the same "
          "configuration on " + ", ".join(f"{same[n]}/{map_size}" for n in CELLS) + " points.", ""]
    L += problem_text(map_size, n_scipy)
    L += compare_tables(cmp_rows, disagreements)
    L += size_table(size_rows, f"gmr_jax: cost vs grid size ({lab5}, default chunk, all cores)", SIZE_NOTE)
    last = size_rows[-1]
    if skipped_1e5 is not None:
        L += [f"1e5 points skipped: predicted {skipped_1e5:.0f} s (cold + warm) > "
              f"{args.max_1e5_s:g} s; linear extrapolation from {last['n']:,} points: "
              f"~{1e5 * last['per']:.0f} s per warm call.", ""]
    if quick:
        L += [f"Quick run: 1e4 and 1e5 not run; linear extrapolation from {last['n']:,} "
              f"points: ~{1e4 * last['per']:.0f} s and ~{1e5 * last['per']:.0f} s per warm "
              "call.", ""]
    L += size_table([cell_rows[n, mode] for n in CELLS for mode in MODES],
                    f"gmr_jax: cost vs number of cells ({map_size:,} points, default chunk)")
    L += size_table(chunk_rows, f"gmr_jax: cost vs chunk ({lab5}, {map_size:,} points, all cores)")
    L += [f"Machine: {platform.machine()}, {os.cpu_count()} CPUs, load average {load0[0]:.2f} "
          f"at the start and {load1[0]:.2f} at the end (a shared machine: other jobs may run "
          "meanwhile, so absolute times are noisy). JAX "
          f"{jax.__version__} on {jax.devices()[0].platform} ({len(jax.devices())} devices), "
          f"diffrax {diffrax.__version__}, equinox {equinox.__version__}, scipy "
          f"{scipy.__version__}, numpy {np.__version__}, Python {platform.python_version()}, "
          f"EQX_ON_ERROR={os.environ['EQX_ON_ERROR']}, float64.", ""]
    text = "\n".join(L)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
