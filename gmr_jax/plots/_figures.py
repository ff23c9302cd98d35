"""Figures in the style of the paper's Figs. 4-7: restoring-force curves and damping-error maps."""

import numpy as np
from matplotlib.figure import Figure

from ..metrics._metrics import _grid_forces, damping_error_map
from ._band import draw_restoring_band


def case_figure(system, models: dict, recordings, path=None, dof: int = 0, title: str = "") -> Figure:
    """One row: restoring force (truth, each model with its 95 % band when it has a covariance,
    `band_figure`; the ranges the data covered) and, per
    model, the damping-error map e_d = log10|F_d - F_d,true| (Eq. 22) on the phase plane.
    Saved to `path` when given; returns the matplotlib `Figure`."""
    truth = system.truth
    xr, vr = system.x_range[dof], system.v_range[dof]
    n = 1 + len(models)
    fig = Figure(figsize=(4.6 * n, 3.8), layout="constrained")
    axes = fig.subplots(1, n)
    ax = axes[0]
    xs = np.linspace(*xr, 400)
    ax.plot(xs, _grid_forces(truth, dof, xs, np.zeros(1), "restoring")[:, 0], "k-", lw=2.5, label="truth")
    styles = ["r--", "b:", "g-."]
    for (name, m), st in zip(models.items(), styles):
        ax.plot(xs, _grid_forces(m, dof, xs, np.zeros(1), "restoring")[:, 0], st, lw=1.8, label=name)
        draw_restoring_band(ax, m, dof, xs, color=st[0], label=name)  # when the model has a covariance
    f_true = _grid_forces(truth, dof, xs, np.zeros(1), "restoring")[:, 0]
    span = np.ptp(f_true)
    ax.set_ylim(f_true.min() - 0.3 * span, f_true.max() + 0.3 * span)
    for r in recordings:
        lo, hi = np.min(r.x[:, dof]), np.max(r.x[:, dof])
        ax.axvspan(lo, hi, color="orange", alpha=0.35, lw=0)
    ax.axhline(0, color="0.7", lw=0.8)
    ax.set_xlabel(system.units[0])
    ax.set_ylabel("restoring force " + system.units[2])
    ax.set_title("restoring force (orange: data range)")
    ax.legend(fontsize=8)
    for ax, (name, m) in zip(axes[1:], models.items()):
        xg, vg, e, _ = damping_error_map(m, truth, dof, xr, vr, n=121)
        im = ax.pcolormesh(xg, vg, e.T, shading="auto", cmap="viridis", vmin=-6, vmax=3)
        for r in recordings:
            ax.plot(r.x[::5, dof], r.v[::5, dof], ",", color="w", alpha=0.5)
        ax.set_xlabel(system.units[0])
        ax.set_ylabel(system.units[1])
        ax.set_title(f"{name}: log10|F_d error|")
        fig.colorbar(im, ax=ax, label=f"log10 |F_d error| ({system.units[2]})")
    if title:
        fig.suptitle(title)
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig
