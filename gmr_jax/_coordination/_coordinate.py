"""Global model construction from local fits (Algorithm 1, stage 2; Eqs. 12-21)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._solution import RESULTS, Solution, error_if_failed
from .._topology import _xp
from .._fit._library import POSITION_DAMPING, STIFFNESS, VELOCITY_DAMPING, Library
from .._fit._local_fit import LocalFit
from .._trace_cache import disk_traced
from ._gls import hermite_gls
from ._hermite import hermite_interpolate, highest_order

#: Above this condition number of the scaled Hermite system the coordination is ill-posed.
MAX_CONDITION = 1e13


class GlobalCoefficients(eqx.Module):
    """Coefficients of one DOF's global model: `stiffness` A_k of x^k (Eq. 12),
    `velocity_damping` B_j of sgn(v)|v|^j (Eq. 21; B_1, the viscous term, is C_0 of the
    damping polynomial), `position_damping` C_j of x^j v (Eq. 14, C_0 = 0 here)."""

    stiffness: Float[Array, " kr"]
    velocity_damping: Float[Array, " kv"]
    position_damping: Float[Array, " kd"]

    def flat(self):
        parts = [self.stiffness, self.velocity_damping, self.position_damping]
        xp = np if all(isinstance(a, np.ndarray) for a in parts) else jnp  # NumPy in, NumPy out
        return xp.concatenate(parts)


def _taylor_blocks(coef: Float[Array, "n terms"], library: Library):
    """Split local coefficients into the restoring Taylor vector (orders 0..r), the damping
    polynomial's Taylor vector [B_1, c_1..c_d] (orders 0..d) and the other B_j."""
    xp = _xp(coef)  # NumPy in, NumPy out (the calibration after the jitted coordination)
    n = coef.shape[0]
    d = library.damping_order
    a = coef[:, library.indices(STIFFNESS)]
    vd_idx = library.indices(VELOCITY_DAMPING)
    vd = coef[:, vd_idx] if vd_idx.size else xp.zeros((n, d + 1))
    pd_idx = library.indices(POSITION_DAMPING)
    pd = coef[:, pd_idx] if pd_idx.size else xp.zeros((n, d))
    c = xp.concatenate([vd[:, 1:2], pd], axis=1)
    return a, c, vd


def _taylor_covariances(cov: Float[Array, "n terms terms"], library: Library):
    """Covariance blocks of the restoring and damping-polynomial Taylor vectors."""
    xp = _xp(cov)
    n = cov.shape[0]
    d = library.damping_order
    idx_a = library.indices(STIFFNESS)
    vd_idx, pd_idx = library.indices(VELOCITY_DAMPING), library.indices(POSITION_DAMPING)
    idx_c = list(vd_idx[1:2]) + list(pd_idx)
    sub = lambda idx: cov[:, idx][:, :, idx]  # noqa: E731
    cov_a = sub(idx_a)
    cov_c = sub(np.asarray(idx_c, int)) if len(idx_c) == d + 1 else xp.zeros((n, d + 1, d + 1))
    return cov_a, cov_c


#: the lowest degree the damping polynomial's GLS test takes (`hermite_gls`'s `min_degree`)
DAMPING_MIN_DEGREE = 0


def _solve(method, equilibria, taylor, order, cov, alpha, confining=False, max_degree=None, min_degree=None):
    exact, k_herm, cond = hermite_interpolate(equilibria, taylor, order)
    if method == "hermite":
        return exact, k_herm, cond, {"K_hermite": k_herm}
    coef, degree, _, stats = hermite_gls(equilibria, taylor, order, cov, alpha, confining=confining,
                                         max_degree=max_degree, min_degree=min_degree)
    # At K' = K the weighted fit is the interpolant itself: take the direct solve.
    return jnp.where(degree == k_herm, exact, coef), degree, cond, stats


def _global_from_local(equilibria, coef, cov, library: Library, method: str, alpha: float, confining: bool = False,
                       max_degree=None):
    a, c, vd = _taylor_blocks(coef, library)
    cov_a, cov_c = _taylor_covariances(cov, library)
    r_i = highest_order(a != 0)
    d_i = highest_order(c != 0)
    stiff, k_r, cond_r, st_r = _solve(method, equilibria, a, r_i, cov_a, alpha, confining=confining,
                                      max_degree=max_degree)
    # the damping polynomial has no saddles to make room for: its degree test starts at 0 (audit D F8: the
    # tri-stable quintic's (0.2 + 1400 x^2) v at 40 dB, the exact interpolant of the wells' noisy slopes, a
    # quartic 5-13 % off at the wells where a pooled pysindy fit is 0.1 % off)
    damp, k_d, cond_d, st_d = _solve(method, equilibria, c, d_i, cov_c, alpha, min_degree=DAMPING_MIN_DEGREE)
    b = jnp.mean(vd, axis=0).at[1].set(damp[0])  # Eq. (21); viscous term from the polynomial
    pos = damp.at[0].set(0.0)
    g = GlobalCoefficients(stiffness=stiff, velocity_damping=b, position_damping=pos)
    extra = {f"{k}_r": v for k, v in st_r.items()} | {f"{k}_d": v for k, v in st_d.items()}
    return g, (k_r, k_d, cond_r, cond_d, r_i, d_i, extra)


def with_dropped(fits: LocalFit) -> Float[Array, "n terms terms"]:
    """The local covariances the GLS weighs the Taylor conditions with: each term STLS removed (a
    known zero) carries the variance it would have had kept (`LocalFit.dropped`), not the near-hard
    constraint of the exact Hermite solve; the global coefficients' covariance stays that of the kept
    terms. Noise-free tri-stable quintic (audit D F6): the middle well's q^4, removed at 5e-8 of its
    force, is 5.4e4 in truth there (its record's centre is 8e-7 off the root), 5e4 "standard errors"
    as an exact zero; every degree below the interpolant's 17 was rejected."""
    cov = fits.covariance
    if fits.dropped is None:
        return cov
    diag = jnp.diagonal(cov, axis1=-2, axis2=-1)
    add = jnp.where(diag > 0, 0.0, fits.dropped)
    return cov + jax.vmap(jnp.diag)(add)


@disk_traced  # eqx.filter_jit, its traced program kept on disk by the CLI
def coordinate(
    fits: LocalFit,
    library: Library = Library(),
    *,
    method: str = "gls",
    alpha: float = 0.05,
    confining: bool = False,
    max_degree: Int[Array, ""] | None = None,
    throw: bool = True,
) -> Solution:
    """Coordinate local fits into one global model of a DOF (Eqs. 12-21).

    **Arguments:**

    - `fits`: a batched `LocalFit` (leading axis: the n >= 2 equilibria), e.g. from
      `jax.vmap(fit_local)`.
    - `library`: the library the local fits used.
    - `method`: "gls" (default): the Hermite problem solved by covariance-weighted least
      squares with the lowest global degree that the local covariances accept (chi-squared
      test at level `alpha`, see `hermite_gls`); it equals the paper's interpolant when no
      lower degree fits. "hermite": the paper's exact interpolant of degree K (Eq. 18).
      Tri-stable NES, 0.5 mm, five noise seeds: restoring error 0.4-2.2 % (hermite),
      see results/README.md for gls.
    - `confining`: with "gls", the restoring force's degree is odd (`hermite_gls`): an even K
      (a term resolved at some wells only) gives way to the highest odd degree below it.
    - `max_degree`: with "gls", the highest restoring degree allowed (`hermite_gls`; None: no
      bound; pass a JAX integer to reuse the compiled program across bounds).

    **Returns:** a `Solution` with `value` a `GlobalCoefficients`, `aux` the covariance of its
    flattened coefficients (propagated exactly from the local fits' covariances: the map is
    linear in the local coefficients), and `stats` with the global orders `K_r` (Eq. 18),
    `K_d` (Eq. 20), the local orders and the condition numbers.
    """
    x = fits.equilibrium
    coef = fits.coef
    if method not in ("gls", "hermite"):
        raise ValueError(f"method must be 'gls' or 'hermite', got {method!r}")
    weigh = with_dropped(fits)
    g, (k_r, k_d, cond_r, cond_d, r_i, d_i, extra) = _global_from_local(
        x, coef, weigh, library, method, alpha, confining, max_degree
    )

    def flat(c):
        return _global_from_local(x, c, weigh, library, method, alpha, confining, max_degree)[0].flat()

    jac = jax.jacfwd(flat)(coef)  # (G, n, P); supports are fixed by `coef`'s zeros
    cov = jnp.einsum("gnp,npq,hnq->gh", jac, fits.covariance, jac)
    spread = jnp.max(x) - jnp.min(x)
    well_posed = (spread > 0) & (cond_r < MAX_CONDITION) & (cond_d < MAX_CONDITION)
    finite = jnp.all(jnp.isfinite(g.flat()))
    result = RESULTS.where(well_posed, RESULTS.successful, RESULTS.ill_posed_coordination)
    result = RESULTS.where(finite, result, RESULTS.nonfinite)
    stats = {"K_r": k_r, "K_d": k_d, "r_i": r_i, "d_i": d_i, "cond_r": cond_r, "cond_d": cond_d} | extra
    return error_if_failed(Solution(value=g, result=result, stats=stats, aux=cov), throw)


def split_flat(flat: Float[Array, " g"], like: GlobalCoefficients) -> GlobalCoefficients:
    n1, n2 = like.stiffness.shape[0], like.velocity_damping.shape[0]
    return GlobalCoefficients(flat[:n1], flat[n1 : n1 + n2], flat[n1 + n2 :])


__all__ = ["GlobalCoefficients", "coordinate", "split_flat", "Int"]
