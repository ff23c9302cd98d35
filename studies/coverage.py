"""Coverage of the global model's 95 % band (issue 15): does the band `reconstruct` gives
(`GlobalModel.covariance`, `force_band`) cover the true restoring force over the interwell
span, and how wide is it?

Cases: the paper systems (bistable joint, tri-stable NES), polynomial chains (2 and 3 cubic
cells), Kresling truss chains (3 and 5 cells), non-polynomial truths (shallow arch, magnetic
oscillator), white noise at 30-60 dB on every channel, several seeds; `reconstruct` with its
DEFAULTS (the library orders of each system, `system.orders["gmr"]`, as the other studies), or
the route `--coordination` names (the paper's "hermite" or "gls").

Per DOF (cell):
- interwell span: from the outermost stable equilibrium of the truth to the other (the
  recorded wells), 401 points; coverage = share of them where the 95 % band holds F_r,true;
- box: the same on the system's error box `x_range` (the other studies' convention: 1.5 x the
  equilibria span for the joint, 5 % beyond the wells for the NES, 25 % for the non-polynomial
  truths, 10 % for the chains);
- width: median over the span of the band's full width (upper - lower), relative to the
  force scale max |F_r,true| over the span;
- restoring error: `metrics.restoring_error` on `x_range` (relative L2);
- damping coverage: share of a 41 x 41 (x, v) grid over the span x `v_range` where the 95 %
  band of F_d holds the true damping force (points with v = 0 excluded: the band and the
  truth are both 0 there).

Run: python studies/coverage.py [--quick] [--basins] [--coordination evidence|hermite|gls]
(writes results/coverage.md; --quick: a reduced set of cases, written to results/coverage_quick.md;
--basins: adds the basin probability demonstration on the bistable joint)
"""

import argparse
import sys
import time
import warnings
from pathlib import Path

import jax
import numpy as np

import gmr_jax as g

RESULTS = Path(__file__).resolve().parents[1] / "results"
LEVEL = 0.95
TARGET = 0.90


def polynomial_chain(stiffness, wells, saddles, masses, zeta=0.04, name="poly2") -> g.systems.System:
    """A chain of bistable cubic cells: F_i(x) = c_i x (x - s_i)(x - L_i), wells at 0 and L_i
    (tangent stiffness `stiffness` at 0), saddle s_i; damping 2 zeta sqrt(k m) split into a
    viscous and a position-dependent part; trained around 0-0-.. and 1-1-.. as the Kresling
    chains."""
    terms = []
    d = len(stiffness)
    for i, (k, L, s, m) in enumerate(zip(stiffness, wells, saddles, masses)):
        c = k / (s * L)
        terms += [{"dof": i, "physics": "stiffness", "order": 1, "coefficient": c * s * L},
                  {"dof": i, "physics": "stiffness", "order": 2, "coefficient": -c * (s + L)},
                  {"dof": i, "physics": "stiffness", "order": 3, "coefficient": c},
                  {"dof": i, "physics": "velocity_damping", "order": 1, "coefficient": zeta * np.sqrt(k * m)},
                  {"dof": i, "physics": "position_damping", "order": 2,
                   "coefficient": zeta * np.sqrt(k * m) / L**2}]
    truth = g.from_terms(list(masses), terms, "chain")
    L = np.asarray(wells, float)
    return g.systems.System(
        name=name, truth=truth, equilibria=np.stack([np.zeros(d), L]), sweep=(0.5, 10.0), duration=30.0,
        fs=1000.0, x_range=np.stack([-0.1 * L, 1.1 * L], axis=1), v_range=np.tile([[-0.1, 0.1]], (d, 1)),
        orders={"gmr": (5, 5), "gmc": (5, 5)}, description=f"{d}-cell polynomial (cubic) chain",
        units=("x [m]", "x' [m/s]", "F [N]"))


def poly2():
    return polynomial_chain((20.0, 40.0), (0.03, 0.025), (0.012, 0.011), (0.04, 0.04), name="poly2")


def poly3():
    return polynomial_chain((20.0, 35.0, 60.0), (0.03, 0.028, 0.025), (0.012, 0.013, 0.01), (0.04, 0.04, 0.04),
                            name="poly3")


def joint_pd():
    return g.systems.bistable_joint("position_dependent")


def joint_pi():
    return g.systems.bistable_joint("position_independent")


#: (label, system factory, base amplitude, SNR dB, seed)
CASES = [
    ("bistable joint (pos.-dep.), 1 deg", joint_pd, np.deg2rad(1.0), 60.0, 0),
    ("bistable joint (pos.-dep.), 1 deg", joint_pd, np.deg2rad(1.0), 40.0, 1),
    ("bistable joint (pos.-dep.), 1 deg", joint_pd, np.deg2rad(1.0), 30.0, 2),
    ("bistable joint (pos.-indep.), 0.5 deg", joint_pi, np.deg2rad(0.5), 50.0, 3),
    ("bistable joint (pos.-indep.), 5 deg", joint_pi, np.deg2rad(5.0), 30.0, 4),
    ("tri-stable NES, 0.5 mm", g.systems.tristable_nes, 5e-4, 60.0, 0),
    ("tri-stable NES, 0.5 mm", g.systems.tristable_nes, 5e-4, 40.0, 1),
    ("tri-stable NES, 0.5 mm", g.systems.tristable_nes, 5e-4, 30.0, 2),
    ("2-cell cubic chain, 0.3 mm", poly2, 3e-4, 50.0, 0),
    ("2-cell cubic chain, 0.3 mm", poly2, 3e-4, 30.0, 1),
    ("3-cell cubic chain, 0.3 mm", poly3, 3e-4, 40.0, 0),
    ("3-cell Kresling chain, 0.3 mm", g.systems.kresling3, 3e-4, 60.0, 0),
    ("3-cell Kresling chain, 0.3 mm", g.systems.kresling3, 3e-4, 40.0, 1),
    ("5-cell Kresling chain, 0.3 mm", g.systems.kresling5, 3e-4, 50.0, 0),
    ("shallow arch, 0.05", g.systems.shallow_arch, 0.05, 60.0, 0),
    ("shallow arch, 0.05", g.systems.shallow_arch, 0.05, 40.0, 1),
    ("shallow arch, 0.05", g.systems.shallow_arch, 0.05, 30.0, 2),
    ("magnetic oscillator, 0.05", g.systems.magnetic_bistable, 0.05, 60.0, 0),
    ("magnetic oscillator, 0.05", g.systems.magnetic_bistable, 0.05, 40.0, 1),
    ("magnetic oscillator, 0.05", g.systems.magnetic_bistable, 0.05, 30.0, 2),
]

QUICK = [0, 7, 9, 15, 18]


def measure(model, system, i, n=401):
    """Coverage, width and errors of DOF `i` (module docstring; `gmr.metrics.band_coverage`)."""
    eq = system.equilibria[:, i]
    out = {}
    for name, x_range in (("span", (eq.min(), eq.max())), ("box", tuple(system.x_range[i]))):
        band = g.metrics.band_coverage(model, system.truth, i, x_range, n=n, level=LEVEL)
        out[f"cover_{name}"] = band.share
        if name == "span":
            out["width"], out["max_err_span"] = band.width, band.max_error
    out["restoring_error"] = g.metrics.restoring_error(model, system.truth, i, system.x_range[i])
    out["cover_damping"], out["width_damping"] = damping_band(model, system, i)
    return out


def damping_band(model, system, i: int, level: float = LEVEL) -> tuple[float, float]:
    """The damping band of DOF `i` over the wells' span x v_range (41 x 40 points, v != 0, the other DOFs at 0):
    the share of the points where it holds the truth's damping force, and its median full width relative to the
    largest |truth| there."""
    eq = system.equilibria[:, i]
    band = g.metrics.band_coverage(model, system.truth, i, (eq.min(), eq.max()), system.v_range[i], part="damping",
                                   level=level, n=41, n_v=41)
    return band.share, band.width


#: extra `reconstruct` keywords (`--coordination`)
OPTIONS: dict = {}


def run_case(label, factory, amplitude, snr, seed):
    system = factory()
    recs = g.systems.make_recordings(system, amplitude, snr_db=snr, seed=seed)
    r, dd = system.orders["gmr"]
    t0 = time.time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = g.reconstruct(recs, g.Library(r, dd), throw=False, **OPTIONS,
                            designs=system.designs if OPTIONS.get("coordination", "evidence") == "evidence" else None)
    seconds = time.time() - t0
    rows = []
    for i in range(sol.value.n_dof):
        st = sol.stats["dofs"][i].stats
        route = st["coordination"] + (f" + design (spread {st['design_spread']:.1e})" if "design" in st else "")
        row = {"case": label, "snr": snr, "seed": seed, "dof": i, "route": route, "seconds": seconds}
        row |= measure(sol.value, system, i)
        rows.append(row)
    return rows, system, sol.value


def basin_demo(lines, n_samples=8, grid=20):
    """Basin probability on the bistable joint (tip-force half-sine of Eq. 25 on a single DOF:
    `load="tip"` acts on the mass): the model's own map against the distribution's."""
    system = joint_pd()
    recs = g.systems.make_recordings(system, np.deg2rad(1.0), snr_db=30.0, seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = g.reconstruct(recs, g.Library(*system.orders["gmr"]), **OPTIONS).value
    f = np.linspace(0.5, 6.0, grid)
    A = np.linspace(500.0, 4000.0, grid)
    t0 = time.time()
    settings = g.SweepSettings(settle_time=5.0)
    sol = g.basin_probability(model, f, A, jax.random.key(0), n_samples, x_range=system.x_range, settings=settings)
    bp = sol.value
    truth = g.basin_map(system.truth, f, A, g.stable_wells(system.truth, system.x_range), settings=settings,
                        throw=False).value
    conf = np.asarray(bp.confidence)
    agree_mean = float(np.mean(np.asarray(bp.mean_config) == np.asarray(truth.config)))
    agree_likely = float(np.mean(np.asarray(bp.most_likely) == np.asarray(truth.config)))
    certain = conf == 1.0
    lines += [
        "", "## Basin map drawn from the model distribution", "",
        f"Bistable joint (position-dependent damping, 1 deg, 30 dB, seed 2), Eq. 25 half-sine on the mass, "
        f"{grid} x {grid} grid f = 0.5-6 Hz, A = 500-4000 (per unit inertia), settle 5 s; "
        f"`basin_probability` with {n_samples} samples ({sol.stats['samples_used']} used, "
        f"{sol.stats['samples_other_wells']} with other wells, {sol.stats['samples_non_dissipative']} whose damping "
        f"feeds energy in), {time.time() - t0:.0f} s.", "",
        "| measure | value |", "|---|---|",
        f"| points where every sample agrees (probability 1) | {100 * certain.mean():.1f} % |",
        f"| median probability of the most likely configuration | {np.median(conf):.3f} |",
        f"| agreement of the model's own map with the truth's | {100 * agree_mean:.1f} % |",
        f"| agreement of the most likely configuration with the truth's | {100 * agree_likely:.1f} % |",
        f"| truth agrees with the model where every sample agrees | "
        f"{100 * float(np.mean((np.asarray(bp.mean_config) == np.asarray(truth.config))[certain])):.1f} % of those points |",
        f"| ... where the samples disagree | "
        f"{100 * float(np.mean((np.asarray(bp.mean_config) == np.asarray(truth.config))[~certain])) if (~certain).any() else float('nan'):.1f} % of those points |",
    ]


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--basins", action="store_true")
    p.add_argument("--out", default=None)
    p.add_argument("--coordination", default="evidence", choices=["evidence", "hermite", "gls"],
                   help="reconstruct(coordination=...): evidence (the default) or the paper's route")
    args = p.parse_args()
    OPTIONS["coordination"] = args.coordination
    cases = [CASES[k] for k in QUICK] if args.quick else CASES
    out = Path(args.out or RESULTS / ("coverage_quick.md" if args.quick else "coverage.md"))
    cmd = "python studies/coverage.py" + " ".join([""] + sys.argv[1:])
    rows = []
    for c in cases:
        got, _, _ = run_case(*c)
        for r in got:
            print({k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items()}, flush=True)
        rows += got
    lines = [
        "# Coverage of the global model's 95 % band", "",
        f"Command: `{cmd}` (module docstring: definitions). `reconstruct(coordination={args.coordination!r})` (library orders "
        f"`system.orders['gmr']`), `force_band(level=0.95)` from `GlobalModel.covariance`.", "",
        "Columns: coverage of F_r,true by the 95 % band on the interwell span (target >= 90 %) and on the "
        "error box; the band's median full width on the span relative to max |F_r,true| there; the model's "
        "largest error on the span (same scale); restoring error (relative L2 on the box); damping band "
        "coverage on span x v_range and its median width relative to max |F_d,true|; coordination route.", "",
        "| case | SNR | seed | DOF | cover span | cover box | width | max err span | restoring err | "
        "cover damping | damping width | route |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['case']} | {r['snr']:g} dB | {r['seed']} | {r['dof']} | {100 * r['cover_span']:.1f} % | "
                     f"{100 * r['cover_box']:.1f} % | {100 * r['width']:.3g} % | {100 * r['max_err_span']:.3g} % | "
                     f"{100 * r['restoring_error']:.3g} % | {100 * r['cover_damping']:.1f} % | "
                     f"{100 * r['width_damping']:.3g} % | {r['route']} |")
    ok = [r for r in rows if r["cover_span"] >= TARGET]
    runs = {(r["case"], r["snr"], r["seed"]) for r in rows}
    runs_ok = {k for k in runs if all(r["cover_span"] >= TARGET for r in rows if (r["case"], r["snr"], r["seed"]) == k)}
    dok = [r for r in rows if r["cover_damping"] >= TARGET]
    lines += [
        "", "## Summary", "",
        f"- restoring band: {len(ok)} of {len(rows)} DOFs (cells) covered >= {100 * TARGET:.0f} % of the interwell "
        f"span; {len(runs_ok)} of {len(runs)} runs (system, SNR, seed) on every cell.",
        f"- median coverage on the span {100 * np.median([r['cover_span'] for r in rows]):.1f} %, on the box "
        f"{100 * np.median([r['cover_box'] for r in rows]):.1f} %; median relative width "
        f"{100 * np.median([r['width'] for r in rows]):.3g} % (max {100 * max(r['width'] for r in rows):.3g} %).",
        f"- damping band: {len(dok)} of {len(rows)} DOFs covered >= {100 * TARGET:.0f} % of span x v_range.",
        "- below target: " + (", ".join(f"{r['case']} {r['snr']:g} dB seed {r['seed']} DOF {r['dof']} "
                                        f"({100 * r['cover_span']:.0f} %)" for r in rows if r["cover_span"] < TARGET)
                              or "none"),
    ]
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n")  # the table first: the basin demonstration takes a while
    if args.basins:
        basin_demo(lines)
    text = "\n".join(lines) + "\n"
    out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
