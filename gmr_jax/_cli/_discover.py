"""`gmr discover MODEL.json REC.npz [...] --holdout REC.npz [...] --out DIR` (contracts)."""

import json

import numpy as np

from .._errors import GMRInputError
from ._args import add_columns_option, load_recordings, output_dir
from ._progress import stage


def register(sub):
    p = sub.add_parser("discover", help="find the physics a model left out, from recordings that disagree with it")
    p.add_argument("model", help="gmr-model/1 JSON (reconstructed or hand-written)")
    p.add_argument("recordings", nargs="+", help="estimation recordings (NPZ or CSV)")
    p.add_argument("--holdout", nargs="+", default=[], help="recordings used only to measure the fit before/after")
    p.add_argument("--out", required=True, help="output folder: report.json, augmented_model.json, summary.txt, figures")
    add_columns_option(p)
    p.add_argument("--form", choices=["auto", "strong", "weak"], default="auto",
                   help="equation-error form (weak: test-function integrals, no acceleration; auto: weak when a is estimated "
                        "from a signal whose noise floor starts near its band edge, strong when a was recorded or the "
                        "signal stands clear of its noise far above its band (noise-free x, an encoder); the report's "
                        "settings.form_reason says which and why)")
    p.add_argument("--error", choices=["auto", "output", "equation"], default="auto",
                   help="holdout error: simulation (output) or equation error (auto: output when both models simulate)")
    p.add_argument("--decimate", type=int, default=1, help="strong form: low-pass and decimate the regression columns by this factor")
    p.add_argument("--alpha", type=float, default=0.05, help="family-wise level of the F-tests (Bonferroni over the catalogue)")
    p.add_argument("--n-boot", type=int, default=200, help="block-bootstrap replicates (stability and intervals)")
    masses = p.add_mutually_exclusive_group()
    masses.add_argument("--hold-masses", dest="refit_masses", action="store_const", const=False, default=None,
                        help="keep the model's masses fixed in the re-calibration")
    masses.add_argument("--refit-masses", dest="refit_masses", action="store_const", const=True,
                        help="let the masses move (independent topology; default there), where the data "
                             "determine them: a DOF without force input, a mass not separable from a "
                             "model term or moved outside [m/2, 2m] is held anyway, and the report says why")
    p.add_argument("--no-figures", action="store_true")
    p.set_defaults(fn=run)
    return p


def _jsonable(o):
    if isinstance(o, dict):
        return {k: _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    if isinstance(o, float) and not np.isfinite(o):
        return None
    return o


def run(args) -> int:
    import gmr_jax as gmr
    from gmr_jax.plots import discovery_figures

    if not (0 < args.alpha < 1):
        raise GMRInputError(f"--alpha must lie in (0, 1), got {args.alpha}")
    if args.n_boot < 20:
        raise GMRInputError(f"--n-boot must be at least 20, got {args.n_boot}")
    if args.decimate < 1:
        raise GMRInputError(f"--decimate must be >= 1, got {args.decimate}")
    out = output_dir(args.out)
    stage(f"loading the model and {len(args.recordings) + len(args.holdout)} recording(s)")
    model = gmr.load_model(args.model)
    recs = load_recordings(args.recordings, args.columns)[0]
    hold = load_recordings(args.holdout, args.columns)[0]
    rule = gmr.SelectionRule(alpha=args.alpha, n_boot=args.n_boot)
    stage("discovering: locate, name and select terms, holdout simulations")
    rep = gmr.discover(model, recs, hold, rule=rule, form=args.form, decimate=args.decimate, error=args.error,
                       refit_masses=args.refit_masses).value
    gmr.save_model(rep.model, out / "augmented_model.json", method="gmr discover",
               discovered=[{k: f[k] for k in ("dof", "physics", "coefficient", "ci95")} for f in rep.findings])
    stage(f"writing {out}")
    d = rep.to_dict("augmented_model.json")
    (out / "report.json").write_text(json.dumps(_jsonable(d), indent=1))
    text = rep.summary()
    (out / "summary.txt").write_text(text + "\n")
    if not args.no_figures:
        discovery_figures(rep, out)
    print(f"gmr discover: {len(rep.findings)} finding(s) from {len(recs)} recording(s); "
          f"holdout: {len(hold) or 'none (estimation recordings reused)'}")
    print(text)
    print(f"wrote {out}/report.json, augmented_model.json, summary.txt" + ("" if args.no_figures else " and figures"))
    stage("done")
    return 0
