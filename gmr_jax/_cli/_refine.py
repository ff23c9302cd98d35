"""`gmr refine MODEL.json REC.npz [...] --out REFINED.json`: output-error refinement of a model."""

import warnings

import numpy as np

from .._errors import GMRInputError
from ._args import add_columns_option, load_recordings, output_file
from ._progress import stage


def register(sub):
    r = sub.add_parser("refine", help="refine a model's coefficients on recordings (multiple shooting, "
                       "Levenberg-Marquardt through the simulations)")
    r.add_argument("model", help="gmr-model/1 JSON (e.g. from gmr fit)")
    r.add_argument("recordings", nargs="+", help="training recordings (NPZ or CSV)")
    r.add_argument("--out", required=True, help="refined model JSON to write (gmr-model/1)")
    add_columns_option(r)
    r.add_argument("--holdout", nargs="+", default=None, help="recordings to report the output error on")
    r.add_argument("--free", default="all", help="coefficients to fit: all (every nonzero term; default), "
                   "stiffness, damping, velocity_damping, position_damping, or a comma-separated list")
    r.add_argument("--window", type=float, default=1.0, help="shooting window length in s (default 1)")
    r.add_argument("--max-iterations", "--max-steps", dest="max_iterations", type=int, default=50,
                   help="least-squares solver iterations (default 50)")
    r.add_argument("--stride", type=int, default=1, help="use every STRIDE-th sample in the residuals")
    r.add_argument("--starts", choices=["estimated", "measured"], default="estimated",
                   help="each window's start state: fitted to the window's x (default; a noisy x or a v "
                   "estimated from it does not bend the coefficients) or the recorded one (cheaper)")
    r.add_argument("--max-windows", type=int, default=None, help="at most this many windows per recording")
    r.add_argument("--solver", choices=["lm", "gauss-newton"], default="lm")
    r.set_defaults(fn=run)
    return r


def run(args) -> int:
    import optimistix as optx

    import gmr_jax as gmr
    from gmr_jax import RESULTS

    from .._solution import code_name

    if args.max_iterations < 1 or args.stride < 1 or (args.max_windows is not None and args.max_windows < 1):
        raise GMRInputError("--max-iterations, --stride and --max-windows must be >= 1")
    if not (np.isfinite(args.window) and args.window > 0):
        raise GMRInputError(f"--window must be a positive number of seconds, got {args.window}")
    output_file(args.out)
    stage(f"loading the model and {len(args.recordings) + len(args.holdout or [])} recording(s)")
    model = gmr.load_model(args.model)
    train = load_recordings(args.recordings, args.columns)[0]
    hold = load_recordings(args.holdout, args.columns)[0] if args.holdout else None
    solver = (optx.LevenbergMarquardt(rtol=1e-6, atol=1e-8) if args.solver == "lm"
              else optx.GaussNewton(rtol=1e-6, atol=1e-8))
    settings = gmr.RefineSettings(window=args.window, solver=solver, max_iterations=args.max_iterations,
                                  stride=args.stride, max_windows=args.max_windows, starts=args.starts)
    stage("refining: multiple-shooting least squares (compiles the windowed solves first)")
    with warnings.catch_warnings():  # printed below as `warning:` lines
        warnings.simplefilter("ignore", gmr.GMRDataWarning)
        sol = gmr.refine(model, train, free=args.free, settings=settings, holdout=hold, throw=False)
    st = sol.stats
    ok = sol.result == RESULTS.successful
    report = {"train": {k: v.as_dict() for k, v in st["train"].items()},
              "holdout": None if st["holdout"] is None else {k: v.as_dict() for k, v in st["holdout"].items()},
              "iterations": st["iterations"], "result": "successful" if ok else RESULTS[sol.result],
              "free": [list(t) for t in st["free"]], "warnings": list(st["warnings"])}
    print(f"gmr refine: {len(st['free'])} free coefficient(s), {st['windows']} window(s) of {args.window} s, "
          f"{st['iterations']} iteration(s)")
    for name in ("train", "holdout"):
        e = st[name]
        if e is not None:
            print(f"  {name} NRMSE over {args.window:g} s windows from the recorded state: {e['before'].nrmse:.4g} -> "
                  f"{e['after'].nrmse:.4g} (failed windows {e['before'].failed} -> {e['after'].failed} of "
                  f"{e['after'].windows})")
    if sol.result in (RESULTS.successful, RESULTS.nonlinear_max_steps_reached):
        stage("checking the refined model over longer horizons (free runs)")
        longer, warn = _longer_horizons(sol.value, hold or train[:1], st["holdout" if hold else "train"], given=model,
                                        starts=args.starts)
        report["free_run"] = longer
        st["warnings"] = list(st["warnings"]) + warn
        report["warnings"] = list(st["warnings"])
        for r in longer:
            print(f"  {r['recording']}: free run over the whole record NRMSE {_pct(r['given_nrmse'])} (given) -> "
                  f"{_pct(r['nrmse'])} (refined)" + (f", over {r['horizon']:.3g} s restarts {_pct(r['given_horizon_nrmse'])}"
                                                     f" -> {_pct(r['horizon_nrmse'])}" if r["horizon"] else ""))
    for w in st["warnings"]:
        print(f"gmr refine: warning: {w}")
    if sol.result == RESULTS.nonlinear_max_steps_reached:
        ok = True  # still an improved model: write it, but say so
        print(f"gmr refine: warning: the solver used all {args.max_iterations} iterations without meeting its "
              f"tolerance (raise --max-iterations); writing the last iterate")
        report["result"] = "max_steps_reached"
    if not ok:
        print(f"gmr refine: error: {RESULTS[sol.result]} [{code_name(sol.result)}]; the model was not written",
              flush=True)
        return 1
    moved = _moved(model, sol.value)
    if moved == 0.0:
        w = (f"no free coefficient moved in {st['iterations']} iteration(s) (the solver took no step that lowered "
             f"the windowed error: windows that fail or diverge carry no gradient); the refined model is the given "
             f"one: check the windows' failures above, a shorter --window, or the model's fit to these records")
        print(f"gmr refine: warning: {w}")
        report["warnings"] = list(report["warnings"]) + [w]
    report["max_relative_change"] = moved
    given = _given_metadata(args.model, train)
    kept = [f"the given model ({args.model}): {w}" for w in given.pop("given_warnings")]
    gmr.save_model(sol.value, args.out, method="refined", refinement=report, **given,
                   warnings=kept + list(report["warnings"]))  # `gmr show` prints them
    for line in sol.value.equations():
        print("  " + line)
    print(f"wrote {args.out}")
    stage("done")
    return 0


def _moved(given, refined) -> float:
    """The largest relative change of any coefficient from `given` to `refined` (0.0: none moved)."""
    out = 0.0
    for block in ("stiffness", "velocity_damping", "position_damping"):
        a, b = (np.asarray(getattr(m, block), float) for m in (given, refined))
        if a.shape == b.shape and a.size:
            out = max(out, float(np.max(np.abs(b - a) / np.maximum(np.abs(a), 1e-300))))
    return out


def _given_metadata(path, recordings) -> dict:
    """What the refined model's file keeps of the given one's (audit: the refined file dropped the fit's warnings
    and its data and speed ranges, so `gmr show` said "no warnings" of laws 17-28 % off and `gmr basins` lost its
    extrapolation notes): `data_range` and `speed_range` widened to the refinement's recordings, the given
    warnings (as `given_warnings`, for the caller to prefix) and the given file's name. Its covariance is not kept:
    the refined coefficients have none (no band, no `--draws`)."""
    import json

    from .._model._metadata import ranges

    try:
        doc = json.loads(open(path).read())
    except (OSError, ValueError):
        doc = {}
    out = {"given_model": str(path), "given_warnings": [str(w) for w in doc.get("warnings", [])]}
    for key, sig in (("data_range", "x"), ("speed_range", "v")):
        now = ranges([r.complete(doc.get("topology", "independent")) for r in recordings], sig)
        old = doc.get(key)
        if isinstance(old, list) and len(old) == len(now):
            now = [[min(a[0], b[0]), max(a[1], b[1])] for a, b in zip(old, now)]
        out[key] = now
    return out


#: the refined model's error over one input period (or the whole record) above this many times its windowed error,
#: and above `LONGER_MIN`, is reported: the short windows restart from the recorded state and hide a missing term
LONGER_FACTOR = 4.0
LONGER_MIN = 0.05


def _pct(a) -> str:
    a = np.atleast_1d(np.asarray(a, float))
    return ", ".join("failed" if not np.isfinite(v) else f"{100 * v:.3g} %" for v in a)


#: the refined model's free run worse than the given model's by this share (and `WORSE_MIN` of NRMSE) is reported
WORSE_FACTOR, WORSE_MIN = 1.1, 0.005


def _longer_horizons(model, recs, windowed, given=None, starts="estimated") -> tuple[list[dict], list[str]]:
    """Free runs of the refined model, and of the `given` one, on `recs` (`gmr.free_run`: the whole record, and
    restarts every input period where x was measured): the multiple-shooting windows restart from the recorded
    state, so a model that lacks a term (no damping at all, free coefficients that cannot stand in for it) can fit
    them and still leave the record within a period (hand-made Duffing without its damping term: windowed NRMSE
    2.6 %, free run 826 %); and windows that start from a noisy recorded state (`--starts measured`) can move exact
    coefficients (hand-made Duffing, x only, 30 dB: k3 300 -> 289, free run 3.2 -> 5.0 %, windowed error up 4.6 %,
    no warning): the refined model's free run worse than the given model's is reported."""
    from .._simulate._free_run import free_run

    def measure(m, rec):
        run = free_run(m, rec, throw=False)
        fr = run.value
        nrmse = np.asarray(fr.nrmse, float)
        h = None if fr.horizon_nrmse is None else np.asarray(fr.horizon_nrmse, float)
        # a record that stays in its wells is judged over its whole length; one that crosses between them can be
        # chaotic (an exact model leaves it too), so over the restarts (`FreeRun.horizon_nrmse`)
        crossing = fr.crossings is not None and np.any(np.asarray(fr.crossings)[0] > 0)
        use = h if crossing and h is not None else nrmse
        worst = float(np.nanmax(use)) if np.any(np.isfinite(use)) else np.inf
        what = f"over {fr.horizon:.3g} s restarts" if use is h else "over the whole record (it stays in its wells)"
        return run, fr, nrmse, h, worst, what

    out, warn = [], []
    ref = float(windowed["after"].nrmse) if windowed is not None else np.nan
    for rec in recs:
        run, fr, nrmse, h, worst, what = measure(model, rec)
        entry = {"recording": rec.name, "nrmse": nrmse.tolist(), "horizon": fr.horizon,
                 "horizon_nrmse": None if h is None else h.tolist(), "result": run.stats["result"]}
        before = np.nan
        if given is not None:
            _, _, g_nrmse, g_h, before, _ = measure(given, rec)
            entry.update(given_nrmse=g_nrmse.tolist(), given_horizon_nrmse=None if g_h is None else g_h.tolist())
        out.append(entry)
        pct = lambda e: "a failed run" if not np.isfinite(e) else f"{100 * e:.3g} %"  # noqa: E731
        far = max(LONGER_FACTOR * ref, LONGER_MIN)
        if worst > far or not np.isfinite(worst):  # far beyond the windows: something no coefficient covers
            both = np.isfinite(before) and before > far
            warn.append(f"{rec.name}: the refined model's output error {what} is {pct(worst)}, against "
                        f"{100 * ref:.3g} % over the short windows, which restart from the recorded state: "
                        + (f"the given model's is {pct(before)} too: the model lacks something no free coefficient "
                           f"covers (a missing term: run gmr discover), or the record is too sensitive to follow (a "
                           f"chaotic response: compare the models over short restarts, gmr simulate)" if both else
                           "the model lacks something no free coefficient covers (a missing term: run gmr discover), "
                           "or the windows are too short to show it (--window)"))
        elif np.isfinite(before) and worst > max(WORSE_FACTOR * before, before + WORSE_MIN):
            warn.append(f"{rec.name}: the refined model's output error {what} is {pct(worst)}, the given model's "
                        f"{pct(before)}: refinement made the free run worse; keep the given model. " + (
                            "The windows start from the recorded state, and a noisy one (x with noise, v estimated "
                            "from it) moves the coefficients to absorb it: the default --starts estimated fits "
                            "each window's start instead" if starts == "measured" else
                            "The training windows do not show what the free run does (records of the wells only, "
                            "for a law used between them): refine on records that cover the motion, or fewer "
                            "free coefficients (--free damping)"))
    return out, warn
