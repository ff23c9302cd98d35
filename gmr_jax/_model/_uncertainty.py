"""Uncertainty of a global model: bands on its forces and samples from its coefficient
distribution (issue 15; beyond the paper).

Every force of a `GlobalModel` is linear in its coefficients (Eq. 1): F_i(x, v) = phi(x, v)'
theta_i with theta_i the DOF's coefficients flattened as `coefficients` orders them. With
theta_i ~ N(mean, Sigma_i) (`GlobalModel.covariance`), F_i(x, v) is exactly normal with
variance phi' Sigma_i phi, so the band is exact linear propagation, no sampling.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from .._errors import GMRInputError
from .._fit._householder import psd_root
from .._fit._library import damping_columns
from ._model import GlobalModel, coefficients

PARTS = ("restoring", "damping", "total")


class ForceBand(eqx.Module):
    """A pointwise band on a model force, per DOF: `mean` (the model's force), `lower`, `upper`
    (mean -/+ z stderr, z the normal quantile of the level) and `stderr` (its standard
    deviation under the model's coefficient distribution)."""

    mean: Float[Array, "*batch dof"]
    lower: Float[Array, "*batch dof"]
    upper: Float[Array, "*batch dof"]
    stderr: Float[Array, "*batch dof"]


def _require_covariance(model, what: str):
    if not isinstance(model, GlobalModel):
        raise GMRInputError(f"{what} needs a GlobalModel (reconstructed or loaded from a model file), got "
                            f"{type(model).__name__}")
    if model.covariance is None:
        raise GMRInputError(f"{what}: the model has no covariance (a hand-written, refined or GMC-SINDy model, "
                            f"or a file written without one); reconstruct it with gmr_jax.reconstruct (which "
                            f"sets GlobalModel.covariance) or give from_terms a covariance=")


def _powers(x, n: int):
    """x^0 .. x^(n-1) on a new last axis, by products (differentiable at x = 0)."""
    return jnp.cumprod(jnp.concatenate([jnp.ones(x.shape + (1,), x.dtype),
                                        jnp.broadcast_to(x[..., None], x.shape + (max(n - 1, 0),))], axis=-1),
                       axis=-1)[..., :n]


def basis(model: GlobalModel, x: Float[Array, " dof"], v: Float[Array, " dof"] | None, part: str):
    """phi (dof, p): each DOF's force `part` at (x, v) is phi[i] @ coefficients(model)[i]."""
    ns, nv, npd = (model.stiffness.shape[-1], model.velocity_damping.shape[-1], model.position_damping.shape[-1])
    x = jnp.asarray(x, model.stiffness.dtype)
    zero = jnp.zeros(x.shape + (nv + npd,), x.dtype)
    restoring = jnp.concatenate([_powers(x, ns), zero], axis=1)
    if part == "restoring":
        return restoring
    cols = damping_columns(x, jnp.asarray(v, x.dtype), nv, npd, model.sign_eps)
    damping = jnp.concatenate([jnp.zeros(x.shape + (ns,), x.dtype), cols], axis=1)
    return damping if part == "damping" else restoring + damping


def force_band(
    model: GlobalModel,
    x: Float[Array, " dof"],
    v: Float[Array, " dof"] | None = None,
    *,
    part: str = "restoring",
    level: float | Float[Array, ""] = 0.95,
) -> ForceBand:
    """The `level` band of a model force at one point, per DOF, from `GlobalModel.covariance`
    (exact linear propagation: the forces are linear in the coefficients, Eq. 1).

    **Arguments:**

    - `model`: a `GlobalModel` with a covariance (`reconstruct` sets one).
    - `x`, `v`: (dof,) deformations and velocities, as `model.restoring` / `model.damping`
      take them (`jax.vmap` over a grid); `v` is needed for the damping.
    - `part`: "restoring" (F_r(x), default), "damping" (F_d(x, v)) or "total".
    - `level`: coverage of the two-sided normal band (traced: a new level does not recompile).

    **Returns:** a `ForceBand` of (dof,) arrays. Jittable, vmappable and differentiable in `x`,
    `v` and the model's coefficients.

    What the covariance of a reconstructed model holds (`reconstruct`): on the default route, the
    posterior covariance of the global law (the same one its standard errors come from), which
    widens between and beyond the wells where the records do not fix the law; on the paper's
    route, the local fits' covariances propagated through the coordination.

    Examples:
        >>> import jax, jax.numpy as jnp
        >>> import gmr_jax as gmr
        >>> model = gmr.from_terms([1.0], [
        ...     {"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -1.0},
        ...     {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1.0}],
        ...     covariance=[{"dof": 0, "terms": [["stiffness", 1], ["stiffness", 3]],
        ...                  "matrix": [[0.01, 0.0], [0.0, 0.0004]]}])
        >>> band = gmr.force_band(model, jnp.array([2.0]))
        >>> [round(float(a[0]), 3) for a in (band.mean, band.stderr, band.lower, band.upper)]
        [6.0, 0.256, 5.498, 6.502]
        >>> xs = jnp.linspace(-1.5, 1.5, 7)[:, None]
        >>> jax.vmap(lambda x: gmr.force_band(model, x).upper)(xs).shape
        (7, 1)
    """
    _require_covariance(model, "force_band")
    if part not in PARTS:
        raise GMRInputError(f"force_band: part must be one of {PARTS}, got {part!r}")
    if part != "restoring" and v is None:
        raise GMRInputError(f"force_band: part={part!r} needs the velocities v (one per DOF)")
    for name, z in (("x", x), ("v", v)):
        if z is not None and jnp.shape(z) != (model.n_elements,):
            raise GMRInputError(f"force_band takes one point: {name} must have shape ({model.n_elements},) (one value per "
                                f"DOF), got shape {jnp.shape(z)}; for a grid of points use "
                                f"jax.vmap(lambda x: force_band(model, x))(xs) with xs of shape (n, {model.n_elements})")
    phi = basis(model, x, v, part)
    mean = jnp.sum(phi * coefficients(model), axis=-1)
    var = jnp.einsum("ip,ipq,iq->i", phi, model.covariance, phi)
    se = jnp.sqrt(jnp.clip(var, 0.0))
    z = jax.scipy.special.ndtri(0.5 + 0.5 * jnp.asarray(level, se.dtype))
    return ForceBand(mean=mean, lower=mean - z * se, upper=mean + z * se, stderr=se)


def covariance_root(cov: Float[Array, "dof p p"]) -> Float[Array, "dof p p"]:
    """R with R R' = cov per DOF (V diag(sqrt(lambda)) by eigendecomposition: a covariance
    with exact zeros, the coefficients no datum moves, is singular and has no Cholesky factor)."""
    sym = 0.5 * (cov + jnp.swapaxes(cov, -1, -2))
    # one-sided Jacobi in plain XLA (`_fit/_householder.py`): jaxlib 0.10.2's batched eigh can deadlock
    root = jnp.vectorize(psd_root, signature="(p,p)->(p,p)")(sym)
    # coefficients of zero variance stay exactly fixed (no round-off leaks into them)
    return jnp.where((jnp.diagonal(cov, axis1=-2, axis2=-1) > 0)[..., :, None], root, 0.0)


def sample_models(model: GlobalModel, key: PRNGKeyArray, n: int) -> GlobalModel:
    """`n` models drawn from the model's coefficient distribution N(coefficients,
    `GlobalModel.covariance`), each DOF independently, as one stacked `GlobalModel` (every
    array with a leading axis of `n`, no covariance or stderr): map a prediction over it with
    `jax.vmap`, or take one with `jax.tree.map(lambda a: a[k], samples)`.

    **Arguments:** `model` (with a covariance), a `jax.random` key, `n` (static) the number of
    samples.

    Examples:
        >>> import jax, jax.numpy as jnp
        >>> import gmr_jax as gmr
        >>> model = gmr.from_terms([1.0], [
        ...     {"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -1.0},
        ...     {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1.0}],
        ...     covariance=[{"dof": 0, "terms": [["stiffness", 1]], "matrix": [[0.01]]}])
        >>> samples = gmr.sample_models(model, jax.random.key(0), 1000)
        >>> samples.stiffness.shape
        (1000, 1, 4)
        >>> f = jax.vmap(lambda m: m.restoring(jnp.array([2.0])))(samples)
        >>> round(float(f.std()), 1)  # the band's stderr at x = 2: 2 x 0.1
        0.2
    """
    _require_covariance(model, "sample_models")
    n = int(n)
    if n < 1:
        raise GMRInputError(f"sample_models: n must be >= 1, got {n}")
    mean = coefficients(model)
    root = covariance_root(model.covariance)
    z = jax.random.normal(key, (n,) + mean.shape, mean.dtype)
    draws = mean[None] + jnp.einsum("ipq,niq->nip", root, z)
    ns, nv = model.stiffness.shape[-1], model.velocity_damping.shape[-1]
    return GlobalModel(masses=jnp.broadcast_to(model.masses, (n,) + model.masses.shape),
                       stiffness=draws[..., :ns], velocity_damping=draws[..., ns:ns + nv],
                       position_damping=draws[..., ns + nv:], topology=model.topology, sign_eps=model.sign_eps)
