"""`gmr fit REC [REC ...] --out MODEL.json`: reconstruct a global model (contracts, "Fit").

Physical sanity checks (`gmr_jax._reconstruct._sanity`) run on the data and the model: a
refusal is an input error (exit 2); a warning is printed to stderr as a `warning: ...` line and
recorded in the model file under "warnings", and the exit status stays 0 (3 with --strict).
"""

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

from .._errors import GMRInputError
from .._model._metadata import fit_metadata
from .._recordings._recording import length_unit
from .._reconstruct._sanity import GMRDataWarning
from ._args import add_columns_option, load_recordings, output_file, positive_int
from ._progress import stage
from ._show import _term_table, format_coordination, format_eiv, format_shared_design


def register(sub):
    f = sub.add_parser("fit", help="reconstruct a global model from recordings (one per equilibrium)")
    f.add_argument("recordings", nargs="+", help="NPZ, CSV or MATLAB .mat recordings, one per well (CSV: a header "
                   "row naming t, x, v, a, base_acc or force, and equilibrium for a velocity-only file; x0, x1, ... "
                   "for several DOFs; units in brackets allowed, 't [ms]' converted; other names: --columns)")
    f.add_argument("--out", required=True, help="model JSON to write (gmr-model/1)")
    add_columns_option(f)
    f.add_argument("--method", choices=["gmr", "gmc-sindy"], default="gmr")
    f.add_argument("--coordination", choices=["auto", "gls", "hermite", "joint"], default="auto",
                   help="GMR's global step: auto (default: the paper's covariance-weighted route unless it fails "
                   "its own data or its damping feeds energy in, then the joint regression; its damping also where the "
                   "noise of a measured v moves it), gls, hermite (the "
                   "paper's exact interpolant), joint (one penalised regression on all wells' data, admissible "
                   "models only)")
    f.add_argument("--no-shared-design", action="store_true",
                   help="chains: each cell alone (by default, cells of one design lend the restoring orders their "
                   "local fits resolve to the weakly excited cells, as a prior on those cells' own fits; the model "
                   "file's shared_design says who lent what)")
    f.add_argument("--no-eiv", action="store_true",
                   help="plain least squares in the local fits (by default, where x is measured with the "
                   "accelerations, they are corrected for the noise on x: errors in variables)")
    f.add_argument("--no-velocity-eiv", action="store_true",
                   help="take a measured v as exact in the joint regression (by default its damping columns are "
                   "corrected for the noise on v, which otherwise attenuates v^3 and leaks it into v)")
    f.add_argument("--structured-noise", action=argparse.BooleanOptionalAction, default=None,
                   help="where accelerations are estimated (x only, v only, x and v): take their noise for what it "
                   "is (the differentiation filter's) and resolve the curvature at each well (default: on where x "
                   "was integrated from v or the records are sweeps, off on steady sines and measured "
                   "accelerations; results/derived_accelerations.md)")
    f.add_argument("--restoring-order", "-r", type=positive_int, default=5)
    f.add_argument("--damping-order", "-d", type=positive_int, default=5)
    f.add_argument("--threshold", default="auto", help="STLS threshold on normalised coefficients, or 'auto' "
                   "(blocked cross-validation, one-standard-error rule; default)")
    f.add_argument("--topology", choices=["chain", "independent"], default=None)
    f.add_argument("--masses", default=None, help="comma-separated masses (default: from recordings, else 1)")
    f.add_argument("--no-velocity-damping", action="store_true")
    f.add_argument("--no-position-damping", action="store_true")
    f.add_argument("--figure", default=None, metavar="PNG",
                   help="figure of the fitted restoring and damping forces over the data ranges, and the "
                   "residuals (PNG, with a PDF beside it; default: OUT's name with _fit.png)")
    f.add_argument("--no-figure", action="store_true",
                   help="write no figure (saves ~1.5 s of matplotlib: its import, drawing the PNG and the PDF)")
    f.add_argument("--strict", action="store_true",
                   help="exit with status 3 when a sanity check warns about the data or the model (the model and "
                   "its warnings are still written); without it warnings are printed and the status is 0")
    f.set_defaults(fn=run)
    return f


def figure_path(out: str, figure: str | None) -> Path:
    """Where `gmr fit` writes its figure: `--figure`, else OUT with its suffix replaced by _fit.png."""
    if figure is not None:
        p = Path(figure)
        if p.suffix.lower() != ".png":
            raise GMRInputError(f"--figure must name a .png file (a .pdf is written beside it), got {figure!r}")
        return p
    o = Path(out)
    return o.with_name(o.stem + "_fit.png")


def run(args) -> int:
    import gmr_jax as gmr

    output_file(args.out)  # a folder that does not exist fails before the fit, not after it
    png = None if args.no_figure else figure_path(args.out, args.figure)  # a bad name fails before the fit
    stage(f"loading {len(args.recordings)} recording(s)")
    recs, load_warnings = load_recordings(args.recordings, args.columns)
    unit = length_unit(recs)[0]  # refused by the fit where they differ; its warning comes with the fit's
    lib = gmr.Library(args.restoring_order, args.damping_order,
                      velocity_damping=not args.no_velocity_damping,
                      position_damping=not args.no_position_damping)
    kwargs = {}
    if args.threshold != "auto":
        try:
            thr = float(args.threshold)
        except ValueError:
            raise GMRInputError(f"--threshold must be 'auto' or a number, got {args.threshold!r}") from None
        if not np.isfinite(thr) or thr < 0:
            raise GMRInputError(f"--threshold must be a non-negative number, got {thr}")
        kwargs = {"solver": gmr.STLS(thr, 0.0, normalize_columns=True), "select": None}
    masses = None
    if args.masses:
        try:
            masses = [float(m) for m in args.masses.split(",")]
        except ValueError:
            raise GMRInputError(f"--masses must be comma-separated numbers, got {args.masses!r}") from None
    fn = gmr.gmc_sindy if args.method == "gmc-sindy" else gmr.reconstruct
    if args.method == "gmr":
        kwargs["coordination"] = args.coordination
        if args.no_shared_design:
            kwargs["shared_design"] = False
        if args.no_eiv:
            kwargs["errors_in_variables"] = False
        if args.no_velocity_eiv:
            kwargs["velocity_eiv"] = False
        if args.structured_noise is not None:
            kwargs["structured_noise"] = args.structured_noise
        kwargs["progress"] = lambda msg: stage(f"gmr: {msg}")
    stage(f"{args.method}: local fits and coordination (the first run of a shape compiles)")
    with warnings.catch_warnings():  # printed below as `warning:` lines, once each
        warnings.simplefilter("ignore", GMRDataWarning)
        sol = fn(recs, lib, topology=args.topology, masses=masses, **kwargs)
    model, st = sol.value, sol.stats
    stage(f"writing {args.out}")
    # the file: what save_model(solution) writes (the fitted region from the completed recordings: an
    # acceleration-only chain's cell deformations, not the loaded mass displacements), the loading warnings first
    meta = fit_metadata(st)
    meta["warnings"] = load_warnings + list(st["warnings"])
    gmr.save_model(model, args.out, **meta)
    ranges, routes, design = meta["data_range"], meta.get("coordination", []), meta.get("shared_design", [])
    print(f"{st['method']} model from {len(recs)} recording(s) -> {args.out}")
    if unit is not None:
        print(f"  lengths in {unit} (x, v and a per s, per s^2; from the files' headers): the model's coefficients, "
              f"wells and ranges are in {unit}")
    for line in _term_table(model, {"terms": model.terms()}, 4):  # equations, coefficients, std. errors
        print(line)
    from .._reconstruct._sanity import restoring_uncertainty

    for i, rep in enumerate(st["dofs"]):
        if rep.equilibria.size:
            band = "" if model.covariance is None else (
                f"; the band on its restoring force "
                f"±{100 * restoring_uncertainty(model.stiffness[i], model.covariance[i], *ranges[i]):.2g} %"
                " (2 sd, RMS over the recorded range: the model file's covariance, the fit figure's band)")
            print(f"  DOF {i}: wells recorded about x = {np.round(rep.equilibria, 6).tolist()} (the records' means; "
                  f"the model's own equilibria: gmr show), global orders "
                  f"K_r={rep.stats['K_r']}, K_d={rep.stats['K_d']}{band}")
    if model.n_dof > 1:
        print(f"  topology: {model.topology.name} (" + ("x_i is cell i's deformation, x_i - x_(i-1); "
              "--topology independent for separate masses)" if model.topology.name == "chain" else
              "each DOF on its own; --topology chain for cells in series)"))
    for line in format_coordination(routes):
        print(line)
    for line in format_shared_design(design):
        print(line)
    for name, sc in st["training"].items():
        band = "" if not any(b is not None for b in sc.get("r2_in_band") or []) else (
            f" (R2 in the response's band {[None if b is None else round(b, 5) for b in sc['r2_in_band']]})")
        print(f"  training {name}: R2 {np.round(sc['r2'], 5).tolist()}, NRMSE {np.round(sc['nrmse'], 5).tolist()}{band}")
    if "resolution" in st:
        print("What each well's data resolved (and the excitation that would resolve what they did not):")
        print(str(st["resolution"]))
    for line in format_eiv(routes):
        print(line)
    for line in _derivation_notes(recs):
        print(line)
    forced = any(r.force is not None and np.any(np.asarray(r.force) != 0) for r in recs)  # a force input: a warning
    if masses is None and all(r.masses is None for r in recs) and model.n_dof == 1 and not forced:  # a chain's too
        print("  note: no masses in the recordings and no --masses: taken as 1, so every coefficient is a force "
              "per unit mass (pass --masses M or a column m in the CSV for forces in the recordings' units)")
    if png is not None:
        stage(f"writing the figure {png} (and .pdf)")
        from ..plots._fit import fit_figure
        from ..plots._save import save_with_pdf

        save_with_pdf(fit_figure(model, recs, title=f"{st['method']} model ({Path(args.out).name}) against its "
                                 f"recordings"), png)
        print(f"  figure: {png} (and {png.with_suffix('.pdf').name}): restoring and damping forces over the "
              f"data ranges, residuals")
    for w in st["warnings"]:
        print(f"warning: {w}", file=sys.stderr)
    n_warn = len(load_warnings) + len(st["warnings"])
    if n_warn and args.strict:
        print(f"gmr fit: {n_warn} warning(s) with --strict: exit status 3 (model written to "
              f"{args.out})", file=sys.stderr)
        return 3
    stage("done")
    return 0


def _derivation_notes(recs) -> list[str]:
    """What was estimated rather than measured, by source (a note per kind of recording)."""
    notes = []
    integrated = [r for r in recs if "x" in r.derived and r.integration]
    if integrated:
        srcs = sorted({r.integration.get("from", "?") for r in integrated})
        notes.append(f"  note: x was integrated from {' and '.join(srcs)} (drift below the cut-off removed, the slow shift of "
                     f"the mean position restored from the force balance; see README, velocity-only records)"
                     + ("; accelerations differentiated from v (Savitzky-Golay)" if "v" in srcs else ""))
    if any("x" not in r.derived and (r.v is None or r.a is None) for r in recs):
        notes.append("  note: velocities/accelerations were estimated from x (Savitzky-Golay, see README)")
    return notes
