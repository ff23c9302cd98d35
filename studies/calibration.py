"""Calibration of the 95 % band and of the printed standard errors, routes side by side on the
same records: `reconstruct`'s default (`coordination="evidence"`, one posterior of every well's
records) and the paper's route (`coordination="gls"`: local STLS fits, then the coordination).

Runs (system, sensors, SNR, seed): the coverage study's 20 (`studies/coverage.py`), and new ones:
displacement-only and (x, a) sensors, Kresling chains on other seeds and noise levels, cubic
chains at 60 dB, an asymmetric quintic double well with cubic damping, and a 2-cell chain of
two designs. Per DOF:

- cover: share of 401 points on the interwell span where the 95 % band holds F_r,true;
- sharp: RMS band half-width over RMS actual error on the span (1: as wide as the error);
- err: restoring error (`metrics.restoring_error` on the system's box);
- coef: for truths inside the library (polynomial laws), the share of printed coefficients
  (stiffness, velocity and position damping, every order) within 2 standard errors of the truth.

Targets: cover >= 90 % in >= 90 % of the DOFs; median sharp <= 4; coef >= 95 %.

Run: python studies/calibration.py [--quick] [--routes evidence gls] [--out results/calibration.md]
"""

import argparse
import dataclasses
import sys
import time
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import gmr_jax as g

sys.path.insert(0, str(Path(__file__).resolve().parent))
from coverage import CASES as COVERAGE, joint_pd, poly2, poly3, polynomial_chain  # noqa: E402

RESULTS = Path(__file__).resolve().parents[1] / "results"


def quintic():
    """An asymmetric quintic double well with cubic damping (wells at 0 and 0.02 m)."""
    k, L, s, r = 50.0, 0.02, 0.008, -0.015  # F = c x (x - s)(x - L)(x - r)^2 ... tangent stiffness k at 0
    roots = np.array([0.0, s, L, r, r])
    poly = np.polynomial.polynomial.polyfromroots(roots)
    c = k / poly[1]
    terms = [{"dof": 0, "physics": "stiffness", "order": o, "coefficient": float(c * a)}
             for o, a in enumerate(poly) if o > 0 and abs(a) > 0]
    terms += [{"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.2},
              {"dof": 0, "physics": "velocity_damping", "order": 3, "coefficient": 50.0}]
    return g.systems.System(
        name="quintic", truth=g.from_terms([0.05], terms), equilibria=np.array([[0.0], [L]]), sweep=(0.5, 10.0),
        duration=30.0, fs=1000.0, x_range=np.array([[-0.1 * L, 1.1 * L]]), v_range=np.array([[-0.1, 0.1]]),
        orders={"gmr": (5, 3), "gmc": (5, 3)}, description="asymmetric quintic double well, cubic damping",
        units=("x [m]", "x' [m/s]", "F [N]"))


def two_designs():
    return polynomial_chain((20.0, 40.0), (0.03, 0.025), (0.007, 0.0125), (0.04, 0.04), name="two designs")


def x_only(recs):
    return [dataclasses.replace(r, v=None, a=None) for r in recs]


def x_a(recs):
    return [dataclasses.replace(r, v=None) for r in recs]


K3, K5 = g.systems.kresling3, g.systems.kresling5
#: (label, factory, amplitude, SNR, seed, sensors)
NEW = [
    ("bistable joint (pos.-dep.), 1 deg, x only", joint_pd, np.deg2rad(1.0), 50.0, 5, x_only),
    ("bistable joint (pos.-dep.), 1 deg, x a", joint_pd, np.deg2rad(1.0), 40.0, 6, x_a),
    ("tri-stable NES, 0.5 mm, x only", g.systems.tristable_nes, 5e-4, 50.0, 5, x_only),
    ("tri-stable NES, 0.5 mm", g.systems.tristable_nes, 5e-4, 50.0, 7, None),
    ("shallow arch, 0.05, x only", g.systems.shallow_arch, 0.05, 50.0, 5, x_only),
    ("magnetic oscillator, 0.05, x a", g.systems.magnetic_bistable, 0.05, 50.0, 5, x_a),
    ("2-cell cubic chain, 0.3 mm", poly2, 3e-4, 60.0, 5, None),
    ("3-cell cubic chain, 0.3 mm", poly3, 3e-4, 30.0, 5, None),
    ("2-cell chain of two designs, 0.3 mm", two_designs, 3e-4, 40.0, 5, None),
    ("3-cell Kresling chain, 0.3 mm", K3, 3e-4, 50.0, 5, None),
    ("3-cell Kresling chain, 0.3 mm", K3, 3e-4, 60.0, 6, None),
    ("3-cell Kresling chain, 0.3 mm, x only", K3, 3e-4, 50.0, 7, x_only),
    ("5-cell Kresling chain, 0.3 mm", K5, 3e-4, 60.0, 5, None),
    ("5-cell Kresling chain, 0.3 mm", K5, 3e-4, 40.0, 6, None),
    ("quintic double well, cubic damping", quintic, 6e-4, 45.0, 5, None),
    ("quintic double well, cubic damping", quintic, 6e-4, 30.0, 6, None),
    ("quintic double well, cubic damping, x only", quintic, 6e-4, 50.0, 7, x_only),
    ("bistable joint (pos.-indep.), 0.5 deg", lambda: g.systems.bistable_joint("position_independent"),
     np.deg2rad(0.5), 60.0, 5, None),
    ("shallow arch, 0.05", g.systems.shallow_arch, 0.05, 50.0, 6, None),
    ("magnetic oscillator, 0.05", g.systems.magnetic_bistable, 0.05, 50.0, 6, None),
]
CASES = [c + (None,) for c in COVERAGE] + NEW
QUICK = [0, 20, 34]


def coefficient_share(model, truth, i):
    """Share of DOF i's printed coefficients within 2 standard errors of the truth's (None where the
    truth is not a polynomial model)."""
    if not isinstance(truth, g.GlobalModel) or model.stderr is None:
        return None
    hits, total = 0, 0
    for name in ("stiffness", "velocity_damping", "position_damping"):
        est, se = np.asarray(getattr(model, name)[i]), np.asarray(model.stderr[name][i])
        tru = np.zeros_like(est)
        t = np.asarray(getattr(truth, name)[i])[: est.size]
        tru[: t.size] = t
        if np.any(np.abs(np.asarray(getattr(truth, name)[i])[est.size:]) > 0):
            return None  # the truth has orders the library lacks
        printed = (np.abs(est) > 0) | (se > 0)
        hits += int(np.sum(printed & (np.abs(est - tru) <= 2.0 * se + 1e-12 * np.abs(tru))))
        total += int(np.sum(printed))
    return hits / max(total, 1)


def measure(model, system, i, n=401):
    eq = system.equilibria[:, i]
    xs = np.linspace(eq.min(), eq.max(), n)
    d = model.n_dof
    x = jnp.zeros((n, d)).at[:, i].set(jnp.asarray(xs))
    band = jax.vmap(lambda p: g.force_band(model, p, jnp.zeros(d), part="restoring", level=0.95))(x)
    f = np.asarray(jax.vmap(system.truth.restoring)(x))[:, i]
    low, up, mean = (np.asarray(a)[:, i] for a in (band.lower, band.upper, band.mean))
    rms_err = np.sqrt(np.mean((mean - f) ** 2))
    return {"cover": float(np.mean((f >= low) & (f <= up))),
            "sharp": float(np.sqrt(np.mean((0.5 * (up - low)) ** 2)) / max(rms_err, 1e-300)),
            "err": g.metrics.restoring_error(model, system.truth, i, system.x_range[i]),
            "coef": coefficient_share(model, system.truth, i)}


def run_case(label, factory, amplitude, snr, seed, sensors, routes):
    system = factory()
    recs = g.systems.make_recordings(system, amplitude, snr_db=snr, seed=seed)
    if sensors is not None:
        recs = sensors(recs)
    r, dd = system.orders["gmr"]
    out = []
    fits = {}
    for route in routes:
        t0 = time.time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sol = g.reconstruct(recs, g.Library(r, dd), coordination=route, throw=False,
                                  designs=system.designs if route == "evidence" else None)
        fits[route] = (sol, time.time() - t0)
    for i in range(system.truth.n_dof):
        row = {"case": label, "snr": snr, "seed": seed, "dof": i}
        for route, (sol, sec) in fits.items():
            row[route] = measure(sol.value, system, i) | {"seconds": sec, "ok": sol.result == g.RESULTS.successful}
        out.append(row)
    return out


def summary(rows, route):
    cov = np.array([r[route]["cover"] for r in rows])
    sharp = np.array([r[route]["sharp"] for r in rows])
    coef = [r[route]["coef"] for r in rows if r[route]["coef"] is not None]
    return (f"| {route} | {np.sum(cov >= 0.9)} / {len(rows)} ({100 * np.mean(cov >= 0.9):.0f} %) | "
            f"{np.median(sharp):.2f} | {100 * np.median([r[route]['err'] for r in rows]):.3g} % | "
            f"{100 * np.mean(coef):.1f} % over {len(coef)} DOFs |")


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--routes", nargs="+", default=["evidence", "gls"])
    p.add_argument("--out", default=None)
    args = p.parse_args()
    cmd = "python studies/calibration.py" + " ".join([""] + sys.argv[1:])
    cases = [CASES[k] for k in QUICK] if args.quick else CASES
    t0 = time.time()
    rows = []
    for c in cases:
        got = run_case(*c, args.routes)
        for r in got:
            print(r, flush=True)
        rows += got
    runs = len({(r["case"], r["snr"], r["seed"]) for r in rows})
    f = lambda v, fmt: "-" if v is None else fmt.format(v)  # noqa: E731
    lines = ["# Calibration of the band and the standard errors, default and paper routes", "",
             f"Command: `{cmd}` ({time.time() - t0:.0f} s; definitions in the module docstring). {runs} runs, "
             f"{len(rows)} DOFs; each cell: " + " / ".join(args.routes) + ".", "",
             "## Summary", "",
             "| route | band holds >= 90 % of the span | median RMS half-width / RMS error | median restoring error | "
             "coefficients within 2 SE (polynomial truths) |", "|---|---|---|---|---|"]
    lines += [summary(rows, route) for route in args.routes]
    lines += ["", "Targets: the band holds >= 90 % of the span in >= 90 % of the DOFs; median sharpness <= 4; "
              ">= 95 % of the coefficients within 2 SE.", "", "## Every DOF", "",
              "| case | SNR | seed | DOF | cover | sharp | restoring err | coef within 2 SE |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        cells = [" / ".join(fmt(r[route]) for route in args.routes) for fmt in (
            lambda m: f"{100 * m['cover']:.0f} %", lambda m: f"{m['sharp']:.2g}", lambda m: f"{100 * m['err']:.3g} %",
            lambda m: f(m["coef"], "{:.0%}"))]
        lines.append(f"| {r['case']} | {r['snr']:g} dB | {r['seed']} | {r['dof']} | " + " | ".join(cells) + " |")
    out = Path(args.out or RESULTS / ("calibration_quick.md" if args.quick else "calibration.md"))
    out.write_text("\n".join(lines) + "\n")
    print("\n".join(lines[:12]))


if __name__ == "__main__":
    main()
