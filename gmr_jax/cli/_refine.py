"""`gmr refine MODEL.json REC.npz [...] --out REFINED.json`: output-error refinement of a model."""

import numpy as np

from .._errors import GMRInputError


def add_parser(sub, cmd_fn):
    r = sub.add_parser("refine", help="refine a model's coefficients on recordings (multiple shooting, "
                       "Levenberg-Marquardt through the simulations)")
    r.add_argument("model", help="gmr-model/1 JSON (e.g. from gmr fit)")
    r.add_argument("recordings", nargs="+", help="training recordings (NPZ or CSV)")
    r.add_argument("--out", required=True, help="refined model JSON to write (gmr-model/1)")
    r.add_argument("--holdout", nargs="+", default=None, help="recordings to report the output error on")
    r.add_argument("--free", default="all", help="coefficients to fit: all (every nonzero term; default), "
                   "stiffness, damping, velocity_damping, position_damping, or a comma-separated list")
    r.add_argument("--window", type=float, default=1.0, help="shooting window length in s (default 1)")
    r.add_argument("--max-steps", type=int, default=50, help="solver iterations (default 50)")
    r.add_argument("--stride", type=int, default=1, help="use every STRIDE-th sample in the residuals")
    r.add_argument("--max-windows", type=int, default=None, help="at most this many windows per recording")
    r.add_argument("--solver", choices=["lm", "gauss-newton"], default="lm")
    r.set_defaults(fn=cmd_fn)
    return r


def run_refine(args) -> int:
    import optimistix as optx

    from .._solution import RESULTS
    from ..model._io import load_model, save_model
    from ..recordings._recording import load_recording
    from ..refine._refine import RefineSettings, refine

    if args.max_steps < 1 or args.stride < 1 or (args.max_windows is not None and args.max_windows < 1):
        raise GMRInputError("--max-steps, --stride and --max-windows must be >= 1")
    if not (np.isfinite(args.window) and args.window > 0):
        raise GMRInputError(f"--window must be a positive number of seconds, got {args.window}")
    model = load_model(args.model)
    train = [load_recording(p) for p in args.recordings]
    hold = [load_recording(p) for p in args.holdout] if args.holdout else None
    solver = (optx.LevenbergMarquardt(rtol=1e-6, atol=1e-8) if args.solver == "lm"
              else optx.GaussNewton(rtol=1e-6, atol=1e-8))
    settings = RefineSettings(window=args.window, solver=solver, max_steps=args.max_steps, stride=args.stride,
                              max_windows=args.max_windows)
    sol = refine(model, train, free=args.free, settings=settings, holdout=hold, throw=False)
    st = sol.stats
    ok = sol.result == RESULTS.successful
    report = {"train": {k: v.as_dict() for k, v in st["train"].items()},
              "holdout": None if st["holdout"] is None else {k: v.as_dict() for k, v in st["holdout"].items()},
              "iterations": st["iterations"], "result": "successful" if ok else RESULTS[sol.result],
              "free": [list(t) for t in st["free"]]}
    print(f"gmr refine: {len(st['free'])} free coefficient(s), {st['windows']} window(s) of {args.window} s, "
          f"{st['iterations']} iteration(s)")
    for name in ("train", "holdout"):
        e = st[name]
        if e is not None:
            print(f"  {name} NRMSE: {e['before'].nrmse:.4g} -> {e['after'].nrmse:.4g} "
                  f"(failed windows {e['before'].failed} -> {e['after'].failed} of {e['after'].windows})")
    if sol.result == RESULTS.max_iterations_reached:
        ok = True  # still an improved model: write it, but say so
        print(f"gmr refine: warning: the solver used all {args.max_steps} iterations without meeting its "
              f"tolerance (raise --max-steps); writing the last iterate")
        report["result"] = "max_steps_reached"
    if not ok:
        print(f"gmr refine: error: {RESULTS[sol.result]}; the model was not written", flush=True)
        return 1
    save_model(sol.value, args.out, method="refined", refinement=report)
    for line in sol.value.equations():
        print("  " + line)
    print(f"wrote {args.out}")
    return 0
