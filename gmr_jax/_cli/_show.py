"""`gmr show MODEL.json`: a model file in words. The equations per DOF with the standard errors
the file stores, the equilibria at rest with their stability, the energy barriers between
neighbouring wells, and the training metadata and warnings written with it.

Equilibria at rest (no input): each DOF (each cell of a chain) is at rest where its own
restoring polynomial F_i(x) = sum_k K_ik x^k vanishes; stable where dF_i/dx > 0. The barrier
from a well to the saddle beside it is the work against the restoring force,
V(s) - V(w) with V(x) = integral of F_i(x) dx (exact: the polynomial is integrated).
"""

import json
from pathlib import Path

import numpy as np

from .._fit._library import POSITION_DAMPING, STIFFNESS, VELOCITY_DAMPING, term_name
from .._model._model import term_key

#: keys `show` prints in their own sections; any other key is listed at the end.
_KNOWN = ("format", "topology", "masses", "terms", "method", "library", "training", "warnings", "data_range",
          "speed_range",
          "resolution", "shared_design", "coordination")


def format_coordination(routes: list[dict]) -> list[str]:
    """`gmr show --detail`: per DOF, the route, the restoring degree and the design it shares."""
    out = []
    for i, r in enumerate(routes):
        if not isinstance(r, dict):
            continue
        line = f"    DOF {i}: {r.get('route', '?')}"
        if r.get("degree", -1) >= 0:
            line += f", restoring degree {r['degree']}"
        if r.get("design"):
            line += (f"; one design with DOFs {', '.join(map(str, r['design']))} (spread about the shared law "
                     f"{100 * float(r.get('design_spread', float('nan'))):.2g} % of its scale)")
        out.append(line)
    return (["  global law per DOF:"] + out) if out else []


def register(sub):
    p = sub.add_parser("show", help="print a model file: equations with standard errors, wells and their "
                       "stability, energy barriers, training metadata and warnings")
    p.add_argument("model", help="gmr-model/1 JSON (e.g. from gmr fit)")
    p.add_argument("--precision", type=int, default=4, help="significant digits of the numbers (default 4)")
    p.add_argument("--detail", action="store_true",
                   help="also the route, restoring degree and shared design of each DOF, and every other key of "
                   "the file")
    p.set_defaults(fn=run)
    return p


def equilibria(stiffness) -> list[list[tuple[float, float]]]:
    """Per DOF, the real zeros x of F_i(x) = sum_k stiffness[i, k] x^k with the slope dF_i/dx
    there (> 0: stable well, < 0: saddle), sorted by x (companion-matrix roots, two Newton steps)."""
    out = []
    for c in np.asarray(stiffness, float):
        c = np.trim_zeros(c, "b")
        if c.size < 2:
            out.append([])
            continue
        r = np.roots(c[::-1])
        scale = max(1.0, float(np.max(np.abs(r)))) if r.size else 1.0
        r = np.sort(r[np.abs(r.imag) <= 1e-7 * scale].real)
        dc = np.polynomial.polynomial.polyder(c)
        for _ in range(2):
            f, df = (np.polynomial.polynomial.polyval(r, a) for a in (c, dc))
            r = np.where(df != 0, r - f / np.where(df != 0, df, 1.0), r)
        r = np.unique(r)
        out.append([(float(x), float(np.polynomial.polynomial.polyval(x, dc))) for x in r])
    return out


def barriers(stiffness, eqs) -> list[list[dict]]:
    """Per DOF, for each saddle between two stable wells: the wells, the saddle and the energy
    V(saddle) - V(well) from each side (V the integral of the restoring force)."""
    out = []
    for c, zs in zip(np.asarray(stiffness, float), eqs):
        integ = np.polynomial.polynomial.polyint(c)
        V = lambda x: float(np.polynomial.polynomial.polyval(x, integ))  # noqa: E731
        rows = []
        for k in range(1, len(zs) - 1):
            (xl, sl), (xs, ss), (xr, sr) = zs[k - 1], zs[k], zs[k + 1]
            if ss < 0 and sl > 0 and sr > 0:
                rows.append({"left": xl, "saddle": xs, "right": xr,
                             "from_left": V(xs) - V(xl), "from_right": V(xs) - V(xr)})
        out.append(rows)
    return out


#: draws of the file's covariance behind the barrier intervals `gmr show` prints
BARRIER_DRAWS = 400


def barrier_intervals(model, bars, n: int = BARRIER_DRAWS, seed: int = 0):
    """Per DOF and barrier of `bars`: the 2.5-97.5 % range of the saddle and of both barrier heights over `n`
    models drawn from the file's covariance (`sample_models`), and the share of draws that keep a saddle with a
    stable well on each side near the model's (a draw that loses them has no such barrier). None without a
    covariance. The barriers are a nonlinear function of the coefficients: their spread is read from the
    draws, not propagated linearly (audit: barriers printed to 4 digits, 22-35 % off, with no interval)."""
    import jax

    from .._model._uncertainty import sample_models

    if getattr(model, "covariance", None) is None:
        return None
    draws = np.asarray(sample_models(model, jax.random.key(seed), n).stiffness, float)  # (n, D, K)
    out = []
    for i, rows in enumerate(bars):
        eqs = equilibria(draws[:, i, :])
        drawn = [barriers([c], [zs])[0] for c, zs in zip(draws[:, i, :], eqs)]
        found = []
        for b in rows:
            width = b["right"] - b["left"]
            vals = []
            for bars_k in drawn:
                got = [r for r in bars_k
                       if abs(r["saddle"] - b["saddle"]) < 0.5 * width and abs(r["left"] - b["left"]) < 0.5 * width
                       and abs(r["right"] - b["right"]) < 0.5 * width]
                if got:
                    r = min(got, key=lambda r: abs(r["saddle"] - b["saddle"]))
                    vals.append((r["saddle"], r["from_left"], r["from_right"]))
            v = np.asarray(vals, float).reshape(-1, 3)
            q = np.percentile(v, [2.5, 97.5], axis=0) if len(v) else np.full((2, 3), np.nan)
            found.append({"kept": len(v) / n, "draws": n, "saddle": q[:, 0], "from_left": q[:, 1], "from_right": q[:, 2]})
        out.append(found)
    return out


def _interval_line(s: dict, p: int) -> str:
    rng = lambda a: f"[{_g(a[0], p)}, {_g(a[1], p)}]"  # noqa: E731
    if s["kept"] == 0:
        return (f"(none of {s['draws']} models drawn from the file's covariance keeps these two wells and the saddle: "
                f"the data do not fix this barrier)")
    return (f"(95 % of the models drawn from the file's covariance: saddle {rng(s['saddle'])}, from the left "
            f"{rng(s['from_left'])}, from the right {rng(s['from_right'])}; "
            f"{100 * s['kept']:.3g} % of the draws keep the two wells and the saddle)")


def _g(x, p):
    return f"{x:.{p}g}"


def _term_table(model, d: dict, p: int) -> list[str]:
    """The equation and a term table (coefficient, standard error, relative error) per DOF."""
    lines = []
    has_se = any("stderr" in t for t in d["terms"])
    eqs = model.equations(precision=p)
    order = {STIFFNESS: 0, VELOCITY_DAMPING: 1, POSITION_DAMPING: 2}
    key = term_key(model.topology)
    for i in range(model.n_elements):
        lines.append("  " + eqs[i])
        terms = sorted((t for t in d["terms"] if t[key] == i and t["coefficient"] != 0),
                       key=lambda t: (order.get(t["physics"], 3), t["order"]))
        if not terms:
            continue
        lines.append(f"    {'term':16s} {'physics':17s} {'coefficient':>13s} {'std. error':>12s} {'rel.':>9s}")
        for t in terms:
            c, se = t["coefficient"], t.get("stderr")
            if se is None:
                se_s, rel_s, flag = "-", "-", ""
            else:
                se_s = _g(se, 3)
                rel_s = f"{100 * se / abs(c):.2g} %"
                flag = "  *" if abs(c) < 2 * se else ""
            lines.append(f"    {term_name(t['physics'], t['order']):16s} {t['physics']:17s} {_g(c, p):>13s} "
                         f"{se_s:>12s} {rel_s:>9s}{flag}")
    if has_se:
        lines.append("  (std. error: from the data's noise; * = the coefficient is within 2 of them of 0: the data do not "
                     "pin it down. The model's band (its covariance) adds the spread of the laws the wells' data admit "
                     "and can be much wider: a rule-11b warning says so, the fit figure draws it)")
    else:
        lines.append("  (no standard errors stored in this file)")
    return lines


def _inside(x, rng) -> bool:
    return rng is None or rng[0] <= x <= rng[1]


def describe(path, precision: int = 4, detail: bool = False) -> str:
    """The text `gmr show` prints for the model file at `path` (GMRInputError on a bad file)."""
    from .._errors import GMRInputError
    from .._model._io import load_model

    if precision < 1:
        raise GMRInputError(f"--precision must be >= 1, got {precision}")
    model = load_model(path)  # every key checked
    d = json.loads(Path(path).read_text(encoding="utf-8-sig"))
    return _describe(model, d, str(path), precision, detail)


def _describe(model, d: dict, name: str, p: int, detail: bool = False) -> str:
    n = model.n_elements
    lab = term_key(model.topology).replace("dof", "DOF")
    masses = [_g(m, p) for m in np.asarray(model.masses)]
    shape = (f"graph of {model.n_dof} nodes and {n} elements {[list(e) for e in model.topology.elements]}"
             if lab == "element" else f"{n} DOF{'s' if n > 1 else ''}, topology {model.topology.name}")
    out = [f"{name}: {d['format']}, {shape}, masses [{', '.join(masses)}]"]
    method = d.get("method")
    lib = d.get("library")
    if method or lib:
        degrees = [int(np.trim_zeros(np.asarray(k, float), "b").size) - 1 for k in np.asarray(model.stiffness)]
        libs = (f"; local-fit library r={lib.get('r')}, d={lib.get('d')} (the local Taylor fits' orders; the global "
                f"restoring law's degree, per DOF: {', '.join(map(str, degrees))})" if isinstance(lib, dict) else "")
        out.append(f"method: {method or 'not recorded'}{libs}")
    units = d.get("units")
    if isinstance(units, dict) and units.get("length"):
        out.append(f"lengths in {units['length']} (from the recordings' headers: the coefficients, wells, ranges and "
                   f"barriers are in {units['length']} and s)")

    out += ["", f"Equations (force of each {lab}, model units):"] + _term_table(model, d, p)

    rng = d.get("data_range")
    rng = None if rng is None else np.asarray(rng, float).reshape(n, 2)
    eqs = equilibria(model.stiffness)
    out += ["", "Equilibria at rest (F_i(x) = 0; stable where dF/dx > 0):"]
    for i in range(n):
        if not eqs[i]:
            out.append(f"  {lab} {i}: none (no real zero of the restoring polynomial)")
            continue
        for k, (x, s) in enumerate(eqs[i]):
            kind = "stable  " if s > 0 else ("saddle  " if s < 0 else "marginal")
            where = "" if _inside(x, None if rng is None else rng[i]) else "  (outside the training data range)"
            out.append(f"  {lab + ' ' + str(i) + ':' if k == 0 else '':7s} x = {_g(x, p):>11s}  {kind}  "
                       f"dF/dx = {_g(s, p)}{where}")
    n_stable = [sum(s > 0 for _, s in e) for e in eqs]
    out.append(f"  stable wells per {lab}: {n_stable}")

    bars = barriers(model.stiffness, eqs)
    out += ["", "Energy barriers between neighbouring wells (V(saddle) - V(well), V = integral of F dx):"]
    if not any(bars):
        out.append(f"  none (no {lab} has two stable wells with a saddle between them)")
    spread = barrier_intervals(model, bars) if any(bars) else None
    for i, rows in enumerate(bars):
        for k, b in enumerate(rows):
            out.append(f"  {lab} {i}: wells {_g(b['left'], p)} | {_g(b['right'], p)} over the saddle at "
                       f"{_g(b['saddle'], p)}: {_g(b['from_left'], p)} from the left well, "
                       f"{_g(b['from_right'], p)} from the right")
            if spread is not None:
                out.append("    " + _interval_line(spread[i][k], 3))
    if spread is None and any(bars):
        out.append("  (no covariance in this file: no interval on these numbers)")

    out += ["", "Training:"]
    if rng is not None:
        out.append("  data range of x: " + ", ".join(f"{lab} {i} [{_g(a, p)}, {_g(b, p)}]"
                                                    for i, (a, b) in enumerate(rng)))
    vr = d.get("speed_range")
    if vr is not None:
        out.append("  data range of v (the speeds the damping law was fitted at; beyond them it is extrapolated): "
                   + ", ".join(f"{lab} {i} [{_g(a, p)}, {_g(b, p)}]"
                               for i, (a, b) in enumerate(np.asarray(vr, float).reshape(n, 2))))
    tr = d.get("training")
    if isinstance(tr, dict) and tr:
        for rec, sc in tr.items():
            if isinstance(sc, dict):
                parts = [f"{k} {', '.join(_g(v, 6) for v in np.atleast_1d(sc[k]))}"
                         for k in ("r2", "nrmse") if k in sc]
                out.append(f"  {rec}: " + "; ".join(parts).replace("r2", "R^2").replace("nrmse", "NRMSE"))
    elif rng is None:
        out.append("  not recorded in this file")
    warns = d.get("warnings") or []
    out += ["", f"Warnings stored with the model: {len(warns) or 'none'}"]
    out += [f"  - {w}" for w in warns]
    if not detail:
        out += ["", "(the route, degree and design of each DOF: --detail)"]
        return "\n".join(out)
    routes = d.get("coordination")
    if isinstance(routes, list) and routes:
        out += ["", "Global law (the route per DOF):"]
        out += format_coordination(routes)[1:]
    extra = [k for k in d if k not in _KNOWN]
    if extra:
        out += ["", "Other keys:"]
        for k in extra:
            s = json.dumps(d[k])
            out.append(f"  {k}: {s if len(s) <= 200 else s[:197] + '...'}")
    return "\n".join(out)


def run(args) -> int:
    print(describe(args.model, args.precision, args.detail))
    return 0
