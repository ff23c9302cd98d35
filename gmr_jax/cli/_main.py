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
    from ._demo import run_demo

    run_demo(args.out)
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


def build_parser():
    p = argparse.ArgumentParser(prog="gmr", description="Global model reconstruction of multi-stable structures")
    sub = p.add_subparsers(dest="cmd", required=True)
    d = sub.add_parser("demo", help="run the built-in paper cases (GMR vs GMC-SINDy), write figures and a report")
    d.add_argument("--out", default="gmr_out", help="output folder (default gmr_out)")
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
