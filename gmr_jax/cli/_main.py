"""The `gmr` command line (formats and shapes: README, "Command line")."""

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from .._errors import GMRInputError


def _positive_int(s):
    v = int(s)
    if v < 1:
        raise argparse.ArgumentTypeError("must be >= 1")
    return v


def _cmd_demo(args):
    if args.system == "paper":
        from ._demo import run_demo

        run_demo(args.out)
    else:
        from ._demo_chain import run_chain_demo

        run_chain_demo(args.system, args.out)
    return 0


def _cmd_fit(args):
    from .._reconstruct import DEFAULT_SOLVER, gmc_sindy, reconstruct
    from ..local._library import Library
    from ..local._local_fit import AutoThreshold
    from ..model._io import save_model
    from ..recordings._recording import load_recording

    recs = [load_recording(p) for p in args.recordings]
    lib = Library(args.restoring_order, args.damping_order,
                  velocity_damping=not args.no_velocity_damping,
                  position_damping=not args.no_position_damping)
    if args.threshold == "auto":
        solver, select = DEFAULT_SOLVER, AutoThreshold()
    else:
        try:
            thr = float(args.threshold)
        except ValueError:
            raise GMRInputError(f"--threshold must be 'auto' or a number, got {args.threshold!r}") from None
        if not np.isfinite(thr) or thr < 0:
            raise GMRInputError(f"--threshold must be a non-negative number, got {thr}")
        from ..local._stls import STLS

        solver, select = STLS(thr, 0.0, normalize_columns=True), None
    masses = None
    if args.masses:
        try:
            masses = [float(m) for m in args.masses.split(",")]
        except ValueError:
            raise GMRInputError(f"--masses must be comma-separated numbers, got {args.masses!r}") from None
    fn = gmc_sindy if args.method == "gmc-sindy" else reconstruct
    res = fn(recs, lib, solver, select, topology=args.topology, masses=masses)
    save_model(res.model, args.out, method=res.method, library={"r": lib.restoring_order, "d": lib.damping_order},
               training=res.training)
    print(f"{res.method} model from {len(recs)} recording(s) -> {args.out}")
    for line in res.model.equations():
        print("  " + line)
    for i, rep in enumerate(res.dofs):
        if rep.equilibria.size:
            print(f"  DOF {i}: equilibria {np.round(rep.equilibria, 6).tolist()}, global orders "
                  f"K_r={rep.stats['K_r']}, K_d={rep.stats['K_d']}")
    for name, sc in res.training.items():
        print(f"  training {name}: R2 {np.round(sc['r2'], 5).tolist()}, NRMSE {np.round(sc['nrmse'], 5).tolist()}")
    if any(r.v is None or r.a is None for r in recs):
        print("  note: velocities/accelerations were estimated from x (Savitzky-Golay, see README)")
    return 0


def _grid(spec, name):
    try:
        a, b, n = spec.split(":")
        a, b, n = float(a), float(b), int(n)
    except ValueError:
        raise GMRInputError(f"--{name} must be START:STOP:NUM, e.g. 0.1:5:50, got {spec!r}") from None
    if n < 1 or not (np.isfinite(a) and np.isfinite(b)) or (name == "f" and min(a, b) <= 0):
        raise GMRInputError(f"--{name} {spec!r}: need NUM >= 1, finite bounds (and f > 0)")
    return np.linspace(a, b, n)


def _start(spec, wells):
    """x0 from a configuration label like 0-1-1-0-0 (cell 0 first; a digit = that cell's well)."""
    if spec is None:
        return None
    try:
        idx = [int(c) for c in spec.split("-")]
    except ValueError:
        raise GMRInputError(f"--start must look like 0-1-1-0-0 (one well index per DOF), got {spec!r}") from None
    n_wells = np.sum(~np.isnan(wells), axis=1)
    if len(idx) != wells.shape[0] or any(k < 0 or k >= n for k, n in zip(idx, n_wells)):
        raise GMRInputError(f"--start {spec!r}: need {wells.shape[0]} well indices, each below that DOF's "
                            f"number of wells {n_wells.tolist()}")
    return np.array([wells[i, k] for i, k in enumerate(idx)])


def _cmd_basins(args):
    import time

    from .._config import use_cpu_cores

    n_cpu = use_cpu_cores(args.cpu_devices, strict=False)  # before any JAX computation
    import jax

    from ..basins._sweep import RESULTS, SweepSettings, basin_map
    from ..basins._wells import stable_wells
    from ..model._io import load_model
    from ..plots._basins import basin_figure, config_label

    model = load_model(args.model)
    f, A = _grid(args.f, "f"), _grid(args.A, "A")
    if not args.x_range:
        raise GMRInputError("--x-range=LO:HI is needed: the deformation interval in which to look for wells")
    try:
        lo, hi = (float(v) for v in args.x_range.split(":"))
    except ValueError:
        raise GMRInputError(f"--x-range must be LO:HI (write --x-range=-0.05:0.05), got {args.x_range!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise GMRInputError(f"--x-range {args.x_range!r}: need finite LO < HI")
    wells = stable_wells(model, [[lo, hi]] * model.n_dof)
    if np.any(np.isnan(wells[:, 0])):
        raise GMRInputError(f"no stable equilibrium found in [{lo}, {hi}] for some DOF: widen --x-range")
    x0 = _start(args.start, wells)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    settings = SweepSettings(settle_time=args.settle_time, load=args.load, batching=args.batching,
                             rtol=args.rtol, atol=args.atol)
    n = f.size * A.size
    devs = jax.devices()
    print(f"gmr basins: {n} points ({A.size} amplitudes x {f.size} frequencies), {args.load} half-sine (Eq. 25), "
          f"wells per DOF: {[np.round(w[~np.isnan(w)], 6).tolist() for w in wells]}; "
          f"{len(devs)} {devs[0].platform} device(s)" + (f" ({n_cpu} CPU cores)" if devs[0].platform == "cpu" else ""))
    t0 = time.perf_counter()

    def progress(done, total):
        k = int(40 * done / total)
        print(f"\r  [{'#' * k}{'.' * (40 - k)}] {done}/{total} points, {time.perf_counter() - t0:.0f} s",
              end="", flush=True)

    bm = basin_map(model, f, A, wells, x0=x0, settings=settings, chunk=args.chunk, progress=progress)
    wall = time.perf_counter() - t0
    print()
    cat = {key: np.asarray(getattr(bm, key)) for key in ("wells", "config", "result", "x_final", "v_final", "steps")}
    np.savez(out / "basins.npz", f=f, A=A, **cat)
    basin_figure(f, A, cat["config"], model.n_dof, out / "basins.png",
                 title=f"{Path(args.model).stem}: final configuration, {args.load} half-sine (Eq. 25)")
    vals, counts = np.unique(cat["config"], return_counts=True)
    for v, c in zip(vals, counts):
        print(f"  {config_label(int(v), model.n_dof):22s} {c:7d} points")
    bad = cat["config"] < 0
    if np.any(bad):
        codes, cc = np.unique(cat["result"][bad], return_counts=True)
        names = {getattr(RESULTS, m)._value: m.replace("_", " ")
                 for m in ("successful", "not_settled", "diverged", "simulation_failed")}
        why = ", ".join(f"{c} {names.get(int(k), 'code ' + str(int(k)))}" for k, c in zip(codes, cc))
        print(f"  -1 (not classified): {why}")
    print(f"{n} points in {wall:.1f} s ({n / wall:.0f} trajectories/s, compile included)")
    print(f"wrote {out}/basins.npz and basins.png")
    return 0


def build_parser():
    p = argparse.ArgumentParser(prog="gmr", description="Global model reconstruction of multi-stable structures")
    sub = p.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("demo", help="run the built-in paper cases (GMR vs GMC-SINDy), write figures and a report")
    d.add_argument("--out", default="gmr_out", help="output folder (default gmr_out)")
    d.add_argument("--system", choices=["paper", "kresling5", "kresling3"], default="paper",
                   help="paper: the single-DOF cases (default); kresling5/kresling3: a Kresling chain, per cell, "
                   "with transmissibility")
    d.set_defaults(fn=_cmd_demo)
    f = sub.add_parser("fit", help="reconstruct a global model from recordings (one per equilibrium)")
    f.add_argument("recordings", nargs="+", help="NPZ or CSV recordings")
    f.add_argument("--out", required=True, help="model JSON to write (gmr-model/1)")
    f.add_argument("--method", choices=["gmr", "gmc-sindy"], default="gmr")
    f.add_argument("--restoring-order", "-r", type=_positive_int, default=5)
    f.add_argument("--damping-order", "-d", type=_positive_int, default=5)
    f.add_argument("--threshold", default="auto", help="STLS threshold on normalised coefficients, or 'auto' "
                   "(blocked cross-validation, one-standard-error rule; default)")
    f.add_argument("--topology", choices=["chain", "independent"], default=None)
    f.add_argument("--masses", default=None, help="comma-separated masses (default: from recordings, else 1)")
    f.add_argument("--no-velocity-damping", action="store_true")
    f.add_argument("--no-position-damping", action="store_true")
    f.set_defaults(fn=_cmd_fit)
    b = sub.add_parser("basins", help="deployment basins over an (f, A) grid of the Eq. (25) tip half-sine")
    b.add_argument("model", help="gmr-model/1 JSON")
    b.add_argument("--f", required=True, help="frequencies START:STOP:NUM (Hz)")
    b.add_argument("--A", required=True, help="amplitudes START:STOP:NUM (force units)")
    b.add_argument("--x-range", default=None, help="LO:HI deformation interval to search for wells")
    b.add_argument("--settle-time", type=float, default=10.0, help="free time after the load (s)")
    b.add_argument("--load", choices=["tip", "base"], default="tip",
                   help="tip: force A sin(2 pi f t) on the last mass (Eq. 25, default); base: the same half-sine "
                   "as base acceleration (A in m/s^2)")
    b.add_argument("--start", default=None, help="start configuration, e.g. 0-0-0-0-0 (default: every DOF in its "
                   "first well)")
    b.add_argument("--rtol", type=float, default=1e-6)
    b.add_argument("--atol", type=float, default=1e-8)
    b.add_argument("--batching", choices=["joint", "member"], default="joint",
                   help="joint: each chunk as one ODE with a shared step (default, faster); member: one solve per point")
    b.add_argument("--chunk", type=_positive_int, default=None,
                   help="points integrated together (default: about 1280 / DOFs, 64-512)")
    b.add_argument("--cpu-devices", type=_positive_int, default=None,
                   help="CPU cores to shard over (default: all; ignored on GPU/TPU)")
    b.add_argument("--out", required=True)
    b.set_defaults(fn=_cmd_basins)
    from ._discover import add_parser as _add_discover

    _add_discover(sub)
    from ._actuate import add_parser as _add_actuate

    _add_actuate(sub)
    from ._refine import add_parser as _add_refine
    from ._refine import run_refine as _run_refine

    _add_refine(sub, _run_refine)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.fn(args)
    except GMRInputError as e:
        print(f"gmr {args.cmd}: error: {e}", file=sys.stderr)
        return 2
    except (OSError, json.JSONDecodeError) as e:
        print(f"gmr {args.cmd}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
