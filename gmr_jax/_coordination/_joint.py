"""Joint coordination: one penalised regression on every well's raw data with shared global
coefficients, the model chosen among admissible candidates (issue 15; beyond the paper).

The paper's route (Eqs. 12-21) first fits each well alone, then solves for the global
polynomial that reproduces the local Taylor coefficients. Where a local fit keeps a term its
data do not resolve (a near-sinusoidal record has few harmonics, so q^3, q^5 and v^3 are nearly
collinear with q and v), the exact interpolant takes it as exact and the global law goes wild.
Here the global law is fitted to all wells' samples at once:

    y = F(x) + C(x) v + sum_{j in S} B_j sgn(v)|v|^j,

F and C in Chebyshev polynomials of u = (x - c) / (2h) (c, h: centre and half-span of the
equilibria, so the equilibria sit at u = -1/2 .. 1/2 and u in [-1, 1] is the span the model is
used on: the equilibria widened by half their span on each side), with the penalties
lambda_r int (d^m F / du^m)^2 du and lambda_d int (C'')^2 du over u in [-1, 1]. Between the
wells, where no sample lies, the penalty (a smoothness prior, m = 3 by default: the least
F''' compatible with what the wells measured) decides the shape; inside each well the data do.

Every candidate (odd degree K, degree J of C, the set S of velocity terms, lambda_r, lambda_d)
is solved from one Gram matrix (fixed shapes, vmapped) and scored by BIC with the effective
degrees of freedom tr(A^-1 G). Among the *admissible* ones, the lowest score wins:

- F confines: K odd and a positive leading coefficient (F -> +inf as x -> +inf, -inf as
  x -> -inf);
- F has exactly 2n - 1 sign changes for n recorded wells on u in [-3, 3] (its wells, the
  saddles between them, and nothing else: no well the data did not put there);
- the damping dissipates, D(x, v) v >= 0, over u in [-1, 1] and |v| up to `speed`, a
  generous bound on the speeds the model will see (not only the training speeds).

The posterior covariance sigma^2 A^-1 (the penalty read as a Gaussian prior) gives the
uncertainty of the global coefficients, wide where the data are silent.

Prior-data conflict: admissibility is a prior on the law's shape, mostly where no datum lies.
When the best admissible candidate scores worse than the best of all by more than `CONFLICT`,
the data reject every admissible law, and the chosen one's posterior (which takes its form as
known) is far too narrow: magnet at 0.05, 40 dB, seed 1 (a record that hops between the wells,
its mean taken as a third "equilibrium"), the admissible degree 11 at lambda 10^-4 was 19 % off
on the span with a 0.5 % band, while the data preferred (by 6300) a law 0.8 % off there that
turns outward beyond them. Then the penalties are searched on a grid refined to half decades
(the best admissible law sits at the edge of admissibility), and the data-preferred law's
difference to the chosen one is returned (`joint_unconstrained`) for `reconstruct` to add to the
covariance and to warn about.

Noise on a measured v (`v_noise`, per well its variance): a velocity column g(v) = sgn(v)|v|^o
of a noisy v holds s^2/2 g''(v) on average and its noise g'(v) e in the normal matrix, so v^3
leaks into v and is attenuated. The columns are corrected to their noise-free mean and the
normal matrix for the noise it holds, to O(s^4) (`_velocity_noise`, `_velocity_gram`; through the
rows' low-pass where it applies). Bistable joint (10 v^3), 5 degrees, 30 dB, 4 seeds: v^3 was
9.28-9.49 (7-10 standard errors low, v|v| beside it), now 9.90-10.04, v^3 alone on
2 of 4 (`studies/velocity_noise.py`). Not for friction (sgn(v): no smooth expansion at 0), and not
where v is estimated or x integrated from it. The residual then holds g'(v) e times the coefficients,
largest where |v| is, so the covariance is the corrected score's sandwich where that is wider than
sigma^2 A^-1 (`_sandwich`; v^3's standard error 0.0132 -> 0.0207, its errors then within 1.7).
`reconstruct(velocity_eiv=False)` turns it off.
"""

import dataclasses
import itertools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._fit._errors_in_variables import hermite_excess
from .._fit._householder import inverse_logdet
from ._hermite import monomial_map

#: Damping power D v below -this x its largest value on the check grid counts as feeding energy in
#: (a damping law that is zero at a point, like the joint's 50 x^2 v, fits slightly negative there).
DISSIPATION_TOLERANCE = 1e-3
#: The dissipation check in the damping-only regression (the restoring force fixed by the paper route), at each speed of the check
#: grid against the largest |D v| at that speed, the speeds geometric from `DISSIPATION_SLOWEST` x the bound up to
#: it: a law whose top power of v dominates at the bound cannot hide a negative viscous term below it, where every
#: motion turns and a free decay ends (bistable joint, 10 v^3, 5 degree sweeps, 30 dB, seed 4: -3.76 v + 2.72 v|v|
#: + 9.56 v^3 fed energy in below |v| = 0.5, within 1e-3 of the largest |D v| of the grid, at the bound). Not in
#: the full joint regression: there, on single-tone records whose powers of v are collinear, the laws it then
#: rejects sent the choice to a restoring degree the data do not fix (10 Hz sines, 45 dB, seed 2: degree 11,
#: 58.7 % off, for the degree-3 law 0.027 % off beside -2.2 v + 3.3 v|v| + 8.9 v^3)
DISSIPATION_SLOWEST = 1e-4
DISSIPATION_SPEEDS = 40


def dissipation_speeds(speed: float, geometric: bool = False) -> np.ndarray:
    """The `DISSIPATION_SPEEDS` speeds at which a damping law's dissipation is checked: evenly spaced in
    (0, `speed`], or `geometric` from `DISSIPATION_SLOWEST` x `speed`."""
    if geometric:
        return np.geomspace(DISSIPATION_SLOWEST * speed, speed, DISSIPATION_SPEEDS)
    return np.linspace(0.0, speed, DISSIPATION_SPEEDS + 1)[1:]
#: Half-width, in u, of the grid on which F's sign changes are counted (5 half-spans past the
#: outer equilibria).
SIGN_GRID_HALF_WIDTH = 3.0
#: Prior-data conflict: the best admissible candidate's score (-2 log evidence) exceeds the best of all
#: candidates by more than this ("very strong" evidence on Kass and Raftery's scale): the data reject every
#: law the admissibility rules allow. Magnet, 40 dB, seed 1 (a record that hops between the wells): 6300.
CONFLICT = 10.0
#: The series' truncation at the degree cap (`_truncation`): the convergence ratio of its last two changes is taken
#: at most this (a tail of at most 4 x the last change)
TRUNCATION_RATIO_MAX = 0.8


class JointSettings(eqx.Module):
    """Candidate models of the joint coordination.

    - `max_degree`: highest (odd) degree K of F; the lowest is 2n - 1 for n wells.
    - `max_damping_degree`: highest degree J of the position-dependent damping C(x).
    - `velocity_orders`: the candidate position-independent terms sgn(v)|v|^j beyond the
      viscous one (0: Coulomb, 2: v|v|, 3: v^3); every subset is a candidate.
    - `penalty_order`: m of the smoothness penalty on F.
    - `log_lambdas`, `log_lambdas_damping`: log10 of the penalty weights, relative to
      trace(G) / trace(penalty) of each block.
    - `damping_only`: fit the damping alone (y already has the restoring force removed).
    - `tie`: admissible candidates whose score is within `tie` of the best are taken as equally
      supported by the data, and among those with as many velocity terms as the best the one that
      extrapolates most tamely wins: the lowest highest velocity power (v|v| before v^3: single-tone
      records at |v| <= 0.2 cannot tell them apart, and v^3 damps 5 x too hard at 3), then the lowest
      degrees K and J. 0: the best score.
    - `truncation`: at `max_degree`, the band holds the series' estimated tail (`_truncation`);
      False where the cap is a choice, not the data's limit (`reconstruct`'s replacement of a paper route).
    """

    max_degree: int = eqx.field(static=True, default=13)
    max_damping_degree: int = eqx.field(static=True, default=3)
    velocity_orders: tuple = eqx.field(static=True, default=(0, 2, 3))
    penalty_order: int = eqx.field(static=True, default=3)
    log_lambdas: tuple = eqx.field(static=True, default=(-12.0, -10.0, -8.0, -6.0, -4.0, -2.0, 0.0))
    log_lambdas_damping: tuple = eqx.field(static=True, default=(-8.0, -4.0, 0.0))
    damping_only: bool = eqx.field(static=True, default=False)
    tie: float = eqx.field(static=True, default=0.0)
    truncation: bool = eqx.field(static=True, default=True)


def chebyshev(u, degree: int):
    """T_0(u) .. T_degree(u), stacked on the last axis."""
    out = [jnp.ones_like(u), u]
    for _ in range(2, degree + 1):
        out.append(2.0 * u * out[-1] - out[-2])
    return jnp.stack(out[: degree + 1], axis=-1)


def _penalty(degree: int, order: int) -> np.ndarray:
    """int_{-1}^{1} T_k^(order)(u) T_l^(order)(u) du, by Gauss-Legendre quadrature."""
    u, w = np.polynomial.legendre.leggauss(degree + 8)
    vals = np.stack([np.polynomial.chebyshev.chebval(u, np.polynomial.chebyshev.chebder(np.eye(degree + 1)[k], order))
                     if k >= order else np.zeros_like(u) for k in range(degree + 1)], axis=1)
    return vals.T @ (w[:, None] * vals)


def cheb_to_monomial(degree: int) -> np.ndarray:
    """M with sum_k a_k T_k(u) = sum_m (M a)_m u^m."""
    cols = [np.polynomial.chebyshev.cheb2poly(np.eye(degree + 1)[k]) for k in range(degree + 1)]
    return np.stack([np.pad(a, (0, degree + 1 - a.size)) for a in cols], axis=1)


class _Layout(eqx.Module):
    """Column layout of the design: F's K+1 Chebyshev columns, C's J+1 (times v), then the
    velocity terms."""

    k: int = eqx.field(static=True)
    j: int = eqx.field(static=True)
    vel: tuple = eqx.field(static=True)

    @property
    def p(self):
        return self.k + 1 + self.j + 1 + len(self.vel)

    @property
    def restoring(self):
        return slice(0, self.k + 1)

    @property
    def damping(self):
        return slice(self.k + 1, self.k + self.j + 2)

    def columns(self, u, v):
        vel = [jnp.sign(v) * jnp.abs(v) ** j for j in self.vel]
        return jnp.concatenate([chebyshev(u, self.k), v[..., None] * chebyshev(u, self.j),
                                jnp.stack(vel, axis=-1).reshape(v.shape + (len(self.vel),))], axis=-1)


def _corrected(gram, rhs, u, vs, ys, w, s2u, layout: _Layout, scale):
    """The joint normal equations (scaled columns) corrected for white noise of variance `s2u`
    (per well, in u) on u: every column is a polynomial in u (Chebyshev) times a factor of v, so
    the products in G and b are polynomials in u, and each power u^n is replaced by its Hermite
    polynomial He_n(u; s²) (`_fit/_errors_in_variables.py`). The recorded equations where the
    corrected G is not positive semi-definite or not finite."""
    k, j = layout.k, layout.j
    n_max = 2 * max(k, j)
    poly = np.zeros((layout.p, n_max + 1))
    poly[: k + 1, : k + 1] = cheb_to_monomial(k).T
    poly[k + 1 : k + j + 2, : j + 1] = cheb_to_monomial(j).T
    poly[k + j + 2 :, 0] = 1.0
    fac = np.concatenate([np.ones(u.shape + (k + 1,)), np.repeat(vs[..., None], j + 1, axis=-1),
                          np.stack([np.sign(vs) * np.abs(vs) ** o for o in layout.vel], axis=-1)
                          .reshape(vs.shape + (len(layout.vel),))], axis=-1) / scale
    s2 = jnp.asarray(np.asarray(s2u, float).reshape(-1, 1))  # per well (rows)
    dq = np.asarray(hermite_excess(jnp.asarray(u), s2, n_max))  # u^n - He_n(u; s²): (wells, samples, n)
    conv = np.zeros((layout.p, layout.p, 2 * n_max + 1))
    for a in range(n_max + 1):
        for b in range(n_max + 1):
            conv[:, :, a + b] += np.outer(poly[:, a], poly[:, b])
    conv = conv[:, :, : n_max + 1]  # a product of two columns has degree <= n_max
    moments = np.einsum("wt,wtn,wta,wtb->nab", w, dq, fac, fac, optimize=True)
    delta = np.einsum("abn,nab->ab", conv, moments)
    small = np.einsum("an,wtn,wta,wt->a", poly, dq, fac, w * ys, optimize=True)
    g2, b2 = gram - delta, rhs - small
    g2 = 0.5 * (g2 + g2.T)
    if not (np.all(np.isfinite(g2)) and np.all(np.isfinite(b2))):
        return gram, rhs
    eig = np.linalg.eigvalsh(g2)  # a column that is zero on these data stays a null direction of both
    return (g2, b2) if eig.min() >= -1e-10 * eig.max() else (gram, rhs)


def _velocity_noise(cols, u, vs, s2v, layout: _Layout):
    """The columns corrected for white noise of variance `s2v` (per well) on the measured v, to
    O(s^4): a velocity term g(v) = sgn(v)|v|^o has E[g(v + e)] = g(v) + s^2/2 g''(v) + O(s^4), so
    sgn(v)|v|^o - s^2/2 o (o - 1) sgn(v)|v|^(o-2) has the noise-free column's mean (v^3 leaks 3 s^2 v
    into the linear term otherwise); C(x) v is linear in v and unbiased. Returns the columns and
    `(idx, d)`: the v-dependent columns and their derivatives in v (wells, samples, m), whose
    products carry the noise into the normal equations (`_velocity_gram`)."""
    k, j = layout.k, layout.j
    off = k + j + 2
    cols = np.array(cols, float)
    idx = np.array(list(range(k + 1, k + j + 2)) + [off + i for i in range(len(layout.vel))])
    d = np.zeros(vs.shape + (idx.size,))
    d[..., : j + 1] = np.asarray(chebyshev(jnp.asarray(u), j))  # d/dv of v T_j(u)
    s2 = np.asarray(s2v, float).reshape(-1, 1)
    for i, o in enumerate(layout.vel):
        if o >= 1:
            d[..., j + 1 + i] = o * np.abs(vs) ** (o - 1)
        if o >= 2:
            cols[..., off + i] -= 0.5 * s2 * o * (o - 1) * np.sign(vs) * np.abs(vs) ** (o - 2)
    return cols, (idx, d)


def _velocity_gram(gram, vd, s2v, w, rows, scale):
    """The joint normal matrix (scaled columns) less the noise of v it holds: a column's noise is
    g'(v) e to first order, so the sum over rows of w g_a' g_b' s^2 (through the rows' low-pass:
    s^2 times the taps' squares convolved with g_a' g_b', decimated as the rows). The recorded
    matrix where the corrected one is not positive semi-definite or not finite."""
    idx, d = vd
    prod = d[..., :, None] * d[..., None, :] * np.asarray(s2v, float).reshape(-1, 1, 1, 1)
    if rows is not None:
        from scipy.signal import fftconvolve

        h2 = np.asarray(rows.taps, float) ** 2
        prod = fftconvolve(prod, h2[None, :, None, None], mode="same", axes=1)[:, :: int(rows.stride)]
    prod = prod / np.outer(scale[idx], scale[idx])
    noise = np.einsum("wt,wtab->ab", w, prod)
    g2 = np.array(gram, float)
    g2[np.ix_(idx, idx)] -= noise
    g2 = 0.5 * (g2 + g2.T)
    if not np.all(np.isfinite(g2)):
        return gram, None
    eig = np.linalg.eigvalsh(g2)
    return (g2, (idx, prod)) if eig.min() >= -1e-10 * eig.max() else (gram, None)


def _sandwich(cols, ys, w, theta, ainv, mask, gram, noise, sigma2):
    """The covariance of the coefficients corrected for the noise of v (`_velocity_noise`): their
    residual is heteroscedastic (a column's noise g'(v) e times its coefficient grows with |v|,
    where v^3 has its leverage), so sigma^2 A^-1 is too narrow there. The corrected score of row
    i, psi_i = w_i (h_i r_i + N_i theta) (h the corrected columns, r the residual, N_i the noise
    its products hold), gives A^-1 (sum psi psi') A^-1 for the data's part (small-sample factor
    n / (n - p)); the prior's part, sigma^2 A^-1 P A^-1, as in sigma^2 A^-1 = sigma^2 A^-1 (G + P) A^-1."""
    idx, prod = noise
    m = mask.astype(float)
    th = theta * m
    r = ys - cols @ th
    psi = w[..., None] * cols * r[..., None]
    psi[..., idx] += w[..., None] * np.einsum("wtab,b->wta", prod, th[idx])
    psi = psi[w > 0] * m
    k = int(m.sum())
    meat = psi.T @ psi * psi.shape[0] / max(psi.shape[0] - k, 1)
    a = np.linalg.pinv(ainv * np.outer(m, m)) * np.outer(m, m)
    pen = a - gram * np.outer(m, m)
    ai = ainv * np.outer(m, m)
    return ai @ (meat + sigma2 * pen) @ ai


def _covariance(i, theta, ainv, rss, edf, n, masks, cols, ys, w, gram, v_rows):
    """sigma^2 and the covariance of candidate `i`'s (scaled) coefficients: sigma^2 A^-1, widened where the
    velocity correction's sandwich (`_sandwich`, given its `v_rows`) is wider, never narrowed (as the Birge ratio,
    `_discrepancy`): where the residual is smaller than its mean (the restoring columns' leverage at large |x|) the
    sandwich is the narrower, and took the magnet's restoring band at 30 dB from 90 to 88.5 % of the span."""
    sigma2 = float(rss[i]) / max(n - float(edf[i]), 1.0)  # the recorded samples' residual
    cov = sigma2 * ainv[i] * masks[i][:, None] * masks[i][None, :]
    if v_rows is not None:
        excess = _sandwich(cols, ys, w, theta[i], ainv[i], masks[i], gram, v_rows, sigma2) - cov
        ev, vec = np.linalg.eigh(0.5 * (excess + excess.T))
        cov = cov + (vec * np.clip(ev, 0.0, None)) @ vec.T
    return sigma2, cov


def _robust_velocity_set(best, meta, lam_r, lam_d, admissible, theta, masks, n, cov) -> int:
    """The chosen candidate, or the admissible one with a subset of its velocity terms (same degrees and penalties)
    where the dropped terms D do not earn their BIC charge on their robust covariance S:
    theta_D' S_DD^-1 theta_D < |D| log n (BIC's test of nested models as a Wald statistic). The score's own
    difference cannot be rescaled to it: its residual is the recorded samples', which holds the noise of v through
    the columns' slopes, theta' N theta, so a law whose slopes amplify less of that noise scores better whether or not
    the data hold its terms (seed 4 above: the v^3-alone law 40 worse in the score for a v|v| whose Wald statistic on
    sigma^2 A^-1 is 6.7 and on S 3.9). The candidate with the lowest W - |D| log n, where it is negative."""
    k, j, vel = meta[best]
    if not vel:
        return best
    vel_cols = np.nonzero(masks[best])[0][-len(vel):]  # the velocity terms are the last columns
    pick, low = best, 0.0
    for i, (ki, ji, vi) in enumerate(meta):
        if (i == best or ki != k or ji != j or lam_r[i] != lam_r[best] or lam_d[i] != lam_d[best]
                or not admissible[i] or not set(vi) < set(vel)):
            continue
        d = np.array([c for c, o in zip(vel_cols, vel) if o not in vi])
        th = theta[best][d]
        score = float(th @ np.linalg.solve(cov[np.ix_(d, d)], th)) - d.size * np.log(n)
        if score < low:
            pick, low = i, score
    return pick


def _candidates(n_wells: int, layout: _Layout, settings: JointSettings):
    """Column masks and penalty indices of every candidate (static NumPy arrays)."""
    k_min = max(2 * n_wells - 1, 1)
    degrees = [k for k in range(k_min, layout.k + 1) if k % 2 == 1] if not settings.damping_only else [-1]
    subsets = [s for r in range(len(layout.vel) + 1) for s in itertools.combinations(range(len(layout.vel)), r)]
    masks, lam_r, lam_d, meta = [], [], [], []
    for k, j, s, a, b in itertools.product(degrees, range(layout.j + 1), subsets,
                                           range(len(settings.log_lambdas)), range(len(settings.log_lambdas_damping))):
        m = np.zeros(layout.p, bool)
        m[: k + 1] = True
        m[layout.k + 1 : layout.k + 2 + j] = True
        for i in s:
            m[layout.k + layout.j + 2 + i] = True
        masks.append(m), lam_r.append(a), lam_d.append(b)
        meta.append((k, j, tuple(layout.vel[i] for i in s)))
    return np.array(masks), np.array(lam_r), np.array(lam_d), meta


def _pseudo_logdet(omega: np.ndarray, size: int) -> tuple[int, float]:
    """Rank and log pseudo-determinant of the leading `size` block of a penalty matrix whose
    null space is spanned by its first columns (Chebyshev degrees below the derivative order)."""
    block = omega[:size, :size]
    if size == 0:
        return 0, 0.0
    ev = np.linalg.eigvalsh(0.5 * (block + block.T))
    pos = ev > 1e-10 * max(ev.max(), 1e-300)
    return int(pos.sum()), float(np.sum(np.log(ev[pos]))) if pos.any() else 0.0


def _penalty_terms(meta, omega_r, omega_d):
    """Per candidate: rank and log pseudo-determinant of each penalty block, and the number p0
    of unpenalised columns (the penalties' null spaces and the velocity terms)."""
    out = []
    for k, j, vel in meta:
        qr_, lr = _pseudo_logdet(omega_r, k + 1) if k >= 0 else (0, 0.0)
        qd, ld = _pseudo_logdet(omega_d, j + 1)
        out.append((qr_, lr, qd, ld, (max(k, -1) + 1 - qr_) + (j + 1 - qd) + len(vel)))
    return np.array(out).T


@eqx.filter_jit
def _select(gram, rhs, yy, n, omega_r, omega_d, masks, lam_r, lam_d, log_r, log_d, checks, pen, layout: _Layout,
            recorded=None):
    """Solve, score and check every candidate; returns the per-candidate arrays.

    Score: -2 log marginal likelihood of the penalised regression read as a Gaussian prior
    (flat on the penalties' null spaces, noise variance profiled out), plus p0 log n for the
    p0 unpenalised columns (BIC's charge for the terms no prior constrains):
    (n - p0) log s2 + log|G + P| - log|P|_+ + p0 log n, s2 = (y'y - 2 b'theta + theta'(G + P) theta)
    / (n - p0) (= (y'y - b'theta) / (n - p0) at the solution). `recorded`: the normal equations
    (G, b) of the recorded samples where `gram`, `rhs` were corrected for the noise on x: theta
    solves the corrected ones, s2 and the residual are the recorded samples' (a corrected residual
    leaves out the noise of x it still holds, and sharpens every comparison by as much)."""
    g0, b0 = (gram, rhs) if recorded is None else recorded
    p = gram.shape[0]
    rr, dd = layout.restoring, layout.damping
    scale_r = jnp.trace(gram[rr, rr]) / jnp.trace(omega_r)
    tr_d = jnp.trace(omega_d)
    scale_d = jnp.where(tr_d > 0, jnp.trace(gram[dd, dd]) / jnp.where(tr_d > 0, tr_d, 1.0), 0.0)
    big_r = jnp.zeros((p, p)).at[rr, rr].set(omega_r)
    big_d = jnp.zeros((p, p)).at[dd, dd].set(omega_d)
    ridge = 1e-12 * jnp.diag(jnp.diag(gram))
    grid_f, grid_d, per_speed = checks

    def one(mask, ir, id_, q_r, ld_r, q_d, ld_d, p0):
        mk = mask.astype(gram.dtype)
        both = mk[:, None] * mk[None, :]
        g = gram * both
        lr, ld = 10.0 ** log_r[ir] * scale_r, 10.0 ** log_d[id_] * scale_d
        a = g + (lr * big_r + ld * big_d + ridge) * both
        a = a + jnp.diag(1.0 - mk)
        ainv, logdet = inverse_logdet(a)
        b = rhs * mk
        theta = ainv @ b
        g_rec, b_rec = g0 * both, b0 * mk
        rss = jnp.maximum(yy - 2.0 * theta @ b_rec + theta @ g_rec @ theta, 1e-300 * yy)
        edf = jnp.trace(ainv @ g)
        penalised = theta @ (a - g - jnp.diag(1.0 - mk)) @ theta  # theta' P theta (ridge included)
        s2 = jnp.maximum(rss + penalised, 1e-300 * yy) / (n - p0)
        logdet_p = q_r * jnp.log(lr) + ld_r + jnp.where(q_d > 0, q_d * jnp.log(jnp.maximum(ld, 1e-300)) + ld_d, 0.0)
        bic = (n - p0) * jnp.log(s2) + logdet - logdet_p + p0 * jnp.log(n)
        # admissibility
        f = grid_f @ theta[rr]
        pos = f >= 0
        sign_changes = jnp.sum(pos[1:] != pos[:-1])
        lead = jnp.max(jnp.where(mask[rr], jnp.arange(layout.k + 1), 0))
        confines = (theta[rr][lead] > 0) & (lead % 2 == 1)
        dissipation = grid_d @ theta[rr.stop:]
        if per_speed:  # each speed against its own largest |D v| (`DISSIPATION_SLOWEST`)
            grid = dissipation.reshape(-1, DISSIPATION_SPEEDS)  # (u, speed)
            largest = jnp.max(jnp.abs(grid), axis=0, keepdims=True)
            dissipative = jnp.all(grid >= -DISSIPATION_TOLERANCE * largest)
        else:
            dissipative = jnp.all(dissipation >= -DISSIPATION_TOLERANCE * jnp.max(jnp.abs(dissipation)))
        if 0 in layout.vel:  # a negative friction feeds energy in below the grid's lowest speed (`damping_faults`)
            dissipative = dissipative & (theta[layout.k + layout.j + 2 + layout.vel.index(0)] >= 0)
        return theta, ainv, rss, edf, bic, sign_changes, confines, dissipative

    return jax.vmap(one)(jnp.asarray(masks), jnp.asarray(lam_r), jnp.asarray(lam_d), *(jnp.asarray(a) for a in pen))


@dataclasses.dataclass(frozen=True)
class RowFilter:
    """A zero-phase low-pass FIR `taps` (odd length, unit DC gain) and the decimation `stride`
    applied to the joint regression's rows (`filtered_rows`)."""

    taps: np.ndarray
    stride: int


#: the rows' cut-off, times the highest 99.5 % band edge of the wells' x (`row_filter`)
ROW_CUTOFF = 1.5


def row_filter(dt: float, band_edge: float) -> RowFilter:
    """The low-pass for a regression whose target holds estimated accelerations.

    The equation of motion holds at every instant, so it holds for any linear filter applied to
    both sides: the filtered target equals the filtered library columns times the same global
    coefficients. A differentiated x or v carries noise that grows with frequency (and the
    Savitzky-Golay bias at the top of a sweep, where the absolute acceleration is a small
    difference of x'' and the base's); above the response's band it is all noise, and the raw rows'
    residual is neither white nor of the response's band, so a BIC on them picks too low a degree
    (shallow arch, x only, 45-60 dB: the cubic, 14.5 % restoring error). The rows are filtered
    by a Hamming-windowed sinc cut at `ROW_CUTOFF` x `band_edge` (Hz; half-length 2 periods of the
    cut-off) and kept every 1 / (2.5 f_c dt) samples (the filtered rows' Nyquist rate, so that
    they are about independent and the BIC counts them right): arch, x only, 30-80 dB and noise
    free, 1.4-3.3 % (the curvature oracle 2.6 %). `dt` in s."""
    fc = ROW_CUTOFF * float(band_edge)
    half = max(int(round(2.0 / (fc * dt))), 1)
    k = np.arange(-half, half + 1)
    taps = 2.0 * fc * dt * np.sinc(2.0 * fc * dt * k) * np.hamming(k.size)
    return RowFilter(taps / taps.sum(), max(1, int(1.0 / (2.5 * fc * dt))))


def filtered_rows(rows: RowFilter, cols, ys, w, weights):
    """(wells, samples, p) columns, (wells, samples) target and weights filtered along the samples
    by `rows.taps` and decimated by `rows.stride`; a row whose filter window reaches a padded or
    weightless sample (the record's ends) gets weight 0."""
    from scipy.signal import fftconvolve

    taps = np.asarray(rows.taps, float)
    cols = fftconvolve(cols, taps[None, :, None], mode="same", axes=1)
    ys = fftconvolve(ys, taps[None, :], mode="same", axes=1)
    full = fftconvolve((weights > 0).astype(float), np.ones(taps.size)[None, :], mode="same", axes=1)
    full = full > taps.size - 0.5
    w, weights = np.where(full, w, 0.0), np.where(full, weights, 0.0)
    s = int(rows.stride)
    return cols[:, ::s], ys[:, ::s], w[:, ::s], weights[:, ::s]


def joint_coordinate(
    xs: Float[Array, "wells samples"],
    vs: Float[Array, "wells samples"],
    ys: Float[Array, "wells samples"],
    weights: Float[Array, "wells samples"],
    equilibria: Float[Array, " wells"],
    well_variance: Float[Array, " wells"],
    speed: float,
    settings: JointSettings = JointSettings(),
    refine: bool = True,
    x_noise: Float[Array, " wells"] | None = None,
    rows: "RowFilter | None" = None,
    band=None,
    gain=None,
    v_noise: Float[Array, " wells"] | None = None,
):
    """The joint coordination of one DOF (module docstring).

    **Arguments:** per well (padded to one length, `weights` 0 on padding) the samples x, v and
    the force the DOF carries y (left side of Eq. 8); the equilibria; each well's residual
    variance (the local fit's, to weight wells of different noise alike); `speed`, the largest
    |v| over which the damping must dissipate.

    **Returns:** `(stiffness, velocity_damping, position_damping, covariance, stats)`:
    monomial coefficients in x (F: K_max + 1; B_j of sgn(v)|v|^j up to the largest
    velocity order, B_1 the viscous term C(0); C_j of x^j v, C_0 = 0), the covariance of their
    concatenation, and `stats` (the chosen degree, damping set, penalty weights, BIC, the
    number of admissible candidates, whether the chosen one is admissible, sigma^2; and
    `joint_alternative`: the best admissible candidate of another degree minus the chosen one,
    times the square root of its model-averaging weight 1 / (1 + exp(delta BIC / 2)), in the same
    flat layout, zeros when there is none: the degree choice's discrepancy that `reconstruct`
    adds to the covariance; `joint_conflict`: the best admissible score minus the best of all,
    and `joint_unconstrained`: the best candidate of all minus the chosen one, zeros unless the
    conflict exceeds `CONFLICT`; `joint_damping_alternative_orders`, `_delta`, `_velocity`, `_position`: the best
    admissible candidate of the chosen degree with another set of velocity terms, its score less the chosen one's
    and its damping coefficients less the chosen ones, None / inf / zeros when there is none: read by
    `reconstruct`'s damping check; `joint_truncation_ratio`, `_tail`: where the chosen degree is the cap, the series'
    convergence ratio and the RMS of its estimated tail on the span, whose covariance the returned one holds
    (`_truncation`), 0 elsewhere; `joint_velocity_noise`: whether the columns were corrected for `v_noise`;
    `joint_velocity_orders_dropped`: the velocity terms the score chose and their robust covariance did not keep
    (`_robust_velocity_set`); `joint_velocity_noise_shift`: what the noise of v moves the chosen law by where it
    is not corrected for, in the flat layout, zeros without the correction). `refine`: on a conflict, search once more on the penalty grid
    refined to half decades (module docstring). `x_noise`: per well, the variance of white noise
    on the measured x; the normal equations are then corrected for it (errors in variables, the
    corrected score of `_fit/_errors_in_variables.py`, each power of u replaced by its Hermite
    polynomial), the noise variance sigma^2 still taken from the recorded samples' residual.
    `rows`: where the target holds differentiated signals, the regression is on the rows filtered
    by this low-pass and decimated (`RowFilter`, `row_filter`; no errors-in-variables correction).
    `band`: where x was integrated, per well its records' (start, stop, dt, drift cut-off)
    (`_reconstruct/_slow.segments`): each record's rows lose their content between 0 and its cut-off
    (the mean kept), where the integrated x misses its slow part (`_slow.band_rows`).
    `gain`: where the accelerations were estimated, per well its records' filter gains
    (`_reconstruct/_filter_gain.gain_segments`): every column passes through its record's gain G, as the
    target holds G[x''] (`ys` then holds the inputs through G too, `_filter_gain.matched_target`).
    """
    xs, vs, ys, weights = (np.asarray(a, float) for a in (xs, vs, ys, weights))
    raw = (xs, vs, ys, weights, x_noise, v_noise)
    eq = np.asarray(equilibria, float)
    n_wells = eq.shape[0]
    lo, hi = float(eq.min()), float(eq.max())
    c, h = 0.5 * (lo + hi), max(0.5 * (hi - lo), 1e-300)
    layout = _Layout(settings.max_degree, settings.max_damping_degree, tuple(settings.velocity_orders))
    w = weights / np.asarray(well_variance, float).reshape(-1, 1)
    u = (xs - c) / (2.0 * h)
    cols = np.asarray(layout.columns(jnp.asarray(u), jnp.asarray(vs)))  # (wells, samples, p)
    vd = None  # the noise of a measured v (not where the columns pass a filter gain or a band: v derived there)
    if v_noise is not None and gain is None and band is None:
        cols, vd = _velocity_noise(cols, u, vs, v_noise, layout)
    if gain is not None:
        from .._recordings._derivatives import apply_gain

        cols = np.stack([apply_gain(segs, cols[k]) for k, segs in enumerate(gain)])
        x_noise = None  # the corrected score is per raw column
    if band is not None:
        from .._recordings._integrate import apply_band

        cols = np.stack([apply_band(segs, cols[k]) for k, segs in enumerate(band)])
        ys = np.stack([apply_band(segs, ys[k]) for k, segs in enumerate(band)])
    if rows is not None:
        cols, ys, w, weights = filtered_rows(rows, cols, ys, w, weights)
        x_noise = None  # the corrected score is per raw sample
    scale = np.sqrt(np.einsum("wn,wnp->p", w, cols**2) / w.sum())
    scale = np.where(scale > 0, scale, 1.0)
    cols = cols / scale
    gram = np.einsum("wn,wnp,wnq->pq", w, cols, cols)
    rhs = np.einsum("wn,wnp,wn->p", w, cols, ys)
    yy = float(np.einsum("wn,wn,wn->", w, ys, ys))
    n = float(weights.sum())
    recorded = (gram, rhs)  # the recorded samples' normal equations (their residual gives sigma^2)
    if x_noise is not None and not settings.damping_only:
        gram, rhs = _corrected(gram, rhs, u, vs, ys, w, np.asarray(x_noise, float) / (2.0 * h) ** 2, layout, scale)
    v_rows, v_gram = None, None
    if vd is not None:
        before = gram
        gram, v_rows = _velocity_gram(gram, vd, v_noise, w, rows, scale)
        v_gram = before - gram if v_rows is not None else None  # the noise of v the normal matrix held
    sr, sd = scale[layout.restoring], scale[layout.damping]
    omega_r = _penalty(layout.k, settings.penalty_order) / np.outer(sr, sr)
    omega_d = _penalty(layout.j, min(2, layout.j)) / np.outer(sd, sd) if layout.j >= 2 else np.zeros((layout.j + 1,) * 2)
    masks, lam_r, lam_d, meta = _candidates(n_wells, layout, settings)
    # admissibility grids: F on u in [-3, 3]; D v on u in [-1, 1] x |v| in (0, speed] (`dissipation_speeds`)
    ug = np.linspace(-SIGN_GRID_HALF_WIDTH, SIGN_GRID_HALF_WIDTH, 1201)
    grid_f = np.asarray(chebyshev(jnp.asarray(ug), layout.k)) / sr
    uu, sp = np.meshgrid(np.linspace(-1.0, 1.0, 41), dissipation_speeds(speed, settings.damping_only), indexing="ij")
    dcols = np.asarray(layout.columns(jnp.asarray(uu.ravel()), jnp.asarray(sp.ravel())))[:, layout.k + 1 :]
    grid_d = dcols * sp.ravel()[:, None] / scale[layout.k + 1 :]
    pen = _penalty_terms(meta, omega_r, omega_d)
    out = _select(jnp.asarray(gram), jnp.asarray(rhs), yy, n, jnp.asarray(omega_r), jnp.asarray(omega_d),
                  masks, lam_r, lam_d, jnp.asarray(settings.log_lambdas), jnp.asarray(settings.log_lambdas_damping),
                  (jnp.asarray(grid_f), jnp.asarray(grid_d), bool(settings.damping_only)), tuple(pen), layout,
                  tuple(jnp.asarray(a) for a in recorded))
    theta, ainv, rss, edf, bic, changes, confines, dissipative = (np.asarray(a) for a in out)
    shape_ok = (changes == 2 * n_wells - 1) & confines if not settings.damping_only else True
    admissible = shape_ok & dissipative & np.isfinite(bic)
    score = np.where(admissible, bic, np.inf)
    best = int(np.argmin(score)) if admissible.any() else int(np.nanargmin(np.where(np.isfinite(bic), bic, np.inf)))
    # prior-data conflict: the best admissible score against the best of all candidates (-2 log evidence)
    free = int(np.argmin(np.where(np.isfinite(bic), bic, np.inf))) if np.isfinite(bic).any() else best
    conflict = float(score[best] - bic[free]) if admissible.any() else 0.0
    if conflict > CONFLICT and refine and (len(settings.log_lambdas) > 1 or settings.damping_only):
        # the data reject every admissible law: the best admissible one sits at the edge of admissibility
        # (the least penalty that keeps the shape), which the decade grid of penalties may step over;
        # search it on the grid refined to half decades (magnet, 40 dB, seed 1: degree 11 at 10^-4, 19 %
        # off on the span, at 10^-5 3.9 %)
        grid = np.asarray(settings.log_lambdas, float)
        fine = tuple(np.unique(np.concatenate([grid, 0.5 * (grid[1:] + grid[:-1])])).tolist())
        changes = {"log_lambdas": fine}
        grid_d, i_d = np.asarray(settings.log_lambdas_damping, float), int(lam_d[best])
        if settings.damping_only and i_d > 0:
            # ... and the damping's: a law that is zero somewhere (the joint's 50 x^2 v at the saddle) is at that
            # edge, which noise puts on either side; between the best admissible penalty and the next smaller one,
            # in quarter decades (bistable joint, 30 dB, seed 2: C(0) 13.7 at 10^-4 for the truth's 0, at
            # 10^-4.75 0.95)
            step = np.arange(grid_d[i_d - 1], grid_d[i_d], 0.25)
            changes["log_lambdas_damping"] = tuple(np.unique(np.concatenate([grid_d, step])).tolist())
        return joint_coordinate(*raw[:4], equilibria, well_variance, speed,
                                dataclasses.replace(settings, **changes), refine=False, x_noise=raw[4], rows=rows,
                                band=band, gain=gain, v_noise=raw[5])
    if settings.tie > 0 and admissible.any():
        near = np.nonzero(score <= score[best] + settings.tie)[0]
        # as many velocity terms as the best: the tie picks among laws of the damping the data chose, it does not
        # drop a term they favour (single-tone arch, x only, 50 dB, seed 0: v|v| by 5.7 over none; dropped, the
        # one-period NRMSE of the unseen cross-well record was 16.1 %, kept 5.2 %)
        near = np.array([i for i in near if len(meta[i][2]) == len(meta[best][2])])
        best = int(min(near, key=lambda i: (max(meta[i][2], default=1), meta[i][0], meta[i][1], score[i])))
    robust = v_rows is not None
    covariance = lambda i: _covariance(i, theta, ainv, rss, edf, n, masks, cols, ys, w, gram, v_rows if robust else None)  # noqa: E731
    dropped_terms, ranked = [], bic  # `ranked`: the scores the alternatives below are weighed by
    sigma2, cov_theta = covariance(best)
    if robust:
        chosen = _robust_velocity_set(best, meta, lam_r, lam_d, admissible, theta, masks, n, cov_theta)
        dropped_terms = sorted(set(meta[best][2]) - set(meta[chosen][2]))
        if dropped_terms:
            # the laws with a term the robust test rejected are out of the alternatives too (else the band takes the
            # term back as the degree choice's discrepancy, at a weight near 1), and the law kept stands at the
            # score's best
            ranked = np.where([any(o in mt[2] for o in dropped_terms) for mt in meta], np.inf, bic)
            ranked[chosen] = bic[best]
            best = chosen
            sigma2, cov_theta = covariance(best)
    k, j, vel = meta[best]
    # map to monomial coefficients in x
    to_x = lambda deg: np.asarray(monomial_map(c, 2.0 * h, deg + 1)) @ cheb_to_monomial(deg)  # noqa: E731
    n_vel = max((*layout.vel, 1)) + 1
    g_size = (layout.k + 1) + n_vel + (layout.j + 1)
    lin = np.zeros((g_size, layout.p))
    lin[: layout.k + 1, layout.restoring] = to_x(layout.k) / sr[None, :]
    damp = to_x(layout.j) / sd[None, :]  # C(x) monomials
    off_v, off_p = layout.k + 1, layout.k + 1 + n_vel
    lin[off_v + 1, layout.damping] = damp[0]  # viscous term: C(0)
    lin[off_p + 1 : off_p + layout.j + 1, layout.damping] = damp[1:]
    for i, order in enumerate(layout.vel):
        lin[off_v + order, layout.k + layout.j + 2 + i] = 1.0 / scale[layout.k + layout.j + 2 + i]
    flat = lin @ theta[best]
    # what the noise of v would have moved the chosen law by, uncorrected, to first order: the same candidate solved
    # on the normal matrix that holds it, (A + N)^-1 b - A^-1 b = -(I + A^-1 N)^-1 A^-1 N theta. The measured columns
    # differ from the corrected ones too (v^3 by 3 s^2 v, in the span of the C(0) v column every candidate has; v|v|
    # by s^2 sgn(v)), which this leaves out: about 10 % of the viscous term's move on a synthetic double well
    shift = np.zeros(g_size)
    if v_gram is not None:
        mk = masks[best].astype(float)
        an = ainv[best] @ (v_gram * np.outer(mk, mk))
        shift = lin @ -np.linalg.solve(np.eye(an.shape[0]) + an, an @ theta[best])
    cov = lin @ cov_theta @ lin.T
    # the degree choice's discrepancy (issue 15): the best admissible candidate of another degree K
    # (the runner-up law), as a difference to the chosen one, weighted as in Bayesian model averaging
    # over the two: the score is -2 log evidence, so the runner-up's posterior weight is
    # w = 1 / (1 + exp(delta / 2)) and E[(F - F_chosen)^2] gains w (F_alt - F_chosen)^2
    degrees = np.array([mt[0] for mt in meta])
    pool = admissible & (degrees != k) & np.isfinite(ranked)
    alt = int(np.argmin(np.where(pool, ranked, np.inf))) if pool.any() else None
    if alt is not None:
        weight = 1.0 / (1.0 + np.exp(min(0.5 * float(ranked[alt] - ranked[best]), 700.0)))
        alternative = np.sqrt(weight) * (lin @ theta[alt] - lin @ theta[best])
    else:
        alternative = np.zeros(g_size)
    # the damping the data could not tell from the chosen one (rule 14, `_sanity.check_damping_choice`): the best
    # admissible candidate of the same restoring degree with another set of velocity terms, as a difference
    vels = [mt[2] for mt in meta]
    pool_d = admissible & (degrees == k) & np.array([v != vel for v in vels]) & np.isfinite(ranked)
    alt_d = int(np.argmin(np.where(pool_d, ranked, np.inf))) if pool_d.any() else None
    damping_alt = (np.zeros(g_size) if alt_d is None else lin @ theta[alt_d] - lin @ theta[best])
    recorded_x = raw[0][raw[3] > 0]  # the span: the wells' and the records' (a record that hops spans both wells)
    span = (min(lo, float(recorded_x.min(initial=lo))), max(hi, float(recorded_x.max(initial=hi))))
    truncation, ratio, tail = _truncation(meta, theta, ranked, lin, layout, (k, j, vel), span, settings)
    cov = cov + truncation
    # ... and the law the data prefer, as a difference to the chosen one (`reconstruct` widens the band by it
    # and warns where the conflict is decisive, `CONFLICT`)
    unconstrained = lin @ theta[free] - lin @ theta[best] if conflict > CONFLICT else np.zeros(g_size)
    stats = {"joint_degree": k, "joint_damping_degree": j, "joint_velocity_orders": list(vel),
             "joint_log_lambda": float(settings.log_lambdas[lam_r[best]]),
             "joint_log_lambda_damping": float(settings.log_lambdas_damping[lam_d[best]]),
             "joint_bic": float(bic[best]), "joint_edf": float(edf[best]), "joint_sigma2": sigma2,
             "joint_admissible": bool(admissible[best]), "joint_n_admissible": int(admissible.sum()),
             "joint_n_candidates": int(admissible.size),
             "joint_alternative": alternative.tolist(), "joint_alternative_degree": -1 if alt is None else meta[alt][0],
             "joint_conflict": conflict, "joint_unconstrained": unconstrained.tolist(),
             "joint_unconstrained_degree": meta[free][0],
             "joint_damping_alternative_orders": None if alt_d is None else list(meta[alt_d][2]),
             "joint_damping_alternative_delta": np.inf if alt_d is None else float(ranked[alt_d] - ranked[best]),
             "joint_damping_alternative_velocity": damping_alt[off_v:off_p].tolist(),
             "joint_damping_alternative_position": damping_alt[off_p:].tolist(),
             "joint_truncation_ratio": ratio, "joint_truncation_tail": tail,
             "joint_velocity_noise": v_rows is not None, "joint_velocity_orders_dropped": dropped_terms,
             "joint_velocity_noise_shift": shift.tolist()}
    return (flat[: layout.k + 1], flat[off_v:off_p], flat[off_p:], cov, stats)


def _truncation(meta, theta, bic, lin, layout: _Layout, chosen, span, settings: JointSettings):
    """The covariance of the restoring series' tail where the chosen degree K is the cap `max_degree`
    (`settings.truncation`), with the convergence ratio rho and the tail's RMS on the wells' span (0, 0 elsewhere).

    The best laws (any admissibility, the chosen damping) of degrees K, K - 2 and K - 4 differ by d_K and
    d_(K-2) (RMS on the span); their ratio rho (at most `TRUNCATION_RATIO_MAX`) is the series' convergence, and
    the geometric tail beyond K is s = rho / (1 - rho) |d_K|. The law has no room for degrees above K, so the
    tail is spread over its two highest Chebyshev polynomials on the span, T_K and T_(K-1), each of variance s^2:
    their squares never vanish together (a rank-one difference would pinch the band at its zeros), and the
    band's RMS over the span is about s."""
    n = lin.shape[0]
    k, j, vel = chosen
    if not settings.truncation or settings.damping_only or k != layout.k:
        return np.zeros((n, n)), 0.0, 0.0

    def best_of(degree):
        pool = [i for i, mt in enumerate(meta) if mt == (degree, j, vel) and np.isfinite(bic[i])]
        return min(pool, key=lambda i: bic[i]) if pool else None

    ids = [best_of(k - 2 * m) for m in range(3)]
    if any(i is None for i in ids):
        return np.zeros((n, n)), 0.0, 0.0
    lo, hi = span
    xs = np.linspace(lo, hi, 201)
    laws = [np.polynomial.polynomial.polyval(xs, (lin @ theta[i])[: layout.k + 1]) for i in ids]
    rms = lambda f: float(np.sqrt(np.mean(f**2)))
    d_k, d_prev = rms(laws[0] - laws[1]), rms(laws[1] - laws[2])
    if not (np.isfinite(d_k) and np.isfinite(d_prev)) or d_k == 0.0:
        return np.zeros((n, n)), 0.0, 0.0
    ratio = min(d_k / d_prev, TRUNCATION_RATIO_MAX) if d_prev > 0 else TRUNCATION_RATIO_MAX
    tail = ratio / (1.0 - ratio) * d_k
    out = np.zeros((n, n))
    for m in (k, k - 1):
        c = np.polynomial.Chebyshev.basis(m, domain=[lo, hi]).convert(kind=np.polynomial.Polynomial).coef
        out[: c.size, : c.size] += tail**2 * np.outer(c, c)
    return out, float(ratio), float(tail)


def restoring_faults(stiffness, equilibria) -> list[str]:
    """Why a global restoring force of one DOF is not admissible, or []: it must confine (odd
    degree, positive leading coefficient: F -> +inf as x -> +inf, -inf as x -> -inf) and change
    sign exactly 2n - 1 times over the span it is used on, the equilibria widened by half their
    span on each side (its n wells and the saddles between them: no other well). Monomial
    coefficients in x, as `GlobalModel` holds them."""
    return [msg for _, msg in _restoring_faults(stiffness, equilibria)]


def restoring_fault_kinds(stiffness, equilibria) -> dict[str, int]:
    """`restoring_faults` by kind, for comparing two laws: "even" (even degree), "outward"
    (negative leading coefficient), "sign" (the number of sign changes, where it is wrong)."""
    return dict(kind for kind, _ in _restoring_faults(stiffness, equilibria))


def restoring_fault_details(stiffness, equilibria) -> list[tuple[str, int, str]]:
    """`restoring_faults` as (kind, count, message) triples (`restoring_fault_kinds`' kinds)."""
    return [(kind, n, msg) for (kind, n), msg in _restoring_faults(stiffness, equilibria)]


def _restoring_faults(stiffness, equilibria) -> list[tuple[tuple[str, int], str]]:
    eq = np.asarray(equilibria, float)
    lo, hi = float(eq.min()), float(eq.max())
    half = 0.5 * (hi - lo)
    x = np.linspace(lo - half, hi + half, 801)
    f = np.polynomial.polynomial.polyval(x, np.asarray(stiffness, float))
    out = []
    coef = np.trim_zeros(np.asarray(stiffness, float), "b")
    if coef.size % 2 == 1 and coef.size > 1:  # even degree: F has one sign at both ends
        out.append((("even", 1), f"its restoring force has even degree {coef.size - 1}, so it cannot confine on both "
                                 f"sides (F -> {'+' if coef[-1] > 0 else '-'}inf as x -> ±inf)"))
    elif coef.size > 1 and coef[-1] < 0:
        out.append((("outward", 1), f"its restoring force turns outward far out (leading term {coef[-1]:.4g} "
                                    f"x^{coef.size - 1}: F -> -inf as x -> +inf): a motion that leaves the recorded "
                                    f"range escapes"))
    pos = f >= 0
    changes = int(np.sum(pos[1:] != pos[:-1]))
    if changes != 2 * eq.size - 1:
        out.append((("sign", changes), f"its restoring force changes sign {changes} times on [{lo - half:.4g}, "
                                       f"{hi + half:.4g}] where {eq.size} wells and the saddles between them need "
                                       f"{2 * eq.size - 1}"))
    return out


def fall_speed(stiffness, wells, mass: float, lo: float, hi: float, n: int = 401) -> float:
    """The speed of a fall from the highest point of the potential V = int F dx on [lo, hi] (`n` points) to the
    lowest of `wells`, sqrt(2 (max V - min V_well) / m): the speeds a law of one DOF is used at without forcing
    (the bound `damping_faults` checks up to); 0 where no point lies above the wells."""
    antider = np.polynomial.polynomial.polyint(np.asarray(stiffness, float))
    drop = float(np.max(np.polynomial.polynomial.polyval(np.linspace(lo, hi, n), antider))
                 - np.min(np.polynomial.polynomial.polyval(np.asarray(wells, float), antider)))
    return float(np.sqrt(2.0 * max(drop, 0.0) / mass))


def damping_faults(velocity_damping, position_damping, equilibria, speed: float) -> list[str]:
    """Why a global damping law of one DOF is not admissible, or []: it must dissipate,
    D(x, v) v >= 0 (within `DISSIPATION_TOLERANCE`) and not identically 0, over the span of use
    (as `restoring_faults`) and |v| <= `speed`; a negative friction b_0 sgn(v) feeds energy in as v -> 0
    (below the check grid's lowest speed) wherever it is."""
    eq = np.asarray(equilibria, float)
    lo, hi = float(eq.min()), float(eq.max())
    half = 0.5 * (hi - lo)
    xx, vv = np.meshgrid(np.linspace(lo - half, hi + half, 41), dissipation_speeds(speed), indexing="ij")
    b = np.asarray(velocity_damping, float)
    if b.size and b[0] < 0:  # D v -> b_0 |v| as v -> 0, below any grid's lowest speed
        return [f"its friction b_0 sgn(v) is negative ({b[0]:.4g}): it feeds energy in at low speed"]
    dv = np.polynomial.polynomial.polyval(xx, np.asarray(position_damping, float)) * vv**2
    dv = dv + sum(b[j] * vv ** (j + 1) for j in range(b.size))
    if not np.any(dv > 0):
        return ["it has no damping"]
    if np.min(dv) < -DISSIPATION_TOLERANCE * np.max(np.abs(dv)):
        i = np.unravel_index(np.argmin(dv), dv.shape)
        return [f"its damping feeds energy in (D v < 0) at x = {xx[i]:.4g}, v = {vv[i]:.4g}"]
    return []


def inadmissible(stiffness, velocity_damping, position_damping, equilibria, speed: float) -> list[str]:
    """Why a global model of one DOF is not admissible over the span it is used on, or []:
    `restoring_faults` and `damping_faults` together."""
    return restoring_faults(stiffness, equilibria) + damping_faults(velocity_damping, position_damping, equilibria,
                                                                    speed)
