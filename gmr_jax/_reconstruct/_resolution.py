"""What each well's data resolve, and the excitation that would resolve what they do not (issue 15).

The coordination (Eqs. 12-21) builds the global restoring force from the Taylor coefficients
a_k = F^(k)(x_i) / k! that the local fits (Eq. 8) measure at each well. Between the wells it can
only be as good as those coefficients: with the exact value, slope and curvature at every well
(the "curvature oracle") a non-polynomial truss is 2.6 % off, with value and slope alone 14.6 %.
This module says, per DOF (cell) and well, which of F, F', F'', F''' the well's records resolve,
which of those the global model needs, and how to excite so that a missing one is resolved.

**Resolved.** Order k at a well is resolved when the local fit kept it with |c_k| >= `T_RESOLVED`
(3) standard errors (significant), or when its noise-limited standard error se_k, carried over
half the distance h to the nearest other well, is at most `BOUND_FRACTION` (1 %) of the well's
force scale k_1 h (se_k h^k <= 0.01 k_1 h: the data bound it, whatever its value, below what
could matter between the wells). se_k is that of the hierarchical least-squares fit of the
well's data on 1, q, ..., q^k plus the damping terms the local fit kept (the term tested last,
so no higher-order column inflates it).

**Needed.** F, F' and F'' at every well (the curvature oracle's data; the issue's target is
to come within 2x of it), and F''' where the global model's own Taylor coefficient there, a_3^G
h^3, is at least `BOUND_FRACTION` of k_1 h (it shapes the force between the wells).

**Advice (scaling argument).** The least-squares standard error of the q^k coefficient is
se_k = sigma_y / (sqrt(N_eff) rms(q^k | lower columns)), and rms(q^k | ...) = g_k A^k, with
A the vibration amplitude and g_k (0 < g_k <= 1, `collinearity`) the share of q^k not
explained by the other columns: the record's harmonic content (a pure tone has g_3 = 0.32,
since q^3 = A^3 (3/4 sin - 1/4 sin 3wt) is 90 % collinear with q; a broadband Gaussian-like
response g_3 = 0.63, g_2 = 0.82). At a fixed SNR the force noise sigma_y grows like A (an
accelerometer's noise relative to its signal), so se_k ~ A^(1-k) / (10^(SNR/20) sqrt(N));
with a fixed noise floor se_k ~ A^-k (then less amplitude is needed than advised). Order k
becomes resolved when se_k falls by the factor rho = min(se_k h^(k-1) / (0.01 k_1),
3 se_k / |a_k^G|) (bounded, or significant at the global model's own value), i.e. at the
amplitude A rho^(1/(k-1)), or with rho^2 times the samples, or 20 log10(rho) dB more SNR;
when the record is nearly sinusoidal (g_k below 0.8 of the broadband value) a sweep over
about 0.5-2 x the well's natural frequency gains (g_broad / g_k). The advised amplitude aims
`SAFETY` (1.25) times below the threshold: the scaling is approximate (noise on x, and a
response spectrum that changes with amplitude, e.g. under cubic damping). The advice is checked by
simulation in `studies/stress_cases.py` (refit at the advised amplitude).

**Warning.** Every well with a needed order unresolved is reported as a `GMRDataWarning`
with its advice (`ResolutionReport.warnings`); `ResolutionReport.unresolved_everywhere` lists,
per DOF, the needed orders that no well resolved.
"""

from dataclasses import asdict, dataclass, field
from typing import ClassVar
from math import comb

import numpy as np

from .._fit._target_noise import structured_covariance
from .._fit._library import POSITION_DAMPING, STIFFNESS, VELOCITY_DAMPING

#: |coefficient| / standard error at which a kept local term counts as significant (the default screen).
T_RESOLVED = 3.0
#: A term is resolved when two of its noise-limited standard errors move the global restoring
#: force by at most this share of its RMS over the span (`_sanity.MAX_RESTORING_UNCERTAINTY`,
#: rule 11's 2 %); F''' is advised on (not needed) when the global model's own a_3 moves it by more.
BOUND_FRACTION = 0.02
#: The advice aims this factor below the threshold (the scaling is approximate: x noise, the
#: spectrum changing with amplitude).
SAFETY = 1.25
#: The span: the wells' range widened by this share of it on either side (the built-in boxes: 0.25).
BOX_MARGIN = 0.25
#: The orders every well must resolve: F, F', F'' (the curvature oracle's data).
NEEDED_ORDER = 2
#: Orders reported: F, F', F'', F'''.
ORDERS = (0, 1, 2, 3)
NAMES = ("F", "F'", "F''", "F'''")
#: g_k of a broadband (Gaussian) response, for the bandwidth advice: 1 / sqrt(VIF) of q^k on
#: 1, q, ..., q^(k-1) for q ~ N(0, 1).
G_BROADBAND = {1: 1.0, 2: float(np.sqrt(2.0 / 3.0)), 3: float(np.sqrt(0.4))}
#: Advised amplitudes above this share of the distance to the nearest other well leave the
#: small-vibration regime (`_sanity.LARGE_AMPLITUDE_RATIO`): then advise more samples or SNR.
MAX_ADVISED_RATIO = 0.3


@dataclass(frozen=True)
class TermResolution:
    """One Taylor order k at one well: the local fit's coefficient and standard error (0, 0
    when dropped), the hierarchical fit's standard error `se_h`, the global model's
    coefficient `global_coef`, the collinearity share `g`, the verdicts and the advised
    amplitude ratio (None when resolved or not needed)."""

    order: int
    coef: float
    se: float
    se_h: float
    global_coef: float
    g: float
    significant: bool
    bounded: bool
    needed: bool
    impact: float = 0.0
    share: float = 0.0
    rho: float = 1.0
    advised_ratio: float | None = None

    @property
    def resolved(self) -> bool:
        return self.bounded

    @property
    def name(self) -> str:
        return NAMES[self.order]

    @property
    def t(self) -> float:
        return abs(self.coef) / self.se if self.se > 0 else (np.inf if self.coef != 0 else 0.0)


@dataclass(frozen=True)
class WellResolution:
    """What one well's records resolve (`terms`: F, F', F'', F''') and where they stand:
    amplitude (99.9th percentile of |x - x_i|) as a ratio of the distance to the nearest other
    well, natural frequency f_n, the band (Hz) holding 5-95 % of the motion's power, samples."""

    dof: int
    well: int
    equilibrium: float
    recordings: list
    amplitude: float
    distance: float
    f_natural: float
    band: tuple
    n_samples: int
    terms: list = field(default_factory=list)

    @property
    def ratio(self) -> float:
        return self.amplitude / self.distance if self.distance > 0 else np.inf

    def missing(self) -> list[TermResolution]:
        return [t for t in self.terms if t.needed and not t.resolved]

    def advice(self) -> str | None:
        """Plain words for the needed orders this well does not resolve, None if none."""
        miss = self.missing()
        if not miss:
            return None
        names = ", ".join(NAMES[t.order] for t in miss)
        high = [t for t in miss if t.order >= 2]  # F' (order 1): amplitude does not change its standard error
        worst = max(high or miss, key=lambda t: t.advised_ratio if t.advised_ratio is not None else np.inf)
        k, rho = worst.order, max(t.rho for t in miss)  # the samples or SNR that resolve every missing order
        parts = []
        if len(high) < len(miss):
            parts.append(f"more amplitude does not help {NAMES[1]} at a fixed SNR (its standard error does not fall "
                         f"with the amplitude)")
        if high and worst.advised_ratio is not None and worst.advised_ratio <= MAX_ADVISED_RATIO:
            parts.append(f"excite it to about {100 * worst.advised_ratio:.2g} % of the interwell distance "
                         f"(now {100 * self.ratio:.2g} %; x{worst.advised_ratio / self.ratio:.2g} the amplitude)")
        elif high:
            parts.append(f"more amplitude alone would leave the small-vibration regime (it would need "
                         f"{'>' if worst.advised_ratio is None else ''}"
                         f"{100 * (worst.advised_ratio or MAX_ADVISED_RATIO):.2g} % of the interwell distance)")
        more, db = np.ceil(10.0 * rho**2) / 10.0, np.ceil(200.0 * np.log10(max(rho, 1.0))) / 10.0  # rounded up
        parts.append(f"or record {more:.3g} x as many samples, or {db:.3g} dB more SNR")
        gb = G_BROADBAND.get(k, G_BROADBAND[3])
        if worst.g < 0.8 * gb:
            parts.append(f"the record is nearly sinusoidal (its q^{k} is {100 * (1 - worst.g ** 2):.0f} % collinear with "
                         f"the lower orders, g_{k} = {worst.g:.2f}; band {self.band[0]:.3g}-{self.band[1]:.3g} Hz); "
                         f"a sweep over about {0.5 * self.f_natural:.3g}-{2 * self.f_natural:.3g} Hz "
                         f"(0.5-2 x f_n) would raise g_{k} towards {gb:.2f}")
        return (f"DOF {self.dof}, well at x = {self.equilibrium:.5g} ({', '.join(self.recordings)}): the records do "
                f"not resolve {names}, which the global model needs between the wells "
                f"({NAMES[k]}: {worst.t:.2g} standard errors; its noise moves the global force by ±{100 * worst.impact:.2g} % "
                f"RMS (2 sd) over the span, above {100 * BOUND_FRACTION:g} %); to resolve it " + "; ".join(parts))


@dataclass(frozen=True)
class ResolutionReport:
    """Per DOF (cell) and well, which local Taylor terms the data resolve, which the global
    model needs, and the excitation that would resolve the missing ones (module docstring of
    `gmr_jax._reconstruct._resolution`). `print(report)` gives a Markdown table and the advice.

    **Attributes:** `wells`: a list of `WellResolution`.
    """

    wells: list
    #: the resolution threshold (`BOUND_FRACTION`) and the orders every well must resolve
    bound: ClassVar[float] = BOUND_FRACTION
    needed_order: ClassVar[int] = NEEDED_ORDER

    def missing(self) -> list:
        return [(w, t) for w in self.wells for t in w.missing()]

    def advice(self) -> list[str]:
        return [a for w in self.wells if (a := w.advice())]

    def unresolved_everywhere(self) -> dict[int, list[str]]:
        """Per DOF, the orders some well needs and no well of that DOF resolves."""
        out = {}
        for d in sorted({w.dof for w in self.wells}):
            ws = [w for w in self.wells if w.dof == d]
            ks = [k for k in ORDERS if any(t.order == k and t.needed for w in ws for t in w.terms)
                  and not any(t.order == k and t.resolved for w in ws for t in w.terms)]
            if ks:
                out[d] = [NAMES[k] for k in ks]
        return out

    def warnings(self) -> list[str]:
        """The advice of every well with a needed order unresolved (emitted as `GMRDataWarning`)."""
        return self.advice()

    def table(self) -> str:
        head = ("| DOF | well x | amplitude (% of distance) | band (Hz) | f_n (Hz) | "
                + " | ".join(f"{n} (t / bound)" for n in NAMES) + " | missing | advised amplitude |")
        lines = [head, "|" + "---|" * (head.count("|") - 1)]
        for w in self.wells:
            cells = []
            for t in w.terms:
                mark = "ok" if t.resolved else ("**NO**" if t.needed else "no")
                cells.append(f"{mark} {t.t:.3g} / {100 * t.impact:.2g} %" + ("" if t.needed else " (not needed)"))
            miss = w.missing()
            adv = max((t.advised_ratio for t in miss if t.advised_ratio is not None), default=None)
            extra = "".join(f" ({t.name}, beyond F, F', F'': {100 * t.advised_ratio:.2g} %)" for t in w.terms
                            if not t.needed and not t.resolved and t.advised_ratio is not None)
            lines.append(f"| {w.dof} | {w.equilibrium:.5g} | {100 * w.ratio:.3g} | {w.band[0]:.3g}-{w.band[1]:.3g} | "
                         f"{w.f_natural:.3g} | " + " | ".join(cells) + f" | {', '.join(NAMES[t.order] for t in miss) or '-'}"
                         f" | {'-' if not miss else ('> %.2g %%' % (100 * MAX_ADVISED_RATIO) if adv is None or adv > MAX_ADVISED_RATIO else '%.2g %%' % (100 * adv))}{extra} |")
        return "\n".join(lines)

    def __str__(self) -> str:
        adv = self.advice()
        legend = ("t: |coefficient| / standard error of the local fit (0: dropped); bound: how far two noise-limited "
                  "standard errors of the term move the global restoring force (RMS over the wells' span widened by "
                  f"{100 * BOX_MARGIN:g} % either side), % of its RMS; ok = bound <= {100 * BOUND_FRACTION:g} %; "
                  "**NO** = needed (F, F', F'') and unresolved; advised amplitude: the response amplitude (% of the "
                  "interwell distance) at which they would be, and in parentheses F''' where the global model's own "
                  "F''' moves its force by more than the bound (beyond what F, F', F'' at the wells fix).")
        nowhere = self.unresolved_everywhere()
        lines = [self.table(), "", legend]
        if nowhere:
            lines += ["", "Needed by the global model and resolved at no well: "
                      + "; ".join(f"DOF {d}: {', '.join(n)}" for d, n in nowhere.items())]
        return "\n".join(lines + (["", "Advice:"] + [f"- {a}" for a in adv] if adv else []))

    def to_dict(self) -> list[dict]:
        """Plain-JSON form (the model file's "resolution" key)."""
        out = []
        for w in self.wells:
            d = asdict(w)
            d["band"] = list(w.band)
            d["terms"] = [asdict(t) | {"name": NAMES[t.order], "resolved": t.resolved} for t in w.terms]
            d["advice"] = w.advice()
            out.append(_plain(d))
        return out


def _plain(obj):
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj) if np.isfinite(obj) else None
    if isinstance(obj, (np.integer, np.bool_)):
        return obj.item()
    return obj


def _band(q: np.ndarray, dt: float) -> tuple[float, float]:
    """Frequencies (Hz) between which 5-95 % of the power of q (mean removed) lies."""
    q = np.asarray(q, float) - np.mean(q)
    p = np.abs(np.fft.rfft(q)) ** 2
    f = np.fft.rfftfreq(q.size, dt)
    c = np.cumsum(p[1:]) / max(np.sum(p[1:]), 1e-300)
    return float(f[1:][np.searchsorted(c, 0.05)]), float(f[1:][min(np.searchsorted(c, 0.95), c.size - 1)])


def _hierarchical(q, v, y, damping_cols, k, noise=None):
    """OLS of y on 1, q, ..., q^k and the given damping columns: (coef_k, se_k, g_k); with
    `noise` (a `TargetNoise`: the target holds estimated accelerations) the standard error is
    the structured sandwich's (`_fit/_target_noise.py`)."""
    cols = [q**j for j in range(k + 1)] + damping_cols
    theta = np.stack(cols, axis=1)
    scale = np.linalg.norm(theta, axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    ts = theta / scale
    coef, *_ = np.linalg.lstsq(ts, y, rcond=None)
    resid = y - ts @ coef
    dof = max(q.size - theta.shape[1], 1)
    s2 = float(resid @ resid) / dof
    inv = np.linalg.pinv(ts.T @ ts)
    se = np.sqrt(max(s2 * inv[k, k], 0.0)) / scale[k]
    if noise is not None:
        cov, _ = structured_covariance(ts, y, np.ones_like(y), coef, np.ones(ts.shape[1], bool), noise)
        se = np.sqrt(max(float(cov[k, k]), 0.0)) / scale[k]
    col = theta[:, k]
    ss = float(np.sum((col - col.mean()) ** 2))
    vif = inv[k, k] * ss / scale[k] ** 2 if k > 0 and ss > 0 else 1.0
    return float(coef[k] / scale[k]), float(se), float(1.0 / np.sqrt(max(vif, 1.0)))


def _damping_columns(q, v, library, support):
    out = []
    for (phys, j), s in zip(library.terms(), support):
        if not s or phys == STIFFNESS:
            continue
        if phys == VELOCITY_DAMPING:
            out.append(np.sign(v) * np.abs(v) ** j if j != 1 else v)
        elif phys == POSITION_DAMPING:
            out.append(q**j * v)
    return out


def hermite_influence(nodes, order: int, lo: float, hi: float, n: int = 201) -> np.ndarray:
    """(wells, order + 1): RMS over [lo, hi] of the cardinal Hermite polynomials of the nodes
    with orders 0..`order` at each: H_ik has Taylor coefficient 1 of order k at node i and 0 for
    every other (node, order); a change da of the local coefficient a_ik moves the interpolated
    global force by da H_ik(x) (the coordination is linear in the local coefficients)."""
    nodes = np.asarray(nodes, float)
    c, hs = 0.5 * (nodes.max() + nodes.min()), max(0.5 * float(np.ptp(nodes)), 1e-300)
    u = (nodes - c) / hs
    m = nodes.size * (order + 1)
    p = np.arange(m)
    rows = []
    for ul in u:
        for j in range(order + 1):
            coef = np.array([comb(int(q), j) for q in p], float)
            rows.append(coef * np.where(p >= j, ul ** np.maximum(p - j, 0), 0.0))
    vand = np.array(rows)
    grid = np.polynomial.polynomial.polyvander((np.linspace(lo, hi, n) - c) / hs, m - 1)
    out = np.zeros((nodes.size, order + 1))
    for i in range(nodes.size):
        for k in range(order + 1):
            rhs = np.zeros(m)
            rhs[i * (order + 1) + k] = hs**k
            out[i, k] = float(np.sqrt(np.mean((grid @ np.linalg.solve(vand, rhs)) ** 2)))
    return out


def _taylor(stiffness: np.ndarray, x0: float, k: int) -> float:
    """F^(k)(x0) / k! of the ascending polynomial `stiffness`."""
    p = np.polynomial.Polynomial(np.asarray(stiffness, float))
    return float(p.deriv(k)(x0) / np.prod(np.arange(1, k + 1))) if k <= p.degree() else 0.0


def resolution_report(recs, targets, groups, reports, model, library, masses, topology,
                      noises=None) -> ResolutionReport:
    """The `ResolutionReport` of a reconstruction: `recs` (completed recordings), `targets`
    (per recording, the (N, D) force each DOF carries), `groups` (per DOF, per well, the
    recording indices), `reports` (per DOF, the `DofReport`), `model` (the `GlobalModel`),
    `library`, `masses`, `topology` (its `carried` sums the masses a chain cell carries);
    `noises` (per DOF, per well, a `TargetNoise` or None) where accelerations were estimated."""
    terms = library.terms()
    idx = {k: terms.index((STIFFNESS, k)) for k in ORDERS if (STIFFNESS, k) in terms}
    carried = np.asarray(topology.carried(np.asarray(masses, float)[None, :]))[0]
    wells = []
    for i, (grp, rep) in enumerate(zip(groups, reports)):
        eq = np.asarray(rep.equilibria, float)
        stiff = np.asarray(model.stiffness[i])
        lo, hi = eq.min() - BOX_MARGIN * np.ptp(eq), eq.max() + BOX_MARGIN * np.ptp(eq)
        f_rms = float(np.sqrt(np.mean(np.polynomial.polynomial.polyval(np.linspace(lo, hi, 201), stiff) ** 2)))
        # order k <= 2 as the curvature oracle uses it (orders 0..2 at every well), F''' with orders 0..3
        influence = {k: (hermite_influence(eq, max(k, NEEDED_ORDER), lo, hi)[:, k] if eq.size > 1
                         else np.zeros(eq.size)) for k in ORDERS}
        for w, g in enumerate(grp):
            x0 = float(eq[w])
            others = np.delete(eq, w)
            dist = float(np.min(np.abs(others - x0))) if others.size else 0.0
            q = np.concatenate([recs[k].x[:, i] for k in g]) - x0
            v = np.concatenate([recs[k].v[:, i] for k in g])
            y = np.concatenate([targets[k][:, i] for k in g])
            amp = max(float(np.percentile(np.abs(recs[k].x[:, i] - recs[k].x[:, i].mean()), 99.9)) for k in g)
            coef, se = np.asarray(rep.local_coef[w], float), np.asarray(rep.local_stderr[w], float)
            k1 = abs(coef[idx[1]]) if 1 in idx else 0.0
            f_n = float(np.sqrt(k1 / carried[i]) / (2 * np.pi)) if carried[i] > 0 else float("nan")
            band = _band(recs[g[0]].x[:, i], recs[g[0]].dt)
            damp = _damping_columns(q, v, library, coef != 0)
            rows = []
            for k in ORDERS:
                if k not in idx:
                    continue
                c, s = float(coef[idx[k]]), float(se[idx[k]])
                _, se_h, gk = _hierarchical(q, v, y, damp, k, noises[i][w] if noises else None)
                se_h = max(se_h, s)  # a kept term: the local fit's own (larger-library) standard error
                a_g = _taylor(stiff, x0, k)
                significant = c != 0 and s > 0 and abs(c) >= T_RESOLVED * s
                impact = 2.0 * se_h * influence[k][w] / f_rms if f_rms > 0 else np.inf
                share = abs(a_g) * influence[k][w] / f_rms if f_rms > 0 else 0.0
                bounded = bool(impact <= BOUND_FRACTION)
                needed = k <= NEEDED_ORDER
                useful = needed or share >= BOUND_FRACTION
                rho, ratio = 1.0, None
                if useful and not bounded and k >= 1 and np.isfinite(impact):
                    rho = max(SAFETY * impact / BOUND_FRACTION, 1.0)
                    # F' (k = 1): its standard error does not fall with the amplitude at a fixed SNR
                    ratio = amp / dist * rho ** (1.0 / (k - 1)) if dist > 0 and k >= 2 else None
                rows.append(TermResolution(order=k, coef=c, se=s, se_h=se_h, global_coef=a_g, g=gk,
                                           significant=bool(significant), bounded=bounded, needed=bool(needed),
                                           impact=float(impact), share=float(share), rho=float(rho),
                                           advised_ratio=ratio))
            wells.append(WellResolution(dof=i, well=w, equilibrium=x0, recordings=[recs[k].name for k in g],
                                        amplitude=amp, distance=dist, f_natural=f_n, band=band,
                                        n_samples=int(q.size), terms=rows))
    return ResolutionReport(wells=wells)


def format_resolution(entries: list[dict], detail: bool = False) -> list[str]:
    """Lines `gmr show` prints for a model file's "resolution" key (`ResolutionReport.to_dict`); `detail`: each
    term's t (|coefficient| / standard error) and bound (% of the global force its two standard errors move)."""
    out = []
    for w in entries:
        try:
            terms = " ".join(f"{t['name']} {'ok' if t['resolved'] else ('NO' if t['needed'] else 'no')}"
                             + (f" (coefficient {t.get('coef') or 0:.4g} +- {t.get('se') or 0:.2g}, bound "
                                f"{100 * (t.get('impact') or 0):.2g} %)" if detail else "")
                             for t in w["terms"])
            ratio = w["amplitude"] / w["distance"] if w.get("distance") else float("nan")
            out.append(f"  DOF {w['dof']}, well x = {w['equilibrium']:.5g}: amplitude {100 * ratio:.3g} % of the "
                       f"interwell distance; {terms}")
            if w.get("advice"):
                out.append(f"    advice: {w['advice']}")
        except (KeyError, TypeError, ZeroDivisionError):
            out.append(f"  (unreadable entry: {str(w)[:80]})")
    return out
