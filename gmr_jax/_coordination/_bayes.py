"""One probabilistic model of every well's data: weak-form rows, a structured Gaussian prior on
the global law, hyperparameters by evidence.

Per DOF, the force balance y(t) = F(x) + B(v) + C(x) v, with

    F(x) = Y sum_k a_k T_k(u),   B(v) = Y sum_j b_j sgn(w)|w|^j,   C(x) v = Y sum_j c_j u^j w,

u = (x - x_c) / h (the records' span mapped to [-1, 1]), w = v / V (V: the largest recorded
speed), Y the RMS of the rows' target, T_k Chebyshev polynomials. It is multiplied by test
functions psi_j(t - t_m) on disjoint windows and integrated (the weak form): the inertia m x''
enters as m psi'' x, the position damping u^j w = d/dt [h u^(j+1) / ((j+1) V)] as -psi' times
that, so neither needs a differentiated signal; rows from disjoint windows carry independent
noise, the test functions of one window are rotated to be uncorrelated under white noise in the
force and in x. Each well w and test function j has its own noise variance s_wj^2.

Prior: a_k ~ N(0, s_F^2 rho_F^(2 max(k - q, 0))) with q = 2W - 1 for W wells: a law with W
stable wells has at least 2W - 1 zeros, so the orders up to q are all expected, and beyond them
the Chebyshev coefficients of a function analytic on a Bernstein ellipse fall geometrically;
b_j ~ N(0, s_bj^2), c_j ~ N(0, s_cj^2), each damping term with its own scale (automatic
relevance determination, sparse Bayesian learning: a term the data do not need gets a scale
near zero and drops out, so the law extrapolates beyond the recorded speeds with the terms the
records hold, not with a smooth mixture of every power). The scales, the decay and the wells'
noise variances maximise the log marginal likelihood (MacKay's evidence) times a hyperprior,
wide on the restoring law's scale and decay, flat on the damping scales (a scale the evidence
drives to zero switches its term off); the posterior mean and covariance then give the law, its standard errors and its
band, one covariance for all three.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import lineax as lx
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from .._solution import RESULTS, Solution, as_result
from ._hermite import monomial_map

#: exponent p of the test function phi(s) = (1 - s^2)^p, s in [-1, 1]: phi, phi', phi'' vanish at the ends
TEST_POWER = 4


def _exact(phi, d1, d2):
    """Correct d1, d2 (least change) so that summation by parts against phi is exact on
    polynomials of degree <= 2 in the sample index n: sum phi' n^k = -k sum phi n^(k-1),
    sum phi'' n^k = k (k - 1) sum phi n^(k-2)."""
    n = np.arange(phi.size) - (phi.size - 1) / 2.0
    V = np.stack([n**0, n, n**2], axis=1)
    m = [np.sum(phi * n**k) for k in range(3)]

    def exact(w, moments):
        return w + V @ np.linalg.solve(V.T @ V, np.asarray(moments) - V.T @ w)

    return exact(d1, [0.0, -m[0], -2.0 * m[1]]), exact(d2, [0.0, 0.0, 2.0 * m[0]])


def test_functions(width: int, count: int = 1) -> np.ndarray:
    """`count` test functions on `width` samples of unit spacing: (count, 3, width), each
    psi, psi', psi''.

    The first is the bump phi(s) = (1 - s^2)^p, s in [-1, 1], summing to 1; with `count` > 1
    the family spans phi(s) P_j(s), j < `count` (P_j Legendre polynomials), rotated so that
    both sum_n psi_i psi_j and sum_n psi_i'' psi_j'' are diagonal: white noise in the force
    (weighted by psi) and in the displacement (weighted by psi'') then leaves the rows of one
    window uncorrelated, each with its own variance. Each has the energy of the first and
    derivatives corrected by `_exact`, so a record's static offset and trend cancel exactly,
    whatever the width."""
    s = -1.0 + (2.0 * np.arange(width) + 1.0) / width
    half = width / 2.0  # ds/dt in samples
    p = TEST_POWER
    bump = np.polynomial.Polynomial([1.0, 0.0, -1.0]) ** p
    fams = []
    for j in range(count):
        f = bump * np.polynomial.Legendre.basis(j).convert(kind=np.polynomial.Polynomial)
        fams.append([f(s), f.deriv(1)(s) / half, f.deriv(2)(s) / half**2])
    fams = np.asarray(fams)  # (count, 3, width)
    norm = fams[0, 0].sum()
    fams = fams / norm
    if count > 1:
        import scipy.linalg

        g0 = fams[:, 0] @ fams[:, 0].T
        g2 = fams[:, 2] @ fams[:, 2].T
        _, vec = scipy.linalg.eigh(g2, g0)  # vec' g0 vec = I, vec' g2 vec diagonal, smoothest first
        fams = np.einsum("jk,jdn->kdn", vec, fams) * np.sqrt(np.sum(fams[0, 0] ** 2))
    return np.stack([np.stack([f[0], *_exact(*f)]) for f in fams])


class Basis(eqx.Module):
    """Sizes of the three families: restoring T_0..T_K, velocity sgn(w)|w|^0..d, position u^1..d w;
    `free`: the restoring orders 0..`free` whose prior does not decay."""

    degree: int = eqx.field(static=True)
    damping_order: int = eqx.field(static=True)
    free: int = eqx.field(static=True, default=0)

    @property
    def sizes(self) -> tuple[int, int, int]:
        return self.degree + 1, self.damping_order + 1, self.damping_order

    @property
    def n(self) -> int:
        return sum(self.sizes)

    def family(self) -> np.ndarray:
        """Family index (0, 1, 2) of every column."""
        return np.concatenate([np.full(n, f) for f, n in enumerate(self.sizes)])

    def decay_power(self) -> np.ndarray:
        """The exponent of rho in every column's prior variance."""
        k, d = self.degree, self.damping_order
        restoring = np.maximum(np.arange(k + 1) - self.free, 0)
        return np.concatenate([restoring, np.abs(np.arange(d + 1) - 1), np.arange(d)]).astype(float)


def _chebyshev(u, degree: int):
    cols = [jnp.ones_like(u), u]
    for _ in range(2, degree + 1):
        cols.append(2.0 * u * cols[-1] - cols[-2])
    return jnp.stack(cols[: degree + 1], axis=-1)


def _windows(sig, width: int):
    """(..., N) -> (..., N // width, width): disjoint windows."""
    m = sig.shape[-1] // width
    return sig[..., : m * width].reshape(sig.shape[:-1] + (m, width))


def weak_rows(
    x: Float[Array, "records samples"],
    v: Float[Array, "records samples"],
    p: Float[Array, "records samples"],
    s: Float[Array, "records samples"],
    mask: Bool[Array, "records samples"],
    centre, half, speed,
    basis: Basis,
    width: int,
    dt,
    tests: int = 1,
):
    """Weak-form rows of every record: the target y = p + s'' and the columns of the three
    families, each integrated against the `tests` test functions of `test_functions` on
    disjoint windows of `width` samples.

    Returns `(rows (R T, M, P), target (R T, M), valid (R T, M))`, record r's rows under test
    function j at index r T + j; a window is valid when every sample in it is."""
    tf = jnp.asarray(test_functions(width, tests))
    phi, d1, d2 = tf[:, 0], tf[:, 1], tf[:, 2]
    u = (x - centre) / half
    w = v / speed
    dtw = jnp.asarray(dt)
    xs_, ws_, ps_, ss_ = (_windows(a, width) for a in (u, w, p, s))
    target = jnp.einsum("rmn,jn->rjm", ps_, phi) + jnp.einsum("rmn,jn->rjm", ss_, d2) / dtw**2
    restoring = jnp.einsum("rmnk,jn->rjmk", _chebyshev(xs_, basis.degree), phi)
    d = basis.damping_order
    pw = jnp.stack([jnp.sign(ws_) * jnp.abs(ws_) ** j for j in range(d + 1)], axis=-1)
    velocity = jnp.einsum("rmnk,jn->rjmk", pw, phi)
    # viscous and position damping as exact time derivatives: u^j w = (h / V) d/dt u^(j+1) / (j + 1)
    anti = jnp.stack([xs_ ** (j + 1) / (j + 1) for j in range(d + 1)], axis=-1)
    exact = -jnp.einsum("rmnk,jn->rjmk", anti, d1) * (half / speed) / dtw
    velocity = velocity.at[..., 1].set(exact[..., 0]) if d >= 1 else velocity
    position = exact[..., 1:]
    rows = jnp.concatenate([restoring, velocity, position], axis=-1)
    valid = jnp.broadcast_to(jnp.all(_windows(mask, width), axis=-1)[:, None, :], target.shape)
    flat = lambda a: a.reshape((-1,) + a.shape[2:])  # noqa: E731
    return flat(rows), flat(target), flat(valid)


def well_statistics(rows, target, valid, well: Int[Array, " records"], n_wells: int):
    """Per well: Gram matrix G_w, moment b_w, sum of squares yy_w and row count n_w."""
    wv = valid.astype(rows.dtype)
    one_hot = jax.nn.one_hot(well, n_wells, dtype=rows.dtype)  # (R, W)
    G = jnp.einsum("rw,rm,rmi,rmj->wij", one_hot, wv, rows, rows)
    b = jnp.einsum("rw,rm,rmi,rm->wi", one_hot, wv, rows, target)
    yy = jnp.einsum("rw,rm,rm->w", one_hot, wv, target**2)
    n = jnp.einsum("rw,rm->w", one_hot, wv)
    return G, b, yy, n


def well_factors(rows, target, valid, well: Int[Array, " records"], n_wells: int):
    """Per well: the triangular factor F_w (P + 1, P + 1) of its valid rows [Phi | y], so that
    F_w' F_w = [[G_w, b_w], [b_w', yy_w]] (the square-root form of `well_statistics`: the
    evidence from it needs no difference of large sums), and the row count n_w."""
    p = rows.shape[-1] + 1
    X = jnp.concatenate([rows, target[..., None]], axis=-1) * valid[..., None]

    def factor(w):
        Xw = (X * (well == w)[:, None, None]).reshape(-1, p)
        return jnp.linalg.qr(jnp.concatenate([Xw, jnp.zeros((p, p))]), mode="r")

    F = jax.vmap(factor)(jnp.arange(n_wells))
    n = jnp.einsum("rw,rm->w", jax.nn.one_hot(well, n_wells, dtype=rows.dtype), valid.astype(rows.dtype))
    return F, n


class Hyper(eqx.Module):
    """log scale and logit decay of the restoring law's prior, log prior standard deviation of
    every damping column (`Basis.sizes[1:]`), log noise variance per well (W,)."""

    log_scale: Float[Array, ""]
    logit_decay: Float[Array, ""]
    log_ard: Float[Array, " damping"]
    log_noise: Float[Array, " wells"]


def prior_sd(h: Hyper, basis: Basis):
    """The prior's standard deviation of every column: s rho^power for the restoring orders, each
    damping column its own (automatic relevance determination)."""
    power = jnp.asarray(basis.decay_power()[: basis.degree + 1])
    restoring = jnp.exp(h.log_scale + power * jax.nn.log_sigmoid(h.logit_decay))
    return jnp.concatenate([restoring, jnp.exp(h.log_ard)])


def _gaussian(sq, X, t, logdet_noise, n):
    """Posterior and log evidence of z ~ N(0, diag(sq^2)) under square-root data rows X, t
    (X'X = Phi' B Phi, X't = Phi' B y, t't = y' B y), sum log det B = `logdet_noise` and n rows.
    In whitened form A = I + D X'X D (D = diag(sq)), mean = D A^-1 D X't: one QR factorisation
    of [[X D, t], [I, 0]] gives the factor R of A, log det A, and the residual
    y'By - b'D A^-1 D b as its last diagonal entry squared, without cancellation."""
    P = sq.shape[0]
    S = jnp.concatenate([jnp.concatenate([X * sq[None, :], t[:, None]], axis=1),
                         jnp.concatenate([jnp.eye(P), jnp.zeros((P, 1))], axis=1)])
    R = jnp.linalg.qr(S, mode="r")
    z = jax.scipy.linalg.solve_triangular(R[:P, :P], R[:P, P], lower=False)
    logdet = 2.0 * jnp.sum(jnp.log(jnp.abs(jnp.diag(R[:P, :P]))))
    log_ev = 0.5 * (logdet_noise - R[P, P] ** 2 - logdet - n * jnp.log(2.0 * jnp.pi))
    return sq * z, R[:P, :P].T, log_ev


def _covariance(chol, sq):
    """The posterior covariance D A^-1 D from `_gaussian`'s factor L (L L' = A) and D = diag(sq)."""
    inv = jax.scipy.linalg.cho_solve((chol, True), jnp.eye(sq.shape[0]))
    return sq[:, None] * inv * sq[None, :]


#: the smallest noise variance of the rows, relative to the target's mean square: rounding in the
#: weak-form integrals is far below it, and noise-free records keep a finite evidence optimum
NOISE_FLOOR = 1e-24


def _weighted(F, log_noise):
    """The wells' factors weighted by their noise precisions beta = 1 / (exp(log_noise) +
    `NOISE_FLOOR`): the square-root rows X, t, and log beta."""
    log_beta = -jnp.logaddexp(log_noise, math.log(NOISE_FLOOR))
    X = jnp.exp(0.5 * log_beta)[..., None, None] * F
    return X[..., :-1], X[..., -1], log_beta


def _solve(h: Hyper, stats, basis: Basis, active):
    F, n = stats
    sq = prior_sd(h, basis) * active  # inactive columns: zero prior variance
    X, t, log_beta = _weighted(F, h.log_noise)
    p = F.shape[-1]
    mean, chol, log_ev = _gaussian(sq, X.reshape(-1, p - 1), t.reshape(-1), jnp.sum(n * log_beta), jnp.sum(n))
    return mean, chol, sq, log_ev


def log_evidence(h: Hyper, stats, basis: Basis, active):
    """log p(rows | hyperparameters, active columns), the marginal likelihood of the
    linear-Gaussian model."""
    return _solve(h, stats, basis, active)[3]


#: standard deviations of the hyperprior on the restoring law's log scale and logit decay: wide, so
#: that the evidence decides, and proper, so that orders the data do not need have a finite optimum
HYPER_SD = (10.0, 15.0)


#: BFGS tolerance on the hyperparameters and on the evidence per row
TOL = 1e-6

#: largest gradient of the evidence per row (per unit of a log or logit hyperparameter) at which an
#: optimum that ran out of BFGS steps is accepted
FLAT = 1e-3

def log_hyperprior(h: Hyper):
    """log p(hyperparameters) up to a constant: independent normals on the restoring law's log
    scale and logit decay (`HYPER_SD`), flat on the damping terms' log scales (sparse Bayesian
    learning: the evidence can switch a term off) and on the log noise variances."""
    return -0.5 * ((h.log_scale / HYPER_SD[0]) ** 2 + (h.logit_decay / HYPER_SD[1]) ** 2)


def _initial(stats, basis: Basis, decay: float) -> Hyper:
    F, n = stats
    var = jnp.sum(F[..., -1] ** 2, axis=-1) / jnp.maximum(n, 1.0)
    return Hyper(jnp.zeros(()), jnp.asarray(math.log(decay / (1.0 - decay))), jnp.zeros(sum(basis.sizes[1:])),
                 jnp.log(1e-2 * var + 1e-30))


#: below this (in units of the target's RMS) a column's posterior mean and standard deviation are zero
OFF = 1e-9


class Posterior(eqx.Module):
    """The posterior of one DOF's scaled coefficients, a mixture over the restoring degree
    K = 1..`degree`: `mean` (P,) and `covariance` (P, P) of the mixture; per degree the
    hyperparameters that maximise the evidence times the hyperprior, that maximum (log) and the
    weight p(K | rows)."""

    mean: Float[Array, " p"]
    covariance: Float[Array, "p p"]
    hyper: Hyper
    log_evidence: Float[Array, " degrees"]
    weight: Float[Array, " degrees"]


#: the optimum's derivative by the implicit function theorem; a least-squares solve where a
#: hyperparameter does not move the evidence (a flat direction of its Hessian)
_ADJOINT = optx.ImplicitAdjoint(linear_solver=lx.AutoLinearSolver(well_posed=False))


def _minimise(loss, starts, args, max_steps: int):
    """The better of BFGS runs from `starts`, and a `RESULTS` code: successful where BFGS stopped
    by its tolerances or where the gradient there is below `FLAT` (BFGS can wander along a
    direction the loss barely depends on without meeting its step tolerance)."""
    solver = optx.BFGS(rtol=TOL, atol=TOL)
    sols = [optx.minimise(loss, solver, y0, args=args, max_steps=max_steps, throw=False, adjoint=_ADJOINT)
            for y0 in starts]
    vals = jnp.stack([loss(sl.value, args) for sl in sols])
    best = jnp.argmin(vals)
    y = jax.tree_util.tree_map(lambda *a: jnp.stack(a)[best], *[sl.value for sl in sols])
    code = RESULTS.promote(sols[0].result)
    for k, sl in enumerate(sols[1:], start=1):
        code = RESULTS.where(best == k, RESULTS.promote(sl.result), code)
    grad = jax.grad(loss)(jax.lax.stop_gradient(y), jax.lax.stop_gradient(args))
    flat = jnp.max(jnp.abs(jnp.concatenate([jnp.ravel(g) for g in jax.tree_util.tree_leaves(grad)]))) < FLAT
    return y, RESULTS.where(flat, RESULTS.successful, code)


def _inverse_2x2(H):
    """The inverse of a symmetric 2 x 2 matrix with its eigenvalues raised to at least the
    hyperprior's curvature (a direction where the evidence is flat or not concave gets the
    hyperprior's variance)."""
    a, b, c = H[0, 0], H[0, 1], H[1, 1]
    mid, rad = 0.5 * (a + c), jnp.sqrt(0.25 * (a - c) ** 2 + b**2)
    floor = 1.0 / max(HYPER_SD) ** 2
    lam = jnp.maximum(jnp.stack([mid + rad, mid - rad]), floor)
    angle = 0.5 * jnp.arctan2(2.0 * b, a - c)
    V = jnp.array([[jnp.cos(angle), -jnp.sin(angle)], [jnp.sin(angle), jnp.cos(angle)]])
    return (V / lam[None, :]) @ V.T


def hyper_covariance(h, mean_of, loss_of):
    """The mean's covariance from the uncertainty of the restoring law's scale and decay
    z = (`h.log_scale`, `h.logit_decay`) (Laplace): J S J' with J = d mean / dz and S the inverse
    Hessian of the negative log posterior of z at its optimum `h`, so that the band holds where
    the evidence cannot fix how the law continues between and beyond the wells. `mean_of` and
    `loss_of` take hyperparameters like `h` (a `Hyper` or a `Design`)."""
    h = jax.lax.stop_gradient(h)

    def at(z):
        return eqx.tree_at(lambda q: (q.log_scale, q.logit_decay), h, (z[0], z[1]))

    z = jnp.stack([h.log_scale, h.logit_decay])
    J = jax.jacfwd(lambda q: mean_of(at(q)))(z)
    return J @ _inverse_2x2(jax.hessian(lambda q: loss_of(at(q)))(z)) @ J.T


def _optimise(stats, basis: Basis, active, max_steps: int):
    def loss(h, args):
        return -(log_evidence(h, args, basis, active) + log_hyperprior(h)) / jnp.maximum(jnp.sum(args[1]), 1.0)

    # two starts: the evidence can have a local optimum at either end
    h, code = _minimise(loss, [_initial(stats, basis, decay) for decay in (0.3, 0.7)], stats, max_steps)
    mean, chol, sq, log_ev = _solve(h, stats, basis, active)
    extra = hyper_covariance(h, lambda q: _solve(q, stats, basis, active)[0],
                             lambda q: -(log_evidence(q, stats, basis, active) + log_hyperprior(q)))
    return h, mean, _covariance(chol, sq) + extra, log_ev + log_hyperprior(h), code._value


def posterior(stats, basis: Basis, *, max_steps: int = 1024, throw: bool = True) -> Solution:
    """Posterior of the scaled coefficients from per-well statistics: each restoring degree
    K = 1..`basis.degree` with its own evidence-optimal hyperparameters, weighted by
    p(K | rows) (a uniform prior over K); mean and covariance are the mixture's.

    **Arguments:**

    - `stats`: `(F, n)` from `well_factors` (wells on the leading axis).
    - `basis`: the families' sizes.
    - `max_steps`: BFGS steps on the negative log evidence.

    **Returns:** a `Solution` with a `Posterior` value and a `RESULTS` code (the optimiser's at
    the most probable degree). Jittable, vmappable over datasets, differentiable (each optimum
    by the implicit function theorem)."""
    fam = basis.family()
    order = np.concatenate([np.arange(n) for n in basis.sizes])
    degrees = np.arange(1, basis.degree + 1)
    active = jnp.asarray(np.stack([np.where(fam == 0, order <= k, True) for k in degrees]).astype(float))
    h, means, covs, log_ev, codes = jax.lax.map(lambda a: _optimise(stats, basis, a, max_steps), active)
    weight = jax.nn.softmax(jnp.where(jnp.isfinite(log_ev), log_ev, -jnp.inf))
    mean = jnp.einsum("k,ki->i", weight, means)
    dev = means - mean[None, :]
    cov = jnp.einsum("k,kij->ij", weight, covs) + jnp.einsum("k,ki,kj->ij", weight, dev, dev)
    # a column the evidence switched off (its prior scale collapsed) is exactly absent
    absent = (jnp.diagonal(cov) < OFF**2) & (jnp.abs(mean) < OFF)
    mean = jnp.where(absent, 0.0, mean)
    cov = jnp.where(absent[:, None] | absent[None, :], 0.0, cov)
    best = jnp.argmax(weight)
    code = RESULTS.where(jnp.all(jnp.isfinite(mean)), as_result(codes[best]), RESULTS.nonfinite)
    out = Solution(Posterior(mean, cov, h, log_ev, weight), code, {})
    if throw:
        out = eqx.tree_at(lambda s: s.value, out, out.result.error_if(out.value, out.result != RESULTS.successful))
    return out


def _chebyshev_to_power(size: int) -> np.ndarray:
    """Matrix C (size, size), C[m, i] the coefficient of u^m in T_i(u)."""
    C = np.zeros((size, size))
    for i in range(size):
        c = np.polynomial.chebyshev.cheb2poly(np.eye(size)[i])
        C[: c.shape[0], i] = c
    return C


def chebyshev_shift(a, b, degree: int):
    """Matrix S (K + 1, K + 1) with sum_i c_i T_i(a u + b) = sum_m (S c)_m T_m(u): Chebyshev
    coefficients in u of a law given by Chebyshev coefficients in u' = a u + b."""
    k = degree + 1
    to_power = _chebyshev_to_power(k)
    to_cheb = np.linalg.inv(to_power)
    i = np.arange(k)
    binom = np.array([[float(math.comb(int(c), int(m))) if m <= c else 0.0 for c in i] for m in i])
    expo = i[None, :] - i[:, None]
    # [m, c]: coefficient of u^m in (a u + b)^c
    sub = binom * a ** i[:, None].astype(float) * jnp.where(expo >= 0, b ** jnp.maximum(expo, 0), 0.0)
    return jnp.asarray(to_cheb) @ sub @ jnp.asarray(to_power)


class Design(eqx.Module):
    """Hyperparameters of one design's shared law: log scale and logit decay of its Chebyshev
    coefficients, each member's log spread about it and its wells' log noise variances."""

    log_scale: Float[Array, ""]
    logit_decay: Float[Array, ""]
    log_spread: Float[Array, " members"]
    logit_spread_decay: Float[Array, " members"]
    log_noise: Float[Array, "members wells"]


def _design_matrices(maps, damping: int):
    """E (J, P, Z): member j's scaled coefficients theta_j = E_j z from z = [g, d_1, e_1, ...,
    d_J, e_J] (g the shared law, d_j member j's deviation, e_j its damping coefficients)."""
    j, k = maps.shape[0], maps.shape[1]
    per = k + damping
    E = jnp.zeros((j, k + damping, k + j * per))
    for m in range(j):
        E = E.at[m, :k, :k].set(maps[m])
        E = E.at[m, :k, k + m * per: k + m * per + k].set(maps[m])
        E = E.at[m, k:, k + m * per + k: k + (m + 1) * per].set(jnp.eye(damping))
    return E


def _design_solve(d: Design, stats, maps, damping_sd, basis: Basis):
    F, n = stats  # (J, W, P + 1, P + 1), (J, W)
    E = _design_matrices(maps, damping_sd.shape[1])
    X, t, log_beta = _weighted(F, d.log_noise)
    X = jnp.einsum("jwrp,jpz->jwrz", X, E)
    power = jnp.asarray(basis.decay_power()[: basis.degree + 1])
    shape = jnp.exp(power * jax.nn.log_sigmoid(d.logit_decay))
    own = jnp.exp(power[None, :] * jax.nn.log_sigmoid(d.logit_spread_decay)[:, None])
    member = jnp.concatenate([jnp.exp(d.log_spread)[:, None] * own, damping_sd], axis=1)
    sq = jnp.concatenate([jnp.exp(d.log_scale) * shape, member.reshape(-1)])
    mean, chol, log_ev = _gaussian(sq, X.reshape(-1, X.shape[-1]), t.reshape(-1), jnp.sum(n * log_beta),
                                   jnp.sum(n))
    return E, mean, chol, sq, log_ev


def _log_design_prior(d: Design):
    return -0.5 * (jnp.sum((jnp.append(d.log_spread, d.log_scale) / HYPER_SD[0]) ** 2)
                   + jnp.sum((jnp.append(d.logit_spread_decay, d.logit_decay) / HYPER_SD[1]) ** 2))


def design_posterior(stats, maps, damping_sd, log_noise, basis: Basis, *, max_steps: int = 1024,
                     throw: bool = True) -> Solution:
    """Posterior of J members of one design: each member's restoring law, in the design's
    normalised coordinates, is the shared law g plus its own deviation d_j,

        theta_j = [A_j (g + d_j); e_j],   g ~ N(0, s^2 rho^(2 p_k)),   d_j ~ N(0, t_j^2 rho^(2 p_k)),

    (p_k the restoring decay powers of `basis`, e_j the damping coefficients with the prior
    `damping_sd` of the member's own fit). The scale s, decay rho, spreads t_j and the wells'
    noise variances (from `log_noise`) maximise the evidence of all members' rows times the
    hyperprior: a member whose rows disagree with the others' law gets a large t_j.

    **Arguments:**

    - `stats`: the members' `well_factors`, stacked (J, W, ...).
    - `maps`: (J, K + 1, K + 1) A_j, the design's normalised Chebyshev coefficients to member
      j's scaled restoring coefficients.
    - `damping_sd`: (J, P - K - 1) the damping columns' prior standard deviations.
    - `log_noise`: (J, W) the wells' log noise variances of the members' own fits (the start).

    **Returns:** a `Solution` whose value is `(mean (J, P), covariance (J, P, P), Design)`."""

    def loss(d, args):
        ev = _design_solve(d, args, maps, damping_sd, basis)[4]
        return -(ev + _log_design_prior(d)) / jnp.maximum(jnp.sum(args[1]), 1.0)

    j = maps.shape[0]
    starts = [Design(jnp.zeros(()), jnp.asarray(-1.0), jnp.full(j, t), jnp.full(j, -1.0), log_noise) for t in (-6.0, 0.0)]
    d, code = _minimise(loss, starts, stats, max_steps)  # two starts: the members one design, or each its own
    E, mean, chol, sq, _ = _design_solve(d, stats, maps, damping_sd, basis)
    cz = _covariance(chol, sq) + hyper_covariance(
        d, lambda q: _design_solve(q, stats, maps, damping_sd, basis)[1],
        lambda q: -(_design_solve(q, stats, maps, damping_sd, basis)[4] + _log_design_prior(q)))
    means = jnp.einsum("jpz,z->jp", E, mean)
    covs = jnp.einsum("jpz,zy,jqy->jpq", E, cz, E)
    code = RESULTS.where(jnp.all(jnp.isfinite(means)), code, RESULTS.nonfinite)
    out = Solution((means, covs, d), code, {})
    if throw:
        out = eqx.tree_at(lambda s: s.value, out, out.result.error_if(out.value, out.result != RESULTS.successful))
    return out


def to_monomials(basis: Basis, centre, half, speed, scale):
    """Matrix M (Q, P) from the scaled coefficients to the model's monomial coefficients:
    stiffness x^0..x^K, velocity damping sgn(v)|v|^0..d, position damping x^0..x^d v (the
    viscous part of C(x) v added to the velocity damping's v, x^0 v left at 0)."""
    k, d = basis.degree, basis.damping_order
    cheb = jnp.asarray(_chebyshev_to_power(k + 1))
    restoring = monomial_map(centre, half, k + 1) @ cheb * scale
    velocity = jnp.diag(scale / speed ** jnp.arange(d + 1.0))
    # u^j w, j = 1..d: (scale / V) sum_m S[m, j] x^m v
    pos = monomial_map(centre, half, d + 1)[:, 1:] * scale / speed  # (d + 1, d)
    q = (k + 1) + (d + 1) + (d + 1)
    M = jnp.zeros((q, basis.n))
    M = M.at[: k + 1, : k + 1].set(restoring)
    M = M.at[k + 1: k + d + 2, k + 1: k + d + 2].set(velocity)
    M = M.at[k + d + 3:, k + d + 2:].set(pos[1:])
    if d >= 1:
        M = M.at[k + 2, k + d + 2:].add(pos[0])  # x^0 v of C(x) v joins the viscous term
    return M
