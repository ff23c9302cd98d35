"""Sparse selection of new physics with a stated false-discovery rule.

The residual y of the given model is regressed on two groups of columns: the model's own basis
functions (and, for independent DOFs, its mass), always allowed to move (re-calibration: a
calibrated model has absorbed the missing physics into its own coefficients, e.g. Coulomb
friction into viscous damping, so the missing term only shows once they can move back), and the
candidate new physics, which must pass the rule:

1. **Forward step with blocked validation.** Among the candidates not yet kept, the one with the
   smallest blocked `n_folds`-fold cross-validation error (contiguous blocks of rows) is tried;
   it must lower that error by at least `min_cv_gain` (relative).
2. **Significance with a Bonferroni bound.** Its partial F-test (one extra column) must have
   p < `alpha` / q, q = the number of candidates in the catalogue for that DOF. The residuals
   are autocorrelated, so the test uses the effective number of rows n / tau, tau the
   integrated autocorrelation time of the larger model's residual (Sokal window).
4. **Practical relevance.** A kept term must explain at least `min_explained` (2 %) of the given
   model's residual sum of squares by itself (drop-one from the final fit); terms below are
   dropped one at a time, smallest first, and listed as rejected.
3. **Bootstrap stability.** Step 2 (the same test and tau) is repeated from scratch on
   `n_boot` moving-block bootstrap replicates of the rows (blocks of `block` rows, default
   max(20, 10 tau)); a term kept in step 1-2 is reported only if it is selected in at least
   `stability` of the replicates. Terms that fail are listed as rejected, with their frequency.

Coefficients come from the least-squares refit of re-calibration + kept terms; 95 % intervals
are percentile intervals of the same block bootstrap (they include the autocorrelation, not the
bias of least squares with noisy regressors).

The Gram-matrix kernels are jitted and vmapped over candidate masks and bootstrap replicates
(fixed shapes: a mask selects the columns).
"""

import math
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from .._errors import as_whole_number, check_real
from .._fit._householder import back_substitute, householder_qr


@dataclass(frozen=True)
class SelectionRule:
    """Settings of the selection rule (module docstring)."""

    alpha: float = 0.05
    min_cv_gain: float = 0.01
    n_folds: int = 5
    n_boot: int = 200
    stability: float = 0.8
    block: int | None = None
    max_new: int = 4
    seed: int = 0
    min_explained: float = 0.02

    def __post_init__(self):
        check_real(self.alpha, "SelectionRule.alpha", lo=0.0, hi=1.0, lo_open=True, hi_open=True,
                   fix="give the family-wise false-discovery level, e.g. 0.05")
        check_real(self.min_cv_gain, "SelectionRule.min_cv_gain", lo=0.0, hi=1.0, hi_open=True,
                   fix="give the least relative drop of the cross-validation error, e.g. 0.01")
        as_whole_number(self.n_folds, "SelectionRule.n_folds", lo=2, fix="give the number of CV blocks, e.g. 5")
        as_whole_number(self.n_boot, "SelectionRule.n_boot", lo=1,
                        fix="give the number of bootstrap replicates, e.g. 200")
        check_real(self.stability, "SelectionRule.stability", lo=0.0, hi=1.0,
                   fix="give the least share of bootstrap replicates that must select a term, e.g. 0.8")
        if self.block is not None:
            as_whole_number(self.block, "SelectionRule.block", lo=1,
                            fix="give the bootstrap block length in rows, or None for the automatic one")
        as_whole_number(self.max_new, "SelectionRule.max_new", lo=0,
                        fix="give the most new terms per DOF, e.g. 4")
        as_whole_number(self.seed, "SelectionRule.seed", lo=0, fix="give a non-negative integer seed")
        check_real(self.min_explained, "SelectionRule.min_explained", lo=0.0, hi=1.0,
                   fix="give the least share of the model's residual a kept term must explain, e.g. 0.02")


def _masked_solve(G, b, mask):
    m = mask.astype(G.dtype)
    A = G * (m[:, None] * m[None, :]) + jnp.diag(1.0 - m)
    # tiny ridge relative to the diagonal keeps near-collinear columns solvable
    A = A + 1e-12 * jnp.trace(A) / A.shape[0] * jnp.eye(A.shape[0])
    # Householder QR in plain XLA: `rss`/`cv_sse` run vmapped, and jaxlib 0.10.2's batched LAPACK
    # kernels can deadlock (`_fit/_householder.py`)
    return back_substitute(*householder_qr(A, b * m)) * m


@jax.jit
def rss(G, b, yy, mask):
    """Residual sum of squares of the least-squares fit on the masked columns."""
    c = _masked_solve(G, b, mask)
    return yy - 2 * c @ b + c @ G @ c


@jax.jit
def cv_sse(Gf, bf, yyf, mask, prior):
    """Blocked cross-validation SSE: fit on all folds but one (Gram sums plus the `prior`
    precision), score on that one."""
    G, b = Gf.sum(0) + prior, bf.sum(0)

    def one(Gk, bk, yyk):
        c = _masked_solve(G - Gk, b - bk, mask)
        return yyk - 2 * c @ bk + c @ Gk @ c

    return jnp.sum(jax.vmap(one)(Gf, bf, yyf))


@jax.jit
def coefficients(G, b, mask):
    return _masked_solve(G, b, mask)


_rss_many = jax.jit(jax.vmap(rss, in_axes=(None, None, None, 0)))
_cv_many = jax.jit(jax.vmap(cv_sse, in_axes=(None, None, None, 0, None)))
# replicates x masks
_rss_boot = jax.jit(jax.vmap(jax.vmap(rss, in_axes=(None, None, None, 0)), in_axes=(0, 0, 0, 0)))
_coef_boot = jax.jit(jax.vmap(coefficients, in_axes=(0, 0, None)))


def autocorrelation(r: np.ndarray, max_lag: int) -> np.ndarray:
    """Sample autocorrelation at lags 0..max_lag (FFT, biased normalisation)."""
    r = np.asarray(r, float) - np.mean(r)
    n = r.size
    f = np.fft.rfft(r, 2 * n)
    c = np.fft.irfft(f * np.conj(f))[: max_lag + 1]
    return c / max(c[0], 1e-300)


def integrated_time(r: np.ndarray, max_lag: int | None = None) -> float:
    """Integrated autocorrelation time 1 + 2 sum rho_k, summed until k >= 5 tau (Sokal)."""
    r = np.asarray(r, float)
    max_lag = max_lag or min(r.size // 4, 5000)
    rho = autocorrelation(r, max_lag)
    tau = 1.0
    for k in range(1, max_lag + 1):
        tau += 2 * rho[k]
        if k >= 5 * tau:
            break
    return float(max(tau, 1.0))


@dataclass
class Selection:
    """Outcome of `select_terms` (coefficients in the units of the unscaled columns)."""

    kept: list            # candidate indices reported (passed 1-3), in order of entry
    rejected: list        # (candidate index, reason)
    coef_base: np.ndarray  # re-calibration coefficients
    coef_kept: np.ndarray
    ci_base: np.ndarray   # (p0, 2)
    ci_kept: np.ndarray   # (k, 2)
    stability: np.ndarray  # (q,) frequency each candidate was selected in the bootstrap
    explained: np.ndarray  # (k,) drop-one RSS increase / RSS of the given model
    explained_base: float  # share of the given model's RSS removed by re-calibration alone
    explained_total: float
    steps: list = field(default_factory=list)
    tau: float = 1.0
    n_rows: int = 0
    resid: np.ndarray | None = None


def _grams(Z, y, n_folds):
    n = Z.shape[0]
    edges = np.linspace(0, n, n_folds + 1).astype(int)
    Gf = np.stack([Z[a:b].T @ Z[a:b] for a, b in zip(edges[:-1], edges[1:])])
    bf = np.stack([Z[a:b].T @ y[a:b] for a, b in zip(edges[:-1], edges[1:])])
    yyf = np.array([y[a:b] @ y[a:b] for a, b in zip(edges[:-1], edges[1:])])
    return jnp.asarray(Gf), jnp.asarray(bf), jnp.asarray(yyf)


def _f_pvalue(rss0, rss1, n_eff, p1):
    d2 = max(n_eff - p1, 1.0)
    F = max(rss0 - rss1, 0.0) / max(rss1 / d2, 1e-300)
    from scipy.stats import f as f_dist

    return float(f_dist.sf(F, 1, d2))


#: a prior's precision is capped at this multiple of the information one unit-norm column of rows carries
PRIOR_CAP = 1e6


def prior_precision(cov: np.ndarray, scale: np.ndarray, noise: float) -> np.ndarray:
    """The precision `noise` C^-1 of corrections whose prior covariance is `cov`, for columns
    divided by `scale`, in the units of a residual sum of squares (so that RSS + d' P d is the
    negative log posterior times 2 `noise`); eigenvalues capped at `PRIOR_CAP`."""
    C = scale[:, None] * np.asarray(cov, float) * scale[None, :]
    lam, V = np.linalg.eigh(0.5 * (C + C.T))
    inv = np.minimum(noise / np.maximum(lam, 1e-300), PRIOR_CAP)
    return (V * inv[None, :]) @ V.T


def select_terms(X_base: np.ndarray, X_cand: np.ndarray, y: np.ndarray,
                 rule: SelectionRule = SelectionRule(), prior: np.ndarray | None = None) -> Selection:
    """Run the selection rule (module docstring) for one DOF.

    **Arguments:** `X_base` (n, p0) re-calibration columns, `X_cand` (n, q) candidates, `y` (n,)
    the given model's residual (rows concatenated over recordings, in time order). `prior`:
    optional (p0, p0) covariance of the re-calibration corrections (a column with no prior:
    infinite variance on the diagonal); the corrections then minimise
    RSS + s^2 tau d' prior^-1 d, s^2 the residual variance and tau the integrated
    autocorrelation time of the re-calibrated fit (n / tau independent rows), and every fit,
    test and bootstrap replicate below carries that penalty."""
    p0, q = X_base.shape[1], X_cand.shape[1]
    Z = np.concatenate([X_base, X_cand], 1)
    scale = np.linalg.norm(Z, axis=0)
    scale[scale == 0] = 1.0
    Z = Z / scale
    n = Z.shape[0]
    Gf, bf, yyf = _grams(Z, y, rule.n_folds)
    G, b, yy = Gf.sum(0), bf.sum(0), float(yyf.sum())
    P = p0 + q
    base = np.zeros(P, bool)
    base[:p0] = True
    Pr = np.zeros((P, P))

    def resid_of(mask):
        c = np.asarray(coefficients(G, b, jnp.asarray(mask)))
        return y - Z @ c

    if prior is not None and p0:
        r0 = resid_of(base)
        noise = float(r0 @ r0) / max(n - p0, 1) * integrated_time(r0)
        free = ~np.isfinite(np.diag(prior))
        cov = np.where(free[:, None] | free[None, :], 0.0, prior)
        Pr[:p0, :p0] = prior_precision(cov, scale[:p0], noise)
        Pr[np.where(free)[0], :] = Pr[:, np.where(free)[0]] = 0.0
        G = G + jnp.asarray(Pr)
    Pj = jnp.asarray(Pr)

    alpha_b = rule.alpha / max(q, 1)
    S = base.copy()
    steps = []
    cv_S = float(cv_sse(Gf, bf, yyf, jnp.asarray(S), Pj))
    rss_S = float(rss(G, b, yy, jnp.asarray(S)))
    tau = integrated_time(resid_of(S))
    for _ in range(min(rule.max_new, q)):
        cand = [j for j in range(p0, P) if not S[j]]
        if not cand:
            break
        masks = np.repeat(S[None], len(cand), 0)
        masks[np.arange(len(cand)), cand] = True
        cvs = np.asarray(_cv_many(Gf, bf, yyf, jnp.asarray(masks), Pj))
        k = int(np.argmin(cvs))
        j = cand[k]
        rss_j = float(rss(G, b, yy, jnp.asarray(masks[k])))
        tau_j = integrated_time(resid_of(masks[k]))
        pval = _f_pvalue(rss_S, rss_j, n / tau_j, masks[k].sum())
        gain = 1.0 - cvs[k] / cv_S if cv_S > 0 else 0.0  # an exact fit (noise-free data): nothing left to gain
        ok = gain >= rule.min_cv_gain and pval < alpha_b
        steps.append({"candidate": j - p0, "cv_gain": float(gain), "p_value": pval,
                      "tau": tau_j, "accepted": bool(ok)})
        if not ok:
            break
        S = masks[k]
        cv_S, rss_S, tau = float(cvs[k]), rss_j, tau_j

    # bootstrap: moving blocks of rows, Gram sums by cumulative sums
    block = rule.block or int(min(max(20, math.ceil(10 * tau)), max(n // 10, 2)))
    rng = np.random.default_rng(rule.seed)
    nb = math.ceil(n / block)
    starts = rng.integers(0, n - block + 1, size=(rule.n_boot, nb))
    gg = np.concatenate([np.zeros((1, P, P)), np.cumsum(Z[:, :, None] * Z[:, None, :], 0)])
    gy = np.concatenate([np.zeros((1, P)), np.cumsum(Z * y[:, None], 0)])
    y2 = np.concatenate([[0.0], np.cumsum(y * y)])
    GB = jnp.asarray((gg[starts + block] - gg[starts]).sum(1) + Pr[None])
    bB = jnp.asarray((gy[starts + block] - gy[starts]).sum(1))
    yyB = jnp.asarray((y2[starts + block] - y2[starts]).sum(1))
    del gg, gy
    from scipy.stats import f as f_dist

    n_eff = n / tau
    SB = np.repeat(base[None], rule.n_boot, 0)
    rssB = np.asarray(jax.vmap(rss, in_axes=(0, 0, 0, 0))(GB, bB, yyB, jnp.asarray(SB)))
    active = np.ones(rule.n_boot, bool)
    for _ in range(min(rule.max_new + 1, q)):
        cand_masks = np.repeat(SB[:, None, :], q, 1)
        cand_masks[:, np.arange(q), p0 + np.arange(q)] = True
        r_all = np.array(_rss_boot(GB, bB, yyB, jnp.asarray(cand_masks)))
        r_all[SB[:, p0:]] = np.inf
        k = np.argmin(r_all, 1)
        r1 = r_all[np.arange(rule.n_boot), k]
        p1 = SB.sum(1) + 1
        d2 = np.maximum(n_eff - p1, 1.0)
        F = np.maximum(rssB - r1, 0) / np.maximum(r1 / d2, 1e-300)
        acc = active & np.isfinite(r1) & (f_dist.sf(F, 1, d2) < alpha_b)
        if not acc.any():
            break
        SB[np.where(acc)[0], p0 + k[acc]] = True
        rssB = np.where(acc, r1, rssB)
        active = acc
    freq = SB[:, p0:].mean(0)

    rejected = []
    for j in np.where(S[p0:])[0]:
        if freq[j] < rule.stability:
            S[p0 + j] = False
            rejected.append((int(j), f"selected in {100 * freq[j]:.0f} % of bootstrap replicates "
                                     f"(< {100 * rule.stability:.0f} %)"))
    for st in steps:
        if not st["accepted"]:
            rejected.append((st["candidate"], f"best next candidate but failed the rule (cv gain "
                                              f"{100 * st['cv_gain']:.2f} %, p = {st['p_value']:.2g}, "
                                              f"Bonferroni bound {alpha_b:.2g})"))
    order = [st["candidate"] for st in steps if st["accepted"] and S[p0 + st["candidate"]]]

    def drop_one(mask, j):
        m = mask.copy()
        m[p0 + j] = False
        return (float(rss(G, b, yy, jnp.asarray(m))) - float(rss(G, b, yy, jnp.asarray(mask)))) / yy

    while order:
        ex = [drop_one(S, j) for j in order]
        k = int(np.argmin(ex))
        if ex[k] >= rule.min_explained:
            break
        j = order.pop(k)
        S[p0 + j] = False
        rejected.append((j, f"explains only {100 * ex[k]:.2f} % of the model's residual "
                            f"(< {100 * rule.min_explained:.0f} %)"))
    Sj = jnp.asarray(S)
    c = np.asarray(coefficients(G, b, Sj)) / scale
    cB = np.asarray(_coef_boot(GB, bB, Sj)) / scale
    ci = np.percentile(cB, [2.5, 97.5], axis=0).T
    rss_final = float(rss(G, b, yy, Sj))
    explained = [drop_one(S, j) for j in order]
    rss_base = float(rss(G, b, yy, jnp.asarray(base)))
    return Selection(
        kept=order, rejected=rejected,
        coef_base=c[:p0], coef_kept=c[[p0 + j for j in order]],
        ci_base=ci[:p0], ci_kept=ci[[p0 + j for j in order]],
        stability=freq, explained=np.array(explained),
        explained_base=(yy - rss_base) / yy, explained_total=(yy - rss_final) / yy,
        steps=steps, tau=tau, n_rows=n, resid=resid_of(S),
    )

