"""Global model construction from local fits (Algorithm 1, stage 2; Eqs. 12-21)."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .._solution import RESULTS, Solution, error_if_failed
from ..local._library import POSITION_DAMPING, STIFFNESS, VELOCITY_DAMPING, Library
from ..local._local_fit import LocalFit
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
        return jnp.concatenate([self.stiffness, self.velocity_damping, self.position_damping])


def _taylor_blocks(coef: Float[Array, "n terms"], library: Library):
    """Split local coefficients into the restoring Taylor vector (orders 0..r), the damping
    polynomial's Taylor vector [B_1, c_1..c_d] (orders 0..d) and the other B_j."""
    n = coef.shape[0]
    d = library.damping_order
    a = coef[:, library.indices(STIFFNESS)]
    vd_idx = library.indices(VELOCITY_DAMPING)
    vd = coef[:, vd_idx] if vd_idx.size else jnp.zeros((n, d + 1))
    pd_idx = library.indices(POSITION_DAMPING)
    pd = coef[:, pd_idx] if pd_idx.size else jnp.zeros((n, d))
    c = jnp.concatenate([vd[:, 1:2], pd], axis=1)
    return a, c, vd


def _global_from_local(equilibria, coef, library: Library):
    a, c, vd = _taylor_blocks(coef, library)
    r_i = highest_order(a != 0)
    d_i = highest_order(c != 0)
    stiff, k_r, cond_r = hermite_interpolate(equilibria, a, r_i)
    damp, k_d, cond_d = hermite_interpolate(equilibria, c, d_i)
    b = jnp.mean(vd, axis=0).at[1].set(damp[0])  # Eq. (21); viscous term from the polynomial
    pos = damp.at[0].set(0.0)
    g = GlobalCoefficients(stiffness=stiff, velocity_damping=b, position_damping=pos)
    return g, (k_r, k_d, cond_r, cond_d, r_i, d_i)


@eqx.filter_jit
def coordinate(fits: LocalFit, library: Library = Library(), *, throw: bool = True) -> Solution:
    """Coordinate local fits into one global model of a DOF (Eqs. 12-21).

    **Arguments:**

    - `fits`: a batched `LocalFit` (leading axis: the n >= 2 equilibria), e.g. from
      `jax.vmap(fit_local)`.
    - `library`: the library the local fits used.

    **Returns:** a `Solution` with `value` a `GlobalCoefficients`, `aux` the covariance of its
    flattened coefficients (propagated exactly from the local fits' covariances: the map is
    linear in the local coefficients), and `stats` with the global orders `K_r` (Eq. 18),
    `K_d` (Eq. 20), the local orders and the condition numbers.
    """
    x = fits.equilibrium
    coef = fits.coef
    g, (k_r, k_d, cond_r, cond_d, r_i, d_i) = _global_from_local(x, coef, library)

    def flat(c):
        return _global_from_local(x, c, library)[0].flat()

    jac = jax.jacfwd(flat)(coef)  # (G, n, P); supports are fixed by `coef`'s zeros
    cov = jnp.einsum("gnp,npq,hnq->gh", jac, fits.covariance, jac)
    spread = jnp.max(x) - jnp.min(x)
    well_posed = (spread > 0) & (cond_r < MAX_CONDITION) & (cond_d < MAX_CONDITION)
    finite = jnp.all(jnp.isfinite(g.flat()))
    result = RESULTS.where(well_posed, RESULTS.successful, RESULTS.ill_posed_coordination)
    result = RESULTS.where(finite, result, RESULTS.nonfinite)
    stats = {"K_r": k_r, "K_d": k_d, "r_i": r_i, "d_i": d_i, "cond_r": cond_r, "cond_d": cond_d}
    return error_if_failed(Solution(value=g, result=result, stats=stats, aux=cov), throw)


def split_flat(flat: Float[Array, " g"], like: GlobalCoefficients) -> GlobalCoefficients:
    n1, n2 = like.stiffness.shape[0], like.velocity_damping.shape[0]
    return GlobalCoefficients(flat[:n1], flat[n1 : n1 + n2], flat[n1 + n2 :])


__all__ = ["GlobalCoefficients", "coordinate", "split_flat", "Int"]
