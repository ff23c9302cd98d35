"""The global model with its 95 % band (issue 15): restoring force and damping force."""

import jax
import jax.numpy as jnp
import numpy as np
from matplotlib.figure import Figure

from .._errors import GMRInputError
from .._model._uncertainty import force_band


def _along(model, dof: int, xs, vs, part: str, level: float):
    d = model.n_dof
    x = jnp.zeros((xs.size, d)).at[:, dof].set(jnp.asarray(xs))
    v = jnp.zeros((xs.size, d)).at[:, dof].set(jnp.asarray(vs))
    b = jax.vmap(lambda p, q: force_band(model, p, q, part=part, level=level))(x, v)
    return tuple(np.asarray(a)[:, dof] for a in (b.mean, b.lower, b.upper))


def draw_restoring_band(ax, model, dof: int, xs, level: float = 0.95, color: str = "r", label: str = "model"):
    """Shade the `level` band of the restoring force of `dof` over `xs` on `ax` (no-op for a
    model without a covariance); returns whether it drew."""
    if getattr(model, "covariance", None) is None:
        return False
    _, lo, up = _along(model, dof, np.asarray(xs), np.zeros_like(np.asarray(xs)), "restoring", level)
    ax.fill_between(xs, lo, up, color=color, alpha=0.2, lw=0, label=f"{label}: {100 * level:g} % band")
    return True


def band_figure(model, dof: int = 0, x_range=None, *, speeds=None, truth=None, recordings=None,
                level: float = 0.95, path=None, title: str = "") -> Figure:
    """The model's restoring force F_r(x) and damping force F_d(x, v) at a few speeds, each with
    its `level` band (`force_band`, from `GlobalModel.covariance`), the truth when given, and
    the ranges the data covered.

    **Arguments:**

    - `model`: a `GlobalModel` with a covariance (from `reconstruct` or a model file that has one).
    - `dof`, `x_range`: the DOF and the (lo, hi) deformation range drawn (default: the model's
      stable wells widened by half their span on each side; give it for a model with fewer
      than two wells).
    - `speeds`: velocities at which F_d(x, v) is drawn (default: 3 values up to the recordings'
      largest |v| of this DOF, else 1).
    - `truth`: optional mechanical model drawn beside it; `recordings`: shade their x ranges.

    Saved to `path` when given; returns the matplotlib `Figure`.
    """
    if getattr(model, "covariance", None) is None:
        raise GMRInputError("band_figure: the model has no covariance (no band to draw); use a model from "
                            "gmr_jax.reconstruct or a model file written with its covariance")
    if x_range is None:
        from .._basins._wells import stable_wells

        w = stable_wells(model)[dof]
        w = w[np.isfinite(w)]
        if w.size < 2:
            raise GMRInputError("band_figure: give x_range=(lo, hi): the model has fewer than two stable wells "
                                f"for DOF {dof}")
        half = 0.5 * (w.max() - w.min())
        x_range = (w.min() - half, w.max() + half)
    xs = np.linspace(float(x_range[0]), float(x_range[1]), 400)
    if speeds is None:
        vmax = max((float(np.max(np.abs(r.v[:, dof]))) for r in recordings or [] if r.v is not None), default=1.0)
        speeds = vmax * np.array([0.33, 0.67, 1.0])
    fig = Figure(figsize=(10.0, 3.8), layout="constrained")
    ax1, ax2 = fig.subplots(1, 2)
    mean, lo, up = _along(model, dof, xs, np.zeros_like(xs), "restoring", level)
    ax1.fill_between(xs, lo, up, color="r", alpha=0.25, lw=0, label=f"{100 * level:g} % band")
    ax1.plot(xs, mean, "r-", lw=1.5, label="model")
    if truth is not None:
        _, tr = _truth(truth, dof, xs, np.zeros_like(xs))
        ax1.plot(xs, tr, "k--", lw=1.5, label="truth")
    for r in recordings or []:
        ax1.axvspan(np.min(r.x[:, dof]), np.max(r.x[:, dof]), color="orange", alpha=0.3, lw=0)
    ax1.axhline(0, color="0.7", lw=0.8)
    ax1.set_xlabel("x")
    ax1.set_ylabel("restoring force F_r")
    ax1.set_title("restoring force" + (" (orange: data range)" if recordings else ""))
    ax1.legend(fontsize=8)
    colors = ["tab:blue", "tab:green", "tab:purple", "tab:brown"]
    for k, s in enumerate(np.asarray(speeds, float)):
        c = colors[k % len(colors)]
        vs = np.full_like(xs, s)
        mean, lo, up = _along(model, dof, xs, vs, "damping", level)
        ax2.fill_between(xs, lo, up, color=c, alpha=0.25, lw=0)
        ax2.plot(xs, mean, "-", color=c, lw=1.5, label=f"v = {s:.3g}")
        if truth is not None:
            ax2.plot(xs, _truth(truth, dof, xs, vs)[0], "--", color=c, lw=1.2)
    ax2.set_xlabel("x")
    ax2.set_ylabel("damping force F_d(x, v)")
    ax2.set_title(f"damping force with {100 * level:g} % bands" + (" (dashed: truth)" if truth is not None else ""))
    ax2.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


def _truth(truth, dof, xs, vs):
    d = truth.n_dof
    x = jnp.zeros((xs.size, d)).at[:, dof].set(jnp.asarray(xs))
    v = jnp.zeros((xs.size, d)).at[:, dof].set(jnp.asarray(vs))
    damp = np.asarray(jax.vmap(truth.damping)(x, v))[:, dof]
    rest = np.asarray(jax.vmap(truth.restoring)(x))[:, dof]
    return damp, rest
