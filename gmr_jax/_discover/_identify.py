"""What the estimation data can determine, decided before anything is re-calibrated or named.

- **Scale (the mass).** With no force input on a DOF (base excitation, free decay) its equation
  m a + F(x, v) = 0 is homogeneous: (m, every coefficient) x c fits exactly as well for any c, so a
  least-squares re-calibration that may move the mass slides to the trivial c -> 0. The mass is
  then held: it sets the scale, and the data fix only ratios to it.
- **Separability (variance inflation).** A column that the others reproduce (uncentred R^2 of
  its least-squares fit on them) is confounded with them. Two levels:
  `VIF_HARD` (R^2 >= 0.99): the column cannot be told apart from them with these data; such a
  candidate is reported as "not separable from <term>" with the correlation, never as a
  finding (a spring against the mass at one frequency: VIF ~1500). `VIF_MAX` (R^2 >= 0.95):
  collinear, but what is left of it may still be determined (EMPS: sgn(v) is 98 % correlated
  with v on its trapezoidal velocity profiles, VIF 26, yet the Coulomb level is fixed to +-8 %
  by 25,000 samples); such a candidate competes, but counts only when the selection rule keeps
  it and its bootstrap interval is tight (`determined`), else it is listed as not separable.
  A mass with VIF >= `VIF_MAX` against the model's terms is held.
- **A re-calibrated mass must stay a mass.** A mass moved outside [m/2, 2m] (or to <= 0) by the
  re-calibration is not believed: it is held and the DOF refitted.
"""

from dataclasses import dataclass, field

import numpy as np

#: variance inflation above which a candidate is collinear with the re-calibration columns
#: (R^2 >= 0.95) and counts only when determined (`determined`); a mass above it is held
VIF_MAX = 20.0
#: variance inflation above which a candidate is not separable at all (R^2 >= 0.99)
VIF_HARD = 100.0
#: a collinear candidate is determined when its 95 % interval excludes zero and its half-width
#: is at most this fraction of the coefficient
DETERMINED_HALF_WIDTH = 0.5
#: partial correlation (beyond the re-calibration columns) from which a candidate that fits as
#: well as a kept term is a substitute for it (`ambiguous`)
SWAP_CORR = 0.5
#: applied-force energy relative to the inertial one below which a DOF has no force input
HOMOGENEOUS = 1e-12
#: the range a re-calibrated mass may move within, relative to the model's mass
MASS_RANGE = (0.5, 2.0)


@dataclass
class DofIdentifiability:
    """The decisions for one DOF (reported under `identifiability` in the discovery report)."""

    dof: int
    mass: str  # "refit", "held" or "given" (chain: masses are not re-calibrated)
    why: str = ""
    not_separable: list = field(default_factory=list)
    vif: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"dof": self.dof, "mass": self.mass, "why": self.why,
                "not_separable": self.not_separable, "vif": self.vif}


def _unit(X: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(X, axis=0)
    return X / np.where(n > 0, n, 1.0)


def explained(c: np.ndarray, X: np.ndarray) -> float:
    """Uncentred R^2 of the least-squares fit of column `c` on the columns of `X` (0 when X is
    empty or c is zero). The models have no intercept unless they carry a preload term, so the
    uncentred measure is the one that matches the regression."""
    cc = float(c @ c)
    if X.shape[1] == 0 or cc == 0.0:
        return 0.0
    Xu = _unit(X)
    coef, *_ = np.linalg.lstsq(Xu, c, rcond=1e-12)
    r = c - Xu @ coef
    return float(np.clip(1.0 - (r @ r) / cc, 0.0, 1.0))


def vif(r2: float) -> float:
    return float(np.inf) if r2 >= 1.0 else 1.0 / (1.0 - r2)


def closest(c: np.ndarray, X: np.ndarray, labels: list[str]) -> tuple[str, float]:
    """The column of X most correlated (uncentred cosine) with c, and that correlation."""
    cu = c / max(np.linalg.norm(c), 1e-300)
    cos = _unit(X).T @ cu
    k = int(np.argmax(np.abs(cos)))
    return labels[k], float(cos[k])


def homogeneous(rows) -> bool:
    """True when the DOF carries no applied force in any of the rows (its equation has no scale)."""
    applied = sum(r.applied_sq for r in rows)
    inertia = sum(r.inertia_sq for r in rows)
    return applied <= HOMOGENEOUS * max(inertia, 1e-300)


def separability_entry(physics: str, term: str, with_: str, corr: float, r2: float, reason: str) -> dict:
    """One `report.not_separable` entry: a candidate the data cannot tell apart from `with_`."""
    return {"physics": physics, "term": term, "with": with_, "correlation": corr, "r2": r2, "vif": vif(r2),
            "reason": reason}


def screen(Xb: np.ndarray, Xc: np.ndarray, base_labels: list[str], cand_labels: list[str],
           cand_physics: list[str]) -> tuple[list[int], list[dict], dict]:
    """Candidates not hopelessly confounded with the re-calibration columns `Xb` (VIF <
    `VIF_HARD`): (indices kept, not-separable entries, VIF of every candidate)."""
    keep, out, vifs = [], [], {}
    for j in range(Xc.shape[1]):
        r2 = explained(Xc[:, j], Xb)
        vifs[cand_labels[j]] = vif(r2)
        if vifs[cand_labels[j]] >= VIF_HARD:
            with_, corr = closest(Xc[:, j], Xb, base_labels)
            out.append(separability_entry(cand_physics[j], cand_labels[j], with_, corr, r2,
                                          f"not separable from {with_} with these data (correlation "
                                          f"{corr:.3f}, R^2 {r2:.3f} on the re-calibration columns): "
                                          f"not a finding"))
        else:
            keep.append(j)
    return keep, out, vifs


def determined(coef: float, ci: np.ndarray) -> bool:
    """A collinear candidate's coefficient is determined apart from the columns it is collinear
    with: its 95 % interval excludes zero and is at most +-`DETERMINED_HALF_WIDTH` of it."""
    lo, hi = float(ci[0]), float(ci[1])
    return bool(lo * hi > 0 and 0.5 * (hi - lo) <= DETERMINED_HALF_WIDTH * abs(coef))


def collinear_entry(physics: str, term: str, Xb: np.ndarray, c: np.ndarray, base_labels: list[str],
                    why: str) -> dict:
    """A not-separable entry for a collinear (VIF_MAX <= VIF < VIF_HARD) candidate not determined."""
    r2 = explained(c, Xb)
    with_, corr = closest(c, Xb, base_labels)
    return separability_entry(physics, term, with_, corr, r2,
                              f"collinear with {with_} in these data (correlation {corr:.3f}, R^2 {r2:.3f} on "
                              f"the re-calibration columns, VIF {vif(r2):.3g}) and {why}: not a finding")


def mass_believable(m: float, dm: float) -> bool:
    lo, hi = MASS_RANGE
    new = m + dm
    return bool(np.isfinite(new) and lo * m <= new <= hi * m)


def residualised(B: np.ndarray, X: np.ndarray) -> np.ndarray:
    """The columns of X with their least-squares fit on B removed (what B cannot explain)."""
    if B.shape[1] == 0:
        return X
    Q, _ = np.linalg.qr(_unit(B))
    return X - Q @ (Q.T @ X)


def _rss(Z: np.ndarray, y: np.ndarray) -> float:
    Zu = _unit(Z)
    coef, *_ = np.linalg.lstsq(Zu, y, rcond=1e-12)
    r = y - Zu @ coef
    return float(r @ r)


def ambiguous(B: np.ndarray, Xc: np.ndarray, kept: list[int], y: np.ndarray, n_eff: float,
              alpha: float = 0.05) -> list[tuple[int, int, float]]:
    """Kept candidates the data do not prefer to a substitute: (kept index, substitute index,
    partial correlation) where replacing the kept term by another candidate raises the residual
    sum of squares by less than the F(1, n_eff) critical value at `alpha` times the residual
    variance (n_eff: rows / integrated autocorrelation time). Such a term explains something,
    but these data cannot say which physics it is: at one forcing frequency, quadratic drag
    beyond its viscous part and cubic damping are both a third harmonic. Only substitutes whose
    part beyond B is correlated with the kept term's (|partial correlation| >= `SWAP_CORR`) count:
    a nearly orthogonal column that fits "as well" explains a different part of the residual
    (low power, not confounding; the F-test and the bootstrap judge the term itself)."""
    from scipy.stats import f as f_dist

    if not kept:
        return []
    full = np.concatenate([B, Xc[:, kept]], 1)
    rss = _rss(full, y)
    s2 = rss / max(n_eff - full.shape[1], 1.0)
    crit = float(f_dist.ppf(1.0 - alpha, 1, max(n_eff - full.shape[1], 1.0)))
    R = _unit(residualised(B, Xc))
    out = []
    for pos, k in enumerate(kept):
        best = None
        for j in range(Xc.shape[1]):
            if j in kept:
                continue
            if abs(float(R[:, k] @ R[:, j])) < SWAP_CORR:
                continue
            swap = full.copy()
            swap[:, B.shape[1] + pos] = Xc[:, j]
            d = (_rss(swap, y) - rss) / max(s2, 1e-300)
            if d < crit and (best is None or d < best[0]):
                best = (d, j)
        if best is not None:
            out.append((k, best[1], float(R[:, k] @ R[:, best[1]])))
    return out


def preload_entry(dof: int, rec_names: list) -> dict:
    """The not-separable entry of `preload` on a DOF whose equilibrium offset was unobservable."""
    return {"dof": dof, "physics": "preload", "term": "1", "with": "the equilibrium offset of x",
            "correlation": 1.0, "r2": 1.0, "vif": None,
            "reason": (f"x was integrated from velocity or acceleration ({', '.join(rec_names)}), so its static "
                       f"offset is unobservable and was placed by the model; a constant force trades exactly "
                       f"against that offset: not a finding (give 'equilibrium' to make it observable)")}
