"""Issue 15: does the noise on a measured v bias the damping law?

`reconstruct` corrects the local regressions for the noise on x (errors in variables,
`_fit/_errors_in_variables.py`); the velocity factors of the damping columns (v, v|v|, v^3, ...)
are taken as measured. On a law with a cubic velocity term and large velocities that cannot hold:
E[(v + e)^3] = v^3 + 3 s^2 v, so a noisy v leaks into the linear and signed-square terms and
attenuates the cubic. This study reconstructs the same sweeps as recorded (every channel at the
given SNR) with the velocity columns taken as measured (`velocity_eiv=False`), as recorded with
the joint regression's velocity correction (the default, `velocity_eiv=True`: `_joint._velocity_noise`,
its covariance `_joint._sandwich`), and with v replaced by its noise-free value (x and a as recorded),
and compares the damping coefficients with the truth in the model's own standard errors
(`GlobalModel.stderr`), with `coordination="joint"` so that every run takes the same route. Then, with
`reconstruct`'s defaults (route "auto": the paper route's damping handed to the corrected joint regression where
the noise of v moves it, `_reconstruct._velocity_noise.V_NOISE_DAMPING`), the damping band per seed; and the scatter over fresh
draws of v's noise about one seed's clean v, through the joint route (x and a noise-free: the corrected
estimator's own bias and calibration, the velocity set re-tested on its robust covariance,
`_joint._robust_velocity_set`) and through the defaults (x and a as recorded: the damping band per draw).

    python studies/velocity_noise.py [--seeds 8] [--redraws 20] [--auto-redraws 12] [--out results/velocity_noise.md]

Case: the bistable joint (position-independent damping, truth 10 v^3), 5 degrees, 30 dB
(`g.systems.bistable_joint("position_independent")`).
"""

import argparse
import sys
import time
import warnings
from pathlib import Path

import numpy as np

import gmr_jax as g

sys.path.insert(0, str(Path(__file__).resolve().parent))
from coverage import damping_band


def damping_coverage(model, system) -> float:
    """Share of the wells' span x v_range where the model's 95 % damping band holds the truth's damping force
    (`studies/coverage.damping_band`)."""
    return damping_band(model, system, 0)[0]


def fit(recs, clean, system, v_clean: bool, velocity_eiv: bool = False, coordination: str = "joint"):
    rr = [g.Recording(t=r.t, x=r.x, v=(c.v if v_clean else r.v), a=r.a, base_acc=r.base_acc, masses=r.masses,
                      name=r.name) for r, c in zip(recs, clean)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sol = g.reconstruct(rr, g.Library(*system.orders["gmr"]), throw=False, coordination=coordination,
                            velocity_eiv=velocity_eiv)
    m = sol.value
    return (np.asarray(m.velocity_damping[0], float), np.asarray(m.stderr["velocity_damping"][0], float),
            sol.stats["dofs"][0].stats.get("joint_velocity_orders"), damping_coverage(m, system),
            sol.stats["dofs"][0].stats["coordination"])


def redraws(recs, clean, n: int, rng, as_recorded: bool):
    """`n` copies of the recordings whose v is the clean v plus fresh white noise of the recorded level (per
    channel); x, a and the base as recorded (`as_recorded`) or noise-free."""
    for _ in range(n):
        yield [g.Recording(t=c.t, x=(r if as_recorded else c).x,
                           v=c.v + np.std(r.v - c.v, axis=0) * rng.standard_normal(c.v.shape),
                           a=(r if as_recorded else c).a, base_acc=(r if as_recorded else c).base_acc,
                           masses=c.masses, name=c.name) for r, c in zip(recs, clean)]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--snr", type=float, default=30.0)
    ap.add_argument("--out", default="results/velocity_noise.md")
    ap.add_argument("--redraws", type=int, default=20,
                    help="redraws of v's noise about one seed's clean v (--redraw-seed): the corrected estimator's "
                    "own scatter and mean, against the standard errors it reports")
    ap.add_argument("--redraw-seed", type=int, default=4)
    ap.add_argument("--auto-redraws", type=int, default=12,
                    help="redraws of v's noise about the same seed's clean v, x, a and the base as recorded, through "
                    "reconstruct's defaults (route auto): the damping band per redraw")
    args = ap.parse_args()
    t0 = time.time()
    s = g.systems.bistable_joint("position_independent")
    amp = np.deg2rad(5.0)
    rows, auto = [], []
    for seed in range(args.seeds):
        recs = g.systems.make_recordings(s, amp, snr_db=args.snr, seed=seed)
        clean = g.systems.make_recordings(s, amp, snr_db=None, seed=seed)
        for v_clean, eiv, mode in ((False, False, "as recorded, `velocity_eiv=False`"),
                                   (False, True, "as recorded, `velocity_eiv=True` (default)"), (True, False, "noise-free")):
            b, se, orders, cover, _ = fit(recs, clean, s, v_clean, eiv)
            rows.append((seed, mode, b, se, orders, cover))
            print(rows[-1][:2], b[:4], se[:4], orders, cover, flush=True)
        for eiv in (False, True):  # reconstruct's defaults (route "auto"), as the coverage study
            *_, cover, route = fit(recs, clean, s, False, eiv, coordination="auto")
            auto.append((seed, eiv, cover, route))
            print(auto[-1], flush=True)
    recs = g.systems.make_recordings(s, amp, snr_db=args.snr, seed=args.redraw_seed)
    clean = g.systems.make_recordings(s, amp, snr_db=None, seed=args.redraw_seed)
    redraw = []  # x, a and the base noise-free at one seed; v = its clean v + fresh noise of the recorded level
    for noisy in redraws(recs, clean, args.redraws, np.random.default_rng(12345), as_recorded=False):
        b, se, orders, _, _ = fit(noisy, clean, s, False, True)
        redraw.append((b, se, orders))
        print("redraw", b[:4], se[:4], orders, flush=True)
    auto_redraw = []  # as above, but x, a and the base as recorded, and reconstruct's defaults
    for noisy in redraws(recs, clean, args.auto_redraws, np.random.default_rng(5), as_recorded=True):
        b, se, orders, cover, route = fit(noisy, clean, s, False, True, coordination="auto")
        auto_redraw.append((b, se, orders, cover, route))
        print("auto redraw", b[:4], se[:4], orders, cover, route, flush=True)
    lines = ["# Noise on v and the damping law", "",
             (f"`python studies/velocity_noise.py --seeds {args.seeds} --redraws {args.redraws} --auto-redraws "
              f"{args.auto_redraws}` ({(time.time() - t0) / 60:.1f} min on the "
              "shared 2-core dev machine)."), "", __doc__.split("\n\n    python")[0].split("\n\n", 1)[1], "",
             f"Truth: 10 v^3. Bistable joint, position-independent damping, base amplitude 5 degrees, {args.snr:g} dB.", "",
             "Coordination forced to the joint regression (`coordination=\"joint\"`); damping band: the share of the "
             "wells' span x v_range where the 95 % band of the damping force holds the truth's (target >= 90 %).", "",
             "| seed | v | velocity orders chosen | v coefficient (se) | v^3 coefficient (se) | v^3 error / se | damping band |",
             "|---|---|---|---|---|---|---|"]
    for seed, mode, b, se, orders, cover in rows:
        lines.append(f"| {seed} | {mode} | {orders} | {b[1]:.4g} ({se[1]:.3g}) | {b[3]:.5g} ({se[3]:.3g}) | "
                     f"{(b[3] - 10.0) / se[3]:+.2f} | {cover:.1%} |")
    lines += ["", "Per mode over the seeds: the RMS of (v^3 - 10) / se (1 for calibrated standard errors) and the share "
              "of seeds whose v^3 lies within 1.96 se of 10 (95 % for a calibrated band).", "",
              "| v | RMS of (v^3 error) / se | within 1.96 se |", "|---|---|---|"]
    for mode in dict.fromkeys(r[1] for r in rows):
        z = np.array([(b[3] - 10.0) / se[3] for _, m, b, se, *_ in rows if m == mode])
        lines.append(f"| {mode} | {np.sqrt(np.mean(z**2)):.2f} | {np.mean(np.abs(z) <= 1.96):.0%} ({int(np.sum(np.abs(z) <= 1.96))}"
                     f" of {z.size}) |")
    lines += ["", "With `reconstruct`'s defaults (route \"auto\", as in `studies/coverage.py`): the damping band per seed.",
              "", "| seed | route | `velocity_eiv=False` | `velocity_eiv=True` (default) |", "|---|---|---|---|"]
    for seed in range(args.seeds):
        (_, _, c0, r0), (_, _, c1, r1) = [a for a in auto if a[0] == seed]
        lines.append(f"| {seed} | {r1}{'' if r0 == r1 else f' ({r0} without)'} | {c0:.1%} | {c1:.1%} |")
    cells = []
    for eiv in (False, True):
        c = np.array([a[2] for a in auto if a[1] == eiv])
        cells.append(f"{int(np.sum(c >= 0.9))} of {c.size} >= 90 %, median {np.median(c):.1%}")
    lines.append(f"| all | | {cells[0]} | {cells[1]} |")
    if redraw:
        b = np.array([r[0] for r in redraw])
        se = np.array([r[1] for r in redraw])
        alone = sum(r[2] == [3] for r in redraw)
        lines += ["", f"The corrected estimator's own scatter: seed {args.redraw_seed}'s clean sweeps (x, a and the base "
                  f"noise-free), v with {args.redraws} fresh draws of white noise at the recorded level, joint route, "
                  f"`velocity_eiv=True` ({alone} of {args.redraws} chose v^3 alone).", "",
                  "| coefficient | truth | mean over the redraws (its se) | scatter (sd) | mean reported se |", "|---|---|---|---|---|"]
        for j, name, truth in ((1, "v", 0.0), (3, "v^3", 10.0)):
            lines.append(f"| {name} | {truth:g} | {b[:, j].mean():.4g} ({b[:, j].std(ddof=1) / np.sqrt(len(b)):.2g}) | "
                         f"{b[:, j].std(ddof=1):.3g} | {se[:, j].mean():.3g} |")
    if auto_redraw:
        cover = np.array([r[3] for r in auto_redraw])
        lines += ["", f"The defaults' own scatter on seed {args.redraw_seed}: its sweeps as recorded (x, a and the base "
                  f"with their noise), v with {args.auto_redraws} fresh draws of white noise at the recorded level, "
                  f"`reconstruct` defaults: the damping band holds the truth on >= 90 % of the span x v_range in "
                  f"{int(np.sum(cover >= 0.9))} of {cover.size} (median {np.median(cover):.1%}, lowest {cover.min():.1%}).",
                  "", "| redraw | route | velocity orders | Coulomb (se) | v (se) | v\\|v\\| (se) | v^3 (se) | damping band |",
                  "|---|---|---|---|---|---|---|---|"]
        for n, (b, se, orders, c, route) in enumerate(auto_redraw):
            lines.append(f"| {n} | {route} | {orders} | {b[0]:.3g} ({se[0]:.2g}) | {b[1]:.3g} ({se[1]:.2g}) | "
                         f"{b[2]:.3g} ({se[2]:.2g}) | {b[3]:.5g} ({se[3]:.2g}) | {c:.1%} |")
    with open(args.out, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
