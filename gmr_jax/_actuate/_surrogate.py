"""Targets, saddles and the smooth terminal surrogate of "the chain ended in the target wells".

The exact outcome of an actuation is discrete: simulate, let the chain settle, classify every
cell into a well (`gmr_jax._basins._sweep.classify`). Gradients need a smooth stand-in. Per cell
i with saddle s_i between its two wells and half interwell distance h_i, the signed margin

    m_i = sigma_i (x_i(t1) - s_i) / h_i,    sigma_i = +1 if the target is the second well, else -1,

is positive when the cell is on the target side of its saddle at the end of the settle time,
and the chain's margin is their soft minimum m = -tau log sum_i exp(-m_i / tau) (positive only
when every cell is on its target side). Where the model has sgn(v) terms (a `GlobalModel` with
`velocity_damping` of even order), the differentiated solve uses the model with sgn(v) replaced
by tanh(v / `sign_eps`) (`GlobalModel.with_sign_eps`); every outcome that is reported (sweeps,
bisections, verification) is computed with the exact model.

Why a settled-state margin still carries a useful gradient: inside a basin the settled state
does not depend on the load, so m is flat; across a basin boundary it jumps. Near a boundary
point, though, the trajectory passes close to a saddle of the chain and every sensitivity of the
final state goes through the one unstable direction of that saddle, dx(t1)/dp ~ w * dg/dp with
g(p) = 0 the boundary. The *ratio* of the partial derivatives of m is then the boundary's normal
direction, whatever its (huge) scale: that is what the optimizer uses (`_actuate.py`).
"""

import re

import jax
import jax.numpy as jnp
import numpy as np

from .._errors import GMRInputError
from .._model._model import AbstractMechanicalModel, GlobalModel


def parse_target(target, n_dof: int) -> np.ndarray:
    """`"0-1-1-0-0"` (cell 0 first, as `config_label` writes it), `"01100"`, a sequence of 0/1,
    or an int bit field -> (dof,) array of 0/1. Raises `GMRInputError` on a malformed target."""
    if isinstance(target, (int, np.integer)) and not isinstance(target, bool):
        if target < 0 or target >= 2**n_dof:
            raise GMRInputError(f"target bit field {target} is outside [0, 2^{n_dof}) for a {n_dof}-cell chain")
        return np.array([(int(target) >> i) & 1 for i in range(n_dof)])
    if isinstance(target, str):
        s = target.strip()
        parts = s.split("-") if "-" in s else list(s)
        if not re.fullmatch(r"[01](-?[01])*", s) or any(p not in ("0", "1") for p in parts):
            raise GMRInputError(
                f"target {target!r} must be one 0 or 1 per cell, cell 0 (at the base) first, "
                f"e.g. {'-'.join(['0', '1'] * n_dof)[: 2 * n_dof - 1]!r}"
            )
        bits = [int(p) for p in parts]
    else:
        bits = [int(b) for b in np.asarray(target).reshape(-1)]
        if any(b not in (0, 1) for b in bits):
            raise GMRInputError(f"target {target!r} must contain only 0 and 1")
    if len(bits) != n_dof:
        raise GMRInputError(f"target {target!r} has {len(bits)} cells but the model has {n_dof}")
    return np.asarray(bits)


def bits_to_config(bits) -> int:
    return int(sum(int(b) << i for i, b in enumerate(np.asarray(bits).reshape(-1))))


def saddles(model: AbstractMechanicalModel, wells: np.ndarray, n: int = 4001) -> np.ndarray:
    """Unstable zero of each cell's restoring force between its first two wells (dof,)
    (a decreasing crossing of F_i; the wells' midpoint if none is found)."""
    wells = np.asarray(wells, float)
    d = wells.shape[0]
    out = np.empty(d)
    for i in range(d):
        lo, hi = wells[i, 0], wells[i, 1]
        xs = np.linspace(lo, hi, n)
        fx = np.asarray(jax.vmap(lambda x, i=i: model.restoring(jnp.zeros(d).at[i].set(x))[i])(jnp.asarray(xs)))
        idx = np.nonzero((fx[:-1] > 0) & (fx[1:] <= 0))[0]
        if idx.size == 0:
            out[i] = 0.5 * (lo + hi)
            continue
        k = idx[np.argmin(np.abs(xs[idx] - 0.5 * (lo + hi)))]
        out[i] = xs[k] - fx[k] * (xs[k + 1] - xs[k]) / (fx[k + 1] - fx[k])
    return out


def needs_smoothing(model: AbstractMechanicalModel) -> bool:
    """True when the model has sgn(v)|v|^j terms that are not smooth in v (j even)."""
    if not isinstance(model, GlobalModel):
        return False
    vd = np.asarray(model.velocity_damping)
    return bool(np.any(vd[:, 0::2] != 0.0))


def smooth_model(model: AbstractMechanicalModel, sign_eps: float) -> AbstractMechanicalModel:
    """The model used inside differentiated solves (sgn(v) -> tanh(v / sign_eps) if needed)."""
    return model.with_sign_eps(sign_eps) if needs_smoothing(model) else model


def terminal_margin(x1, sigma, saddle, half, tau):
    """Soft minimum over cells of sigma_i (x_i - s_i) / h_i (see the module docstring)."""
    m = sigma * (x1 - saddle) / half
    return -tau * jax.scipy.special.logsumexp(-m / tau)
