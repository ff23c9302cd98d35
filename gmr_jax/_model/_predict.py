"""Accelerations of a model over many states at once (jitted, vmapped): the vectorised
counterpart of `AbstractMechanicalModel.accelerations`, for evaluating a model on data."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._errors import GMRInputError, is_tracer
from .._fit._library import signed_power
from ._model import AbstractMechanicalModel, GlobalModel


@eqx.filter_jit
def _predict(model, x, v, b, f):
    return jax.vmap(model.accelerations)(x, v, b, f)


@eqx.filter_jit
def _parts(model, x, v):
    return jax.vmap(model.restoring)(x), jax.vmap(model.damping)(x, v)


def _states(name: str, model, x, v):
    """x and v as (n, dof) arrays for `model` (a 1-DOF model also takes (n,)), or a clear
    `GMRInputError`; v None is zero."""
    if not isinstance(model, AbstractMechanicalModel):
        raise GMRInputError(f"{name}: model must be a mechanical model, got {type(model).__name__}")
    d = model.n_dof
    xp = jnp if is_tracer(x) or is_tracer(v) else np
    x = xp.asarray(x, float)
    v = xp.zeros_like(x) if v is None else xp.asarray(v, float)
    if d == 1 and x.ndim == 1:
        x, v = x[:, None], v.reshape(-1, 1) if v.ndim == 1 else v
    if x.ndim != 2 or x.shape[1] != d or v.shape != x.shape:
        raise GMRInputError(f"{name}: x and v must both be (n, {d}) for this {d}-DOF model, got {x.shape} "
                            f"and {v.shape}")
    return x, v


def forces(
    model: AbstractMechanicalModel,
    x: Float[ArrayLike, "n dof"],
    v: Float[ArrayLike, "n dof"] | None = None,
    *,
    parts: bool = False,
):
    """The force each DOF carries, F(x, v) = F_r(x) + F_d(x, v) (Eq. 1), at n states: the
    model's restoring and damping laws evaluated on a grid or on data.

    **Arguments:**

    - `model`: a mechanical model (`GlobalModel`, a system's truth).
    - `x`, `v`: displacements and velocities, (n, dof) (a 1-DOF model also takes (n,));
      `v` None is zero (then F is the restoring force alone, F_d(x, 0) = 0).
    - `parts`: return (F_r, F_d) instead of their sum.

    **Returns:** F (n, dof), or the pair (F_r (n, dof), F_d (n, dof)); NumPy arrays for
    concrete inputs, JAX arrays under `jit`/`vmap`/`grad` (traced inputs or model).

    A `GlobalModel` is evaluated in NumPy (Horner's rule: no JAX program to compile); another
    model by one compiled program, padded to a bucket of rows so that similar sizes share it.

    Examples:
        The double well F_r = -x + x^3 with damping 0.1 v:

        >>> import numpy as np
        >>> import gmr_jax as gmr
        >>> model = gmr.from_terms([1.0], [
        ...     {"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -1.0},
        ...     {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1.0},
        ...     {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.1}])
        >>> gmr.forces(model, np.array([0.0, 0.5, 1.0, 2.0]))[:, 0].tolist()
        [0.0, -0.375, 0.0, 6.0]
        >>> fr, fd = gmr.forces(model, np.array([0.5]), np.array([2.0]), parts=True)
        >>> float(fr[0, 0]), float(fd[0, 0])
        (-0.375, 0.2)
    """
    x, v = _states("forces", model, x, v)
    traced = is_tracer(x) or is_tracer(v) or any(is_tracer(a) for a in jax.tree.leaves(model))
    if traced or x.shape[0] == 0:
        fr, fd = _parts(model, jnp.asarray(x), jnp.asarray(v))
    elif isinstance(model, GlobalModel):
        fr, fd = numpy_forces(model, x, v)
    else:
        fr, fd = _bucketed(_parts, model, x, v)
    return (fr, fd) if parts else fr + fd


def numpy_forces(model: GlobalModel, x, v) -> tuple[np.ndarray, np.ndarray]:
    """(F_r, F_d) of a `GlobalModel` at n states (n, dof), each (n, dof), in NumPy: the same
    sums as `GlobalModel.restoring` / `.damping` (Horner's rule, `signed_power`), with no JAX
    program to trace (the bookkeeping of `reconstruct`, figures)."""
    x, v = np.atleast_2d(np.asarray(x, float)), np.atleast_2d(np.asarray(v, float))
    k, b, c = (np.asarray(a, float) for a in (model.stiffness, model.velocity_damping, model.position_damping))

    def horner(coef, z):  # coef (dof, orders), z (n, dof)
        out = np.zeros_like(z)
        for col in coef.T[::-1]:
            out = out * z + col
        return out

    fd = horner(c, x) * v
    for j in range(b.shape[1]):
        fd = fd + b[:, j] * signed_power(v, j, model.sign_eps)
    return horner(k, x), fd


def _bucket(n: int) -> int:
    """Row count compiled for n rows: the next power of two (at least 16), so that calls on
    similar sizes share one compiled function."""
    return max(16, 1 << (int(n) - 1).bit_length())


def _bucketed(fn, model, *arrays):
    """`fn(model, *arrays)[:n]` (each output array's first n rows) with every (concrete)
    array's n rows zero-padded to `_bucket(n)`."""
    n = arrays[0].shape[0]
    m = _bucket(n)
    padded = [np.pad(np.asarray(a), [(0, m - n)] + [(0, 0)] * (np.ndim(a) - 1)) for a in arrays]
    # sliced in NumPy: no eager JAX operation
    return jax.tree.map(lambda a: np.asarray(a)[:n], fn(model, *padded))


def predict(
    model: AbstractMechanicalModel,
    x: Float[ArrayLike, "n dof"],
    v: Float[ArrayLike, "n dof"],
    base_acc: Float[ArrayLike, " n"] | None = None,
    force: Float[ArrayLike, "n dof"] | None = None,
) -> Float[Array, "n dof"]:
    """Relative accelerations x'' of `model` at n states (x, v) under inputs, vectorised.

    **Arguments:**

    - `model`: a mechanical model (`GlobalModel`, a system's truth).
    - `x`, `v`: displacements and velocities, (n, dof) (a 1-DOF model also takes (n,)).
    - `base_acc` (n,), `force` (n, dof): inputs (default zero).

    **Returns:** x'' (n, dof), the derivative of v in the first-order form; absolute
    accelerations are `model.absolute_accelerations(xdd, base_acc)`.

    Jitted and vmapped over states; concrete inputs are padded to the next power of two rows
    so that arrays of similar length reuse one compiled function (inside a `jax.jit` it traces
    as is).

    Examples:
        A unit mass with F(x, v) = -x + x^3 + 0.1 v: x'' = -F at rest in the input's absence.

        >>> import numpy as np
        >>> import gmr_jax as gmr
        >>> model = gmr.from_terms([1.0], [
        ...     {"dof": 0, "physics": "stiffness", "order": 1, "coefficient": -1.0},
        ...     {"dof": 0, "physics": "stiffness", "order": 3, "coefficient": 1.0},
        ...     {"dof": 0, "physics": "velocity_damping", "order": 1, "coefficient": 0.1}])
        >>> x = np.array([0.0, 0.5, 1.0, 2.0])
        >>> gmr.predict(model, x, np.zeros(4))[:, 0].tolist()
        [0.0, 0.375, 0.0, -6.0]
        >>> gmr.predict(model, x, np.ones(4), base_acc=np.ones(4))[:, 0].tolist()
        [-1.1, -0.725, -1.1, -7.1]
    """
    x, v = _states("predict", model, x, v)
    n, d = x.shape
    b = jnp.zeros(n) if base_acc is None else jnp.asarray(base_acc, float).reshape(n)
    f = jnp.zeros((n, d)) if force is None else jnp.asarray(force, float).reshape(n, d)
    if any(is_tracer(a) for a in (x, v, b, f)) or n == 0:
        return _predict(model, x, v, b, f)
    return jnp.asarray(_bucketed(_predict, model, x, v, b, f))


def input_gains(model: AbstractMechanicalModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The linear maps of the equation of motion, x'' = G_F F + g_b base_acc + G_f force, as
    numpy arrays: G_F (dof, dof), g_b (dof,), G_f (dof, dof) (probed from `accelerations`,
    which is linear in the force F and the inputs)."""
    d = model.n_dof
    eye, z = np.eye(d), np.zeros(d)
    acc = lambda F, b, f: np.asarray(model.topology.accelerations(  # noqa: E731
        jnp.asarray(F), model.masses, jnp.asarray(b, float), jnp.asarray(f)))
    G_F = np.stack([acc(eye[k], 0.0, z) for k in range(d)], 1)
    g_b = acc(z, 1.0, z)
    G_f = np.stack([acc(z, 0.0, eye[k]) for k in range(d)], 1)
    return G_F, g_b, G_f
