"""`gmr basins MODEL.json --f F0:F1:NF --A A0:A1:NA --out DIR` (contracts, "Basin map")."""

import argparse
import time
from pathlib import Path

import numpy as np

from ._args import (draw_box, find_wells, grid, output_dir, positive_float, positive_int, recorded_range, start_configuration,
                    tolerance)
from .._errors import GMRInputError
from ._progress import stage


def register(sub):
    b = sub.add_parser("basins", help="deployment basins over an (f, A) grid of the Eq. (25) tip half-sine")
    b.add_argument("model", help="gmr-model/1 JSON")
    b.add_argument("--f", required=True, help="frequencies START:STOP:NUM (Hz)")
    b.add_argument("--A", required=True, help="amplitudes START:STOP:NUM (force units)")
    b.add_argument("--x-range", default=None, help="LO:HI deformation interval to search for wells (default: the "
                   "stable roots of the model's restoring polynomial, within the training data range when the file "
                   "records it)")
    b.add_argument("--settle-time", type=positive_float, default=None,
                   help="free time after the load before the final state is judged, s (default: the model's own, "
                        "the time its slowest free vibration about its wells takes to decay a thousandfold, at "
                        "least 10 s; 10 s for a model whose free motion does not decay)")
    b.add_argument("--load", type=load_spec, default="tip",
                   help="tip: force A sin(2 pi f t) on the last mass (Eq. 25, default); node:K: the same force on "
                   "mass (node) K, counted from 0; base: the same half-sine as base acceleration (A in m/s^2)")
    b.add_argument("--start", default=None, help="start configuration, e.g. 0-0-0-0-0, one well index per DOF (per "
                   "element of a graph model; 0 for its one-well couplers) (default: every cell in its first well)")
    b.add_argument("--rtol", type=tolerance, default=1e-6, help="relative tolerance, 0 < rtol < 1 (default 1e-6)")
    b.add_argument("--atol", type=tolerance, default=1e-8, help="absolute tolerance, 0 < atol < 1 (default 1e-8)")
    b.add_argument("--batching", choices=["auto", "native", "lanes", "joint", "member"], default="auto",
                   help="auto (default) = lanes: diffrax's solver and step-size controller, each point with its own "
                        "step control, in lanes that take the next point when one is done (any model, CPUs and "
                        "GPUs); native: an opt-in C kernel generated from the model (the same queue, 16 points at a "
                        "time in vector registers, all cores, 3-5x faster on a CPU; needs a C compiler, float64 "
                        "polynomial models, tsit5/dopri5/dopri8); joint: each chunk as one ODE with a shared step; "
                        "member: vmap of one solve per point")
    b.add_argument("--solver", choices=["tsit5", "dopri5", "dopri8", "kvaerno5"], default="tsit5",
                   help="diffrax solver of each point (default tsit5; kvaerno5: implicit, for a stiff chain)")
    b.add_argument("--chunk", type=positive_int, default=None,
                   help="lanes per device (lanes: default 128 on a CPU, 32768 on a GPU) or points integrated "
                        "together (joint, member: default about 1280 / DOFs, 64-512)")
    b.add_argument("--cpu-devices", type=positive_int, default=None,
                   help="CPU cores to use (default: all; ignored on GPU/TPU)")
    b.add_argument("--draws", type=int, default=0,
                   help="also sweep this many models drawn from the model file's covariance (gmr.basin_probability): "
                        "the probability of each final configuration per grid point, basins_probability.npz and "
                        "basins_confidence.png (default 0: off; needs a fitted model's covariance)")
    b.add_argument("--out", required=True)
    b.set_defaults(fn=run)
    return b


_COMPILE = {"seconds": 0.0, "listening": False}


def _compile_seconds() -> float:
    """XLA and C (native kernel) compile time of this process so far (one listener, registered
    on first use: a second `run` in the same process, e.g. in tests, does not add another)."""
    from .._basins._native import BUILD_SECONDS

    if not _COMPILE["listening"]:
        import jax

        def listen(event, secs, **kwargs):
            if event == "/jax/core/compile/backend_compile_duration":
                _COMPILE["seconds"] += secs

        jax.monitoring.register_event_duration_secs_listener(listen)
        _COMPILE["listening"] = True
    return _COMPILE["seconds"] + BUILD_SECONDS[0]


def _probability(gmr, model, args, f, A, x0, settings, out, wells) -> None:
    """`--draws N`: the map over N models drawn from the file's covariance (`gmr.basin_probability`, wells searched
    in the span of the model's own wells widened by half of it, as `find_wells` reads the data range), written to
    basins_probability.npz and drawn (the probability of the most likely configuration) in basins_confidence.png."""
    import jax
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if model.covariance is None:
        raise GMRInputError(f"--draws: {args.model} has no covariance (a model written by gmr fit has one); "
                            f"drop --draws to map the model itself")
    box = draw_box(wells)
    stage(f"sweeping {args.draws} models drawn from the covariance")
    sol = gmr.basin_probability(model, f, A, jax.random.key(0), args.draws, x_range=box, x0=x0, settings=settings,
                                chunk=args.chunk)
    bp, st = sol.value, sol.stats
    if st["samples_used"] == 0:
        print(f"gmr basins: warning: --draws: none of the {st['samples_drawn']} models drawn from the covariance has "
              f"the model's wells and a dissipative damping ({st['samples_other_wells']} with other wells, "
              f"{st['samples_non_dissipative']} feeding energy in): the covariance is too wide to map; no "
              f"probability written")
        return
    conf = np.asarray(bp.confidence)
    np.savez(out / "basins_probability.npz", f=f, A=A, configs=np.asarray(bp.configs),
             probability=np.asarray(bp.probability), most_likely=np.asarray(bp.most_likely), confidence=conf,
             mean_config=np.asarray(bp.mean_config), unsettled=np.asarray(bp.unsettled))
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    im = ax.pcolormesh(f, A, conf, vmin=0.0, vmax=1.0, cmap="viridis", shading="nearest")
    fig.colorbar(im, ax=ax, label="probability of the most likely configuration")
    ax.set_xlabel("f (Hz)")
    ax.set_ylabel("A")
    ax.set_title(f"{Path(args.model).stem}: {st['samples_used']} models drawn from its covariance")
    fig.savefig(out / "basins_confidence.png", dpi=100, bbox_inches="tight")
    plt.close(fig)
    agree = float(np.mean(np.asarray(bp.most_likely) == np.asarray(bp.mean_config)))
    print(f"  drawn models: {st['samples_used']} used of {st['samples_drawn']} drawn ({st['samples_other_wells']} "
          f"with other wells, {st['samples_non_dissipative']} whose damping feeds energy in); every one agrees at "
          f"{100 * float(np.mean(conf == 1.0)):.3g} % of the points, the most likely configuration at least 90 % "
          f"likely at {100 * float(np.mean(conf >= 0.9)):.3g} %; the model's own map is the most likely at "
          f"{100 * agree:.3g} % (basins_probability.npz, basins_confidence.png)")
    configs = np.asarray(bp.configs)
    if np.any(configs == -1):
        lost = np.asarray(bp.probability)[..., int(np.argmax(configs == -1))]
        unsettled = np.asarray(bp.unsettled)
        most = int(np.sum(np.asarray(bp.most_likely) == -1))
        print(f"gmr basins: warning: --draws: {100 * float(np.mean(lost)):.3g} % of the drawn runs ended in no well "
              f"(configuration -1): {100 * float(np.mean(unsettled)):.3g} % had not settled (lengthen --settle-time, "
              f"now {args.settle_time:g} s), {100 * float(np.mean(lost - unsettled)):.3g} % failed or diverged; the "
              f"most likely outcome at {most} of {conf.size} points, whose maps are unknown")


def _beyond_data(model, model_path, A, load: str) -> tuple[str, float] | None:
    """Where the grid's loads must push the model beyond the range it was fitted on: the largest restoring
    force each DOF (cell) reached over its training range (the model file's `data_range`, `gmr fit`) against
    the static force the load puts on it (tip: A on every cell of a chain, on the last DOF of independent
    ones; base: A times the masses it carries). Above A* = the smallest such ratio no static equilibrium of
    the load lies in the range, so the trajectory leaves it and the map extrapolates the model (a bound:
    the dynamic overshoot leaves it at lower A too). A sentence and A*, or None (no data range, or no A above A*)."""
    d = model.n_dof
    rng = recorded_range(model_path, d)
    if rng is None or np.max(A) <= 0:
        return None
    stiff = np.asarray(model.stiffness, float)
    masses = np.asarray(model.masses, float)
    if load == "base":
        per = np.asarray(model.topology.carried(masses[None, :]))[0]
    elif model.topology.name == "chain":
        per = np.ones(d)
    else:
        per = np.where(np.arange(d) == d - 1, 1.0, 0.0)
    stars = []
    for i in range(d):
        if per[i] <= 0:
            continue
        f = np.polynomial.polynomial.polyval(np.linspace(rng[i, 0], rng[i, 1], 401), stiff[i])
        stars.append((max(float(np.max(f)), 0.0) / per[i], i))  # a positive load pushes towards +x
    if not stars:
        return None
    a_star, i = min(stars)
    over = int(np.sum(A > a_star))
    if over == 0:
        return None
    roots = np.polynomial.polynomial.polyroots(stiff[i] - np.eye(stiff.shape[1])[0] * float(np.max(A)) * per[i])
    out = roots[(np.abs(roots.imag) < 1e-9) & (roots.real > rng[i, 1])].real
    where = (f"the static deflection at A = {float(np.max(A)):.4g} is x = {float(np.min(out)):.4g}" if out.size else
             f"at A = {float(np.max(A)):.4g} the model has no static equilibrium beyond it")
    return (f"at A > {a_star:.4g} ({over} of {A.size} amplitudes) the load exceeds the largest restoring force "
            f"{'cell' if model.topology.name == 'chain' and d > 1 else 'DOF'} {i} reached over its recorded range "
            f"[{rng[i, 0]:.4g}, {rng[i, 1]:.4g}] (the model file's data_range; {where}): those trajectories go "
            f"beyond the motion the model was fitted on, and the map there is the model's extrapolation (a static "
            f"bound: dynamic overshoot goes beyond at lower A too)", a_star)


def _settle_advice(model, wells, settle_time: float) -> str:
    """What to pass where points had not settled: the slowest decay rate sigma of the model's free
    motion about its stable configurations (`slowest_decay`), and the settle time 7 / sigma in
    which that mode decays a thousandfold."""
    from .._basins._settle import DECAYS, slowest_decay

    sigma, scale = slowest_decay(model, wells)
    if not np.isfinite(sigma):
        return f"points not settled: lengthen --settle-time (now {settle_time:g} s)"
    if sigma <= 1e-9 * scale:  # rounding of a purely imaginary pair
        return (f"points not settled: the model's free motion about a configuration of its wells does not decay "
                f"(slowest linearised decay rate {sigma:.3g} 1/s: no damping there), so no settle time will do; "
                f"check its damping terms")
    need = DECAYS / sigma
    return (f"points not settled: the model's slowest free vibration about its wells decays at {sigma:.3g} 1/s "
            f"(time constant {1 / sigma:.3g} s), so it needs about {need:.3g} s to settle "
            f"(now {settle_time:g} s): rerun with --settle-time {float(f'{need:.2g}'):g}")


#: `gmr basins` notes a barrier whose crossing takes more than this many times the fastest recorded speed
SPEED_FACTOR = 2.0


def _beyond_speed(model, model_path, wells, x0) -> str | None:
    """Where crossing a barrier takes speeds the damping law was not fitted at: from each DOF's start well, the
    lowest barrier dV of the model's restoring law to a neighbouring well gives the speed sqrt(2 dV / m) a
    crossing needs at the least (m the mass the DOF's deformation moves: for a chain cell, every mass it carries); above `SPEED_FACTOR` times the fastest recorded speed (the model file's
    `speed_range`), the damping there is the local law extrapolated. Small vibrations do not show terms that act
    at speed (v^3, v|v|, x^2 v far from the wells), and the file's band does not include them (audit: a v^3 term
    left out, the damping at crossing speeds 2.6 x low with a ±0.3 % band, 70 % basin agreement). A sentence, or
    None (no speed_range, or crossings within it)."""
    from ._show import barriers, equilibria

    d = model.n_dof
    vr = recorded_range(model_path, d, "speed_range")
    if vr is None:
        return None
    vmax = np.max(np.abs(vr), axis=1)
    # the mass a cell's deformation moves: every mass it carries (a chain: itself and the masses above it)
    masses = np.asarray(model.topology.carried(np.asarray(model.masses, float)[None, :]))[0]
    eqs = equilibria(model.stiffness)
    worst = None
    for i, rows in enumerate(barriers(model.stiffness, eqs)):
        start = float(np.asarray(wells)[i, 0] if x0 is None else np.asarray(x0)[i])  # default: the first well
        tol = 1e-6 * max(1.0, abs(start)) + 1e-9
        heights = [b[f"from_{side}"] for b in rows for side in ("left", "right")
                   if abs(b[side] - start) < tol and b[f"from_{side}"] > 0]
        if not heights or vmax[i] <= 0:
            continue
        need = float(np.sqrt(2.0 * min(heights) / masses[i]))
        if need > SPEED_FACTOR * vmax[i] and (worst is None or need / vmax[i] > worst[0]):
            worst = (need / vmax[i], i, need)
    if worst is None:
        return None
    ratio, i, need = worst
    return (f"crossing DOF {i}'s barrier from its start well takes |v| of at least {need:.3g} "
            f"(sqrt(2 barrier / mass)), {ratio:.3g} x the fastest recorded ({vmax[i]:.3g}, the model file's "
            f"speed_range): the damping along the crossings is the small vibrations' law extrapolated; terms that "
            f"act only at speed (v^3, v|v|) are not in those data and not in the band, and the map's boundaries "
            f"depend on the damping. Where the structure may have them, record a motion at those speeds (a "
            f"crossing record: gmr refine --free damping) before trusting the boundaries")


def load_spec(text: str) -> str:
    """--load: tip, base or node:K."""
    from .._basins._lanes import node_of

    if text in ("tip", "base") or node_of(text) is not None:
        return text
    raise argparse.ArgumentTypeError(f"--load must be tip, base or node:K (K a mass index from 0), got {text!r}")


def run(args) -> int:
    import gmr_jax as gmr

    n_cpu = gmr.use_cpu_cores(args.cpu_devices, strict=False)  # before any JAX computation
    import diffrax as dfx
    import jax

    from ..plots._basins import basin_figure, counts_figure, well_label

    f, A = grid(args.f, "f"), grid(args.A, "A")
    stage("loading the model, finding its wells")
    out = output_dir(args.out)
    model = gmr.load_model(args.model)
    wells, how = find_wells(model, args.x_range, args.model)
    graph = isinstance(model.topology, gmr.Graph)
    if graph and args.draws:
        raise GMRInputError("--draws sweeps chains and independent DOFs; a graph model's map is swept once (drop "
                            "--draws)")
    x0 = start_configuration(args.start, wells, model if graph else None)
    if args.settle_time is None:
        from .._basins._settle import model_settle_time

        need = model_settle_time(model, wells, configurations=[x0] if graph else None)
        args.settle_time = 10.0 if need is None else need
        print(f"gmr basins: settle time {args.settle_time:g} s after the load ("
              + ("the model's slowest free vibration about its wells decays a thousandfold in it"
                 if need is not None else "its free motion about its wells does not decay") + "; --settle-time to change)")
    settings = gmr.SweepSettings(settle_time=args.settle_time, load=args.load, batching=args.batching,
                                 solver=getattr(dfx, args.solver.capitalize())(),  # tsit5 -> diffrax.Tsit5
                                 integrator=gmr.Integrator(rtol=args.rtol, atol=args.atol, max_steps=100_000))
    n = f.size * A.size
    devs = jax.devices()
    print(f"gmr basins: {n} points ({A.size} amplitudes x {f.size} frequencies), {args.load} half-sine (Eq. 25), "
          f"wells per {'element' if graph else 'DOF'}: {[np.round(w[~np.isnan(w)], 6).tolist() for w in wells]} ({how}); "
          f"{len(devs)} {devs[0].platform} device(s)" + (f" ({n_cpu} CPU cores)" if devs[0].platform == "cpu" else ""))
    t0 = time.perf_counter()

    def progress(done, total):
        k = int(40 * done / total)
        print(f"\r  [{'#' * k}{'.' * (40 - k)}] {done}/{total} points, {time.perf_counter() - t0:.0f} s",
              end="", flush=True)

    compiled_before = _compile_seconds()
    stage(f"integrating {n} trajectories (compiling unless the compilation cache has it)")
    sol = gmr.basin_map(model, f, A, wells, x0=x0, settings=settings, chunk=args.chunk, progress=progress,
                        throw=False, devices=None if args.cpu_devices is None else devs)
    bm = sol.value
    wall = time.perf_counter() - t0
    print()
    cat = {key: np.asarray(getattr(bm, key)) for key in ("wells", "config", "result", "x_final", "v_final", "steps")}
    cat["counts"] = np.asarray(bm.counts())
    np.savez(out / "basins.npz", f=f, A=A, **cat)
    beyond = None if graph or args.load.startswith("node") else _beyond_data(model, args.model, A, args.load)
    title = f"{Path(args.model).stem}: final configuration, {args.load} half-sine (Eq. 25)"
    if graph:
        counts_figure(f, A, cat["counts"], out / "basins.png", title=title, load=args.load)
        vals, counts = np.unique(cat["counts"], return_counts=True)
        for v, c in zip(vals, counts):
            label = "not classified" if v < 0 else f"{int(v)} element(s) outside their first well"
            print(f"  {label:40s} {c:7d} points")
    else:
        basin_figure(f, A, cat["config"], model.n_dof, out / "basins.png", title=title, wells=wells,
                     load=args.load, extrapolated_above=beyond[1] if beyond else None)
        vals, counts = np.unique(cat["config"], return_counts=True)
        for v, c in zip(vals, counts):
            print(f"  {well_label(int(v), model.n_dof, wells):22s} {c:7d} points")
    bad = cat["config"] < 0
    if np.any(bad):
        from .._solution import code_name

        codes, cc = np.unique(cat["result"][bad], return_counts=True)
        why = ", ".join(f"{c} {code_name(k).replace('_', ' ')}" for k, c in zip(codes, cc))
        print(f"  -1 (not classified): {why}")
        if np.any(cat["result"][bad] == gmr.RESULTS.not_settled._value):
            print(f"  {_settle_advice(model, wells, args.settle_time)}")
    comp = _compile_seconds() - compiled_before
    if sol.stats.get("sign_eps"):
        print(f"  Coulomb friction sgn(v) integrated as tanh(v / {sol.stats['sign_eps']:.3g}): exact above a tenth "
              f"of the settled-speed test (SweepSettings.sign_eps)")
    print(f"{n} points in {wall:.1f} s ({n / wall:.0f} trajectories/s, batching {sol.stats['batching']}); of which "
          f"compiling {comp:.1f} s" + ("" if comp > 0 else " (compiled programs loaded from the cache)"))
    if args.draws:
        _probability(gmr, model, args, f, A, x0, settings, out, wells)
    if beyond:
        print(f"  note: {beyond[0]}")
    fast = None if graph else _beyond_speed(model, args.model, wells, x0)
    if fast:
        print(f"  note: {fast}")
    print(f"wrote {out}/basins.npz and basins.png (.pdf)")
    stage("done")
    return 0
