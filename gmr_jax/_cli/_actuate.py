"""`gmr actuate MODEL.json --target 0-1-1-0-0 --out DIR`: design the cheapest tip load that deploys the
chain into the target configuration and verify it (README, "Actuation design")."""

import json
import sys

import numpy as np

from .._errors import GMRInputError
from ._args import draw_box, find_wells, interval, output_dir, positive_float, positive_int
from ._progress import stage


def register(sub):
    """Register the `actuate` subcommand on an argparse subparsers object."""
    a = sub.add_parser("actuate", help="find the lowest-peak tip load that deploys a chain to a target configuration")
    a.add_argument("model", help="gmr-model/1 JSON (chain)")
    a.add_argument("--target", required=True, help="target configuration, cell 0 (base) first, e.g. 0-1-1-0-0")
    a.add_argument("--out", required=True, help="output folder (writes actuation.json)")
    a.add_argument("--kind", choices=["half_sine", "samples"], default="half_sine",
                   help="Eq. (25) half-sine (f, A), or a sampled tip force history")
    a.add_argument("--f-range", default="0.1:5", help="half-sine frequencies searched, LO:HI (Hz)")
    a.add_argument("--A-range", default="0.02:1", help="half-sine amplitudes searched, LO:HI (force units)")
    a.add_argument("--x-range", default=None, help="LO:HI deformation interval to search for wells (default: "
                   "the stable roots of the model's restoring polynomial)")
    a.add_argument("--settle-time", type=positive_float, default=None,
                   help="free time after the load before the final state is judged, s (default: the model's own, "
                        "the time its slowest free vibration about its wells takes to decay a thousandfold, at "
                        "least 10 s; as gmr basins advises)")
    a.add_argument("--objective", choices=["peak", "effort"], default="peak",
                   help="minimise the peak force (default) or the integral of F^2 dt")
    a.add_argument("--grid", type=positive_int, default=24, help="seed grid points per axis (default 24)")
    a.add_argument("--seeds", type=positive_int, default=6, help="seeds refined along the basin boundary (default 6)")
    a.add_argument("--knots", type=positive_int, default=24, help="samples of the force history (--kind samples)")
    a.add_argument("--draws", type=int, default=32,
                   help="models drawn from the file's covariance on which the designed half-sine, and larger "
                   "amplitudes, are tried: the share of them it deploys, and the amplitude that deploys 95 %% "
                   "(default 32; 0: off)")
    a.add_argument("--require-robust", action="store_true",
                   help="exit with status 3 where the design is reached on the model but not robust: it deploys "
                   "fewer than 95 %% of the --draws models, or that could not be said (no draws, no covariance); "
                   "the file is written either way")
    a.add_argument("--sign-eps", type=positive_float, default=1e-3,
                   help="sgn(v) -> tanh(v/eps) inside differentiated solves (models with sgn(v) terms)")
    a.set_defaults(fn=run)
    return a


def run(args):
    import gmr_jax as gmr
    from gmr_jax import RESULTS
    from gmr_jax.plots import config_label

    out = output_dir(args.out)
    stage("loading the model, finding its wells")
    model = gmr.load_model(args.model)
    if model.topology.name != "chain" and model.n_dof == 1:
        # one mass: m a + F = force either way, and the tip is that mass
        import dataclasses

        model = dataclasses.replace(model, topology=gmr.Chain())
    if model.topology.name != "chain":
        raise GMRInputError("gmr actuate needs a chain model (topology 'chain'): the load is a tip force; a model "
                            f"of {model.n_dof} independent DOFs has no tip")
    wells, how = find_wells(model, args.x_range, args.model)
    if wells.shape[1] < 2 or np.any(np.isnan(wells[:, :2])):
        few = [i for i in range(model.n_dof) if np.sum(~np.isnan(wells[i])) < 2]
        raise GMRInputError(f"cells {few} have fewer than two stable wells ({how}): every cell must be bistable "
                            "to be actuated" + ("; widen --x-range" if args.x_range else "; give --x-range=LO:HI"))
    print(f"gmr actuate: wells per cell {[np.round(w[~np.isnan(w)], 6).tolist() for w in wells]} ({how})")
    if args.draws < 0:
        raise GMRInputError(f"--draws must be >= 0, got {args.draws}")
    if args.grid < 2 or args.seeds < 1 or args.knots < 3 or not args.sign_eps > 0:
        raise GMRInputError("need --grid >= 2, --seeds >= 1, --knots >= 3, --settle-time > 0, --sign-eps > 0")
    if args.settle_time is None:
        from .._basins._settle import model_settle_time

        args.settle_time = model_settle_time(model, wells)
        if args.settle_time is None:
            raise GMRInputError("the model's free motion about its wells does not decay (no damping there): no settle "
                                "time lets a final state be judged; check its damping terms, or give --settle-time")
        print(f"gmr actuate: settle time {args.settle_time:g} s after the load (the model's slowest free vibration "
              f"about its wells decays a thousandfold in it; --settle-time to change)")
    settings = gmr.ActuateSettings(
        f_range=interval(args.f_range, "f-range", positive=True), A_range=interval(args.A_range, "A-range"),
        n_f=args.grid, n_A=args.grid, n_seeds=args.seeds, objective=args.objective,
        sweep=gmr.SweepSettings(settle_time=args.settle_time), sign_eps=args.sign_eps, n_knots=args.knots,
    )
    stage(f"designing the {args.kind} load for {args.target}: (f, A) sweep, then gradient refinement")
    sol = gmr.actuate(model, args.target, kind=args.kind, settings=settings, wells=wells, throw=False)
    act, st = sol.value, sol.stats
    reached = bool(sol.result == RESULTS.successful)
    found = act.f is not None if act.kind == "half_sine" else act.t is not None
    doc = act.to_json() if found else {"kind": act.kind}
    d = model.n_dof
    doc.update({
        "target": config_label(int(st["target_config"]), d),
        "reached": reached,
        "final_wells": st["verified_wells"],
        "final_config": config_label(int(st["verified_config"]), d),
        "result": sol.status,  # the name: "successful", "target_not_found", ... (RESULTS[...] is its message)
        "message": RESULTS[sol.result] if not reached else "",
        "solves": st["solves"],
        "gradient_evaluations": st["gradient_evaluations"],
        "objective": args.objective,
    })
    robust = None
    if reached and act.kind == "half_sine" and args.draws > 0:
        robust = _robustness(gmr, model, act, wells, settings, int(st["target_config"]), args)
        doc["robustness"] = robust
        # top level, beside `reached` (on the model): whether the design deploys the structures the data admit
        # (audit: three designs `reached` on their models deployed 3 %, 0 %, 0 % of the drawn ones and none the truth)
        doc["robust"] = None if robust.get("share_at_design") is None else bool(robust["share_at_design"]
                                                                                   >= ROBUST_SHARE)
    (out / "actuation.json").write_text(json.dumps(doc, indent=1) + "\n")
    if act.kind == "half_sine" and act.f is not None:
        desc = f"half-sine f = {act.f:.6g} Hz, A = {act.A:.6g}"
    elif act.t is not None:
        desc = f"{len(act.t)}-sample tip force over {act.t[-1]:.4g} s"
    else:
        desc = "none"
    print(f"gmr actuate: target {doc['target']}: {desc}; peak {act.peak:.6g}, effort {act.effort:.6g}; "
          f"verified final configuration {doc['final_config']} ({'reached on the model' if reached else 'NOT reached'}"
          f"{'; NOT robust: see the warning' if doc.get('robust') is False else ''}); "
          f"{st['solves']} ODE solves")
    if robust is not None:
        print("  " + robust["sentence"])
        if doc.get("robust") is False:
            print(f"gmr actuate: {robust['sentence']}", file=sys.stderr)
    print(f"wrote {out}/actuation.json")
    stage("done")
    if not reached:
        return 1
    if args.require_robust and doc.get("robust") is not True:
        if doc.get("robust") is False:
            why = "it is not robust (see the warning above)"
        elif robust is not None:
            why = f"its robustness could not be said ({robust['sentence']})"
        else:
            why = ("its robustness was not tried (" + ("--draws 0" if args.draws == 0 else
                   "a sampled force history is verified on the model only") + ")")
        print(f"gmr actuate: --require-robust: the design reaches the target on the model, but {why}; exit status 3",
              file=sys.stderr)
        return 3
    return 0



#: amplitudes (times the design's) tried on the models drawn from the covariance, and the share of them that must
#: deploy for an amplitude to be called robust
LADDER = (1.0, 1.05, 1.1, 1.2, 1.35, 1.5, 1.75, 2.0, 2.5, 3.0)
ROBUST_SHARE = 0.95


def _robustness(gmr, model, act, wells, settings, target: int, args) -> dict:
    """The designed half-sine (f, A), and A times `LADDER`, swept over `args.draws` models drawn from the file's
    covariance (`gmr.basin_probability`, wells searched as `gmr basins --draws` does): the share of them that end
    in the target, and the smallest amplitude at which `ROBUST_SHARE` do. A design of the lowest peak sits on the
    model's basin boundary by construction, so about half of the structures the data admit stay put (audit: a
    design 'verified (reached)' on the model needed 11-30 % more on the truth)."""
    import jax

    from ..plots._basins import _digits, config_code, well_base

    if getattr(model, "covariance", None) is None:
        return {"sentence": f"note: {args.model} has no covariance: the design is verified on the model only, at its "
                            f"basin boundary (a structure slightly off the model may not deploy); give it a margin",
                "draws": 0}
    box = draw_box(wells)
    amps = float(act.A) * np.asarray(LADDER)
    stage(f"trying the design on {args.draws} models drawn from the covariance")
    sol = gmr.basin_probability(model, np.array([float(act.f)]), amps, jax.random.key(0), args.draws, x_range=box,
                                settings=settings.sweep)
    bp, st = sol.value, sol.stats
    used = int(st["samples_used"])
    if used == 0:
        return {"draws": 0, "drawn": int(st["samples_drawn"]),
                "sentence": f"warning: none of the {st['samples_drawn']} models drawn from the covariance keeps the "
                            f"model's wells with a dissipative damping: the covariance is too wide to say how robust "
                            f"the design is; it is verified on the model only, at its basin boundary"}
    configs = np.asarray(bp.configs).tolist()
    prob = np.asarray(bp.probability)[:, 0, :]  # (amplitudes, configs)
    unsettled = np.asarray(bp.unsettled)[:, 0]  # (amplitudes,): not settled by t1, apart from ending elsewhere
    # the sweep's codes are digits in base K (the well slots of the model in the box): the target's bits there
    target = config_code(_digits(target, model.n_dof, 2), well_base(gmr.stable_wells(model, box)))
    share = prob[:, configs.index(target)] if target in configs else np.zeros(len(amps))
    ok = np.nonzero(share >= ROBUST_SHARE)[0]
    a95 = float(amps[ok[0]]) if ok.size else None
    lad = [[float(k), float(a), float(p)] for k, a, p in zip(LADDER, amps, share)]
    elsewhere = 1.0 - share - unsettled  # settled in another configuration (or failed, diverged)
    if a95 is None:
        tail = (f"no amplitude up to {LADDER[-1]:g} x ({amps[-1]:.4g}) deploys {100 * ROBUST_SHARE:.0f} % of them "
                f"(best {100 * float(np.max(share)):.0f} %): the data do not make this deployment reliable")
    elif a95 == amps[0]:
        tail = f"the design itself deploys at least {100 * ROBUST_SHARE:.0f} % of them"
    else:
        tail = (f"A = {a95:.4g} ({a95 / amps[0]:.3g} x, f the same) deploys {100 * ROBUST_SHARE:.0f} %: the lowest-peak "
                f"design sits on the model's basin boundary, so use the larger amplitude on hardware")
    rest = f"{100 * float(elsewhere[0]):.0f} % end in another configuration"
    if unsettled[0] > 0:
        rest += (f", {100 * float(unsettled[0]):.0f} % had not settled {settings.sweep.settle_time:g} s after the "
                 f"load (undecided: lengthen --settle-time)")
    sentence = (f"{'warning' if share[0] < ROBUST_SHARE else 'robustness'}: over {used} models drawn from the file's "
                f"covariance (the structures its data admit), the design deploys {100 * float(share[0]):.0f} % "
                f"({rest}); {tail}")
    return {"draws": used, "drawn": int(st["samples_drawn"]), "ladder": lad, "share_at_design": float(share[0]),
            "unsettled_at_design": float(unsettled[0]), "elsewhere_at_design": float(elsewhere[0]),
            "settle_time": float(settings.sweep.settle_time), "robust_A": a95, "sentence": sentence}
