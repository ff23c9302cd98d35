"""`gmr fit REC [REC ...] --out MODEL.json`: reconstruct a global model (contracts, "Fit").

Physical sanity checks (`gmr_jax._reconstruct._sanity`) run on the data and the model: a
refusal is an input error (exit 2); a warning is printed to stderr as a `warning: ...` line and
recorded in the model file under "warnings", and the exit status stays 0 (3 with --strict).
"""

import sys
import warnings
from pathlib import Path

import numpy as np

from .._errors import GMRInputError
from .._model._metadata import fit_metadata
from .._recordings._recording import length_unit
from .._reconstruct._sanity import GMRDataWarning
from ._args import add_columns_option, load_recordings, output_file, positive_int, short_warning
from ._progress import stage


def register(sub):
    f = sub.add_parser("fit", help="reconstruct a global model from recordings (one per equilibrium)")
    f.add_argument("recordings", nargs="+", help="NPZ, CSV or MATLAB .mat recordings, one per well (CSV: a header "
                   "row naming t, x, v, a, base_acc or force, and equilibrium for a velocity-only file; x0, x1, ... "
                   "for several DOFs; units in brackets allowed, 't [ms]' converted; other names: --columns)")
    f.add_argument("--out", required=True, help="model JSON to write (gmr-model/1)")
    add_columns_option(f)
    f.add_argument("--method", choices=["gmr", "gmc-sindy"], default="gmr",
                   help="gmr: one global law from every well's records (--coordination); gmc-sindy: the baseline, one library on "
                   "all data")
    f.add_argument("--coordination", choices=["evidence", "hermite", "gls"], default="evidence",
                   help="GMR's global step: evidence (default: one posterior of every well's records; the law, its "
                   "degree and its band from the evidence; cells labelled one design by --designs share a law), hermite "
                   "(the paper's route: local STLS fits, then their exact Hermite interpolant), gls (the paper's "
                   "route with a covariance-weighted least-squares coordination)")
    f.add_argument("--restoring-order", "-r", type=positive_int, default=5,
                   help="hermite/gls: highest power of x in each well's local restoring fit")
    f.add_argument("--damping-order", "-d", type=positive_int, default=5,
                   help="highest order of the damping terms (sgn(v)|v|^j and x^j v)")
    f.add_argument("--threshold", default="auto", help="hermite/gls: STLS threshold on normalised coefficients, or 'auto' "
                   "(blocked cross-validation, one-standard-error rule; default)")
    f.add_argument("--topology", default=None, metavar="chain|independent|GRAPH.json",
                   help="several DOFs: chain (cells in series, x_i the deformation of cell i; the default), "
                   "independent (each DOF its own mass on the ground), or a graph file {\"nodes\": D, \"masses\": "
                   "[...], \"elements\": [[a, b], ...]} (x: node displacements; every element's law from every "
                   "node's balance, on the evidence route; masses from the file unless --masses)")
    f.add_argument("--designs", default=None, metavar="L0,L1,...",
                   help="one integer label per DOF (per element of a graph); cells with one label are one design "
                   "and share one law as far as their data agree (default: every cell its own law)")
    f.add_argument("--masses", default=None, help="comma-separated masses (default: from recordings, else 1)")
    f.add_argument("--no-velocity-damping", action="store_true",
                   help="leave out the terms sgn(v)|v|^j (friction, drag) from the library")
    f.add_argument("--no-position-damping", action="store_true",
                   help="leave out the terms x^j v (damping that varies with position) from the library")
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


def graph_option(args, kwargs: dict):
    """`--topology`: a name, or a graph file (its masses and `--designs` go into `kwargs`)."""
    import gmr_jax as gmr

    if args.designs is not None:
        try:
            kwargs["designs"] = np.array([int(v) for v in args.designs.split(",")])
        except ValueError:
            raise GMRInputError(f"--designs must be comma-separated integers, one per DOF (per element of a graph), "
                                f"got {args.designs!r}") from None
    if args.topology in (None, "chain", "independent"):
        return args.topology
    if not Path(args.topology).suffix.lower() == ".json":
        raise GMRInputError(f"--topology must be chain, independent or a graph .json file, got {args.topology!r}")
    graph, kwargs["graph_masses"] = gmr.load_graph(args.topology)
    return graph


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
    topology = graph_option(args, kwargs)
    if "designs" in kwargs and args.method != "gmr":
        raise GMRInputError("--designs pools cells of one design on --method gmr; drop it for --method gmc-sindy")
    if isinstance(topology, gmr.Graph):
        if args.method != "gmr":
            raise GMRInputError("a graph is fitted by --method gmr (its elements' laws jointly, evidence route)")
        masses = kwargs.pop("graph_masses") if masses is None else masses
        kwargs = {"designs": kwargs.get("designs"), "settings": gmr.ReconstructSettings(
            damping_order=args.damping_order), "coordination": "evidence"}
        png = None  # the fit figure draws chains and independent DOFs
    if args.method == "gmr" and not isinstance(topology, gmr.Graph):
        kwargs["coordination"] = args.coordination
        kwargs["progress"] = lambda msg: stage(f"gmr: {msg}")
    stage(f"{args.method}: the global law (the first run of a shape compiles)")
    with warnings.catch_warnings():  # printed below as `warning:` lines, once each
        warnings.simplefilter("ignore", GMRDataWarning)
        sol = fn(recs, lib, topology=topology, masses=masses, **kwargs)
    model, st = sol.value, sol.stats
    stage(f"writing {args.out}")
    # the file: what save_model(solution) writes (the fitted region from the completed recordings: an
    # acceleration-only chain's cell deformations, not the loaded mass displacements), the loading warnings first
    meta = fit_metadata(st)
    meta["warnings"] = load_warnings + list(st["warnings"])
    gmr.save_model(model, args.out, **meta)
    ranges = meta["data_range"]
    for line in summary_lines(model, st, recs, args.out, unit, ranges, masses_given=masses is not None):
        print(line)
    if png is not None:
        stage(f"writing the figure {png} (and .pdf)")
        from ..plots._fit import fit_figure
        from ..plots._save import save_with_pdf

        save_with_pdf(fit_figure(model, recs, title=f"{st['method']} model ({Path(args.out).name}) against its "
                                 f"recordings", unit=unit), png)
        print(f"  figure: {png} (and .pdf): forces over the data ranges with their 95 % band, residuals")
    print(f"  details (standard errors, route, degree and design per DOF): gmr show {args.out} --detail")
    for w in st["warnings"]:  # the loading warnings were printed as the files were read
        print(f"warning: {short_warning(w).replace('gmr show MODEL', f'gmr show {args.out}')}", file=sys.stderr)
    n_warn = len(load_warnings) + len(st["warnings"])
    if n_warn and args.strict:
        print(f"gmr fit: {n_warn} warning(s) with --strict: exit status 3 (model written to "
              f"{args.out})", file=sys.stderr)
        return 3
    stage("done")
    return 0


def summary_lines(model, st, recs, out, unit, ranges, masses_given=False) -> list[str]:
    """What `gmr fit` prints on stdout: the model, its wells, how well it fits, what was estimated."""
    from .._reconstruct._sanity import restoring_uncertainty
    from ._show import equilibria

    lu = f" {unit}" if unit else ""
    lines = [f"{st['method']} model from {len(recs)} recording(s) -> {out}"
             + (f" (lengths in {unit}, forces in the recordings' units)" if unit else "")]
    lines += ["  " + e for e in model.equations(precision=4)]
    eqs = equilibria(model.stiffness)
    graph = model.topology.name == "graph"
    what = "element" if graph else "DOF"
    for i in range(model.n_elements):
        lo, hi = ranges[i]
        near = [(x, s) for x, s in eqs[i] if lo - 0.5 * (hi - lo) <= x <= hi + 0.5 * (hi - lo)]
        stable = [x for x, s in near if s > 0]
        saddles = [x for x, s in near if s < 0]
        far = len(eqs[i]) - len(near)
        band = "" if model.covariance is None else (
            f"; restoring-force band ±{100 * restoring_uncertainty(model.stiffness[i], model.covariance[i], *ranges[i]):.2g} %")
        lines.append(f"  {what} {i}: stable wells at x = {', '.join(f'{x:.4g}' for x in stable) or 'none'}{lu}"
                     + (f", saddle{'s' if len(saddles) > 1 else ''} at {', '.join(f'{x:.4g}' for x in saddles)}{lu}"
                        if saddles else "") + band
                     + (f" ({far} more zero{'s' if far > 1 else ''} of the law beyond the recorded range by half its "
                        f"width: extrapolation, not a prediction)" if far else ""))
    if graph:
        lines.append(f"  topology: graph of {model.n_dof} nodes and {model.n_elements} elements (x: an element's "
                     f"deformation, the displacement of its second node minus its first's)")
    elif model.n_dof > 1:
        lines.append(f"  topology: {model.topology.name}" + (" (x_i: cell i's deformation; --topology independent for "
                     "separate masses)" if model.topology.name == "chain" else " (--topology chain for cells in series)"))
    tr = st.get("training") or {}
    if tr:
        r2 = [v for sc in tr.values() for v in np.atleast_1d(sc["r2"])]
        nr = [v for sc in tr.values() for v in np.atleast_1d(sc["nrmse"])]
        span = lambda v, p: f"{min(v):.{p}g}" + ("" if f"{min(v):.{p}g}" == f"{max(v):.{p}g}" else f"-{max(v):.{p}g}")  # noqa: E731
        lines.append(f"  fit to the recordings: R^2 {span(r2, 6)}, force NRMSE {span(nr, 3)}")
    lines += _derivation_notes(recs)
    forced = any(r.force is not None and np.any(np.asarray(r.force) != 0) for r in recs)  # a force input: a warning
    if not masses_given and all(r.masses is None for r in recs) and model.n_dof == 1 and not forced:
        lines.append("  masses: none given, taken as 1 (coefficients per unit mass; --masses M for forces)")
    return lines


def _derivation_notes(recs) -> list[str]:
    """What was estimated rather than measured, by signal and source (one line per distinct case); `recs` as
    loaded (a missing v or a is estimated by the fit)."""
    notes = []
    for r in recs:
        info = r.integration or {}
        parts = [f"{k} integrated from {info.get('from', '?')}" for k in ("x", "v") if k in r.derived]
        if r.v is None:
            parts.append("v differentiated from x")
        if r.a is None:
            parts.append(f"a differentiated from {r.derivative_source()}")
        if parts:
            notes.append(", ".join(parts))
    how = lambda n: "drift removed; Savitzky-Golay" if "integrated" in n else "Savitzky-Golay"  # noqa: E731
    return [f"  estimated: {n} ({notes.count(n)} of {len(recs)} recording(s); {how(n)})" for n in dict.fromkeys(notes)]
