"""Figures in the style of the paper's Figs. 4-7: restoring-force curves and damping-error maps."""

import numpy as np
from matplotlib.figure import Figure

from ..metrics._metrics import _grid_forces, damping_error_map


def case_figure(system, models: dict, recordings, path=None, dof: int = 0, title: str = "") -> Figure:
    """One row per case, in the style of the paper's Figs. 4-7.

    - Left, top: the restoring force of the truth and of each model (each its own line style and marker),
      each model's 95 % band where it has a covariance, and the ranges the data covered.
    - Left, below: each model minus the truth, with its band about zero (a band 100 times narrower than
      the force is visible here).
    - Then, per model, the damping-error map e_d = log10|F_d - F_d,true| (Eq. 22) on the phase plane,
      with the recorded (x, v) points; one colour range per figure, from the maps' own values, with a
      labelled colour bar.

    Saved to `path` when given; returns the matplotlib `Figure`."""
    truth = system.truth
    xr, vr = system.x_range[dof], system.v_range[dof]
    n = 1 + len(models)
    fig = Figure(figsize=(4.8 * n, 5.2), layout="constrained")
    grid = fig.add_gridspec(2, n, height_ratios=[2.2, 1.0])
    ax = fig.add_subplot(grid[0, 0])
    ax_res = fig.add_subplot(grid[1, 0], sharex=ax)
    xs = np.linspace(*xr, 400)
    f_true = _grid_forces(truth, dof, xs, np.zeros(1), "restoring")[:, 0]
    ax.plot(xs, f_true, "k-", lw=2.5, label="truth")
    styles = [("tab:red", "--", "o"), ("tab:blue", ":", "s"), ("tab:green", "-.", "^")]
    for k, ((name, m), (col, ls, mk)) in enumerate(zip(models.items(), styles)):
        f_m = _grid_forces(m, dof, xs, np.zeros(1), "restoring")[:, 0]
        ax.plot(xs, f_m, color=col, ls=ls, marker=mk, markevery=(10 * k, 50), ms=5, lw=1.8, label=name)
        ax_res.plot(xs, f_m - f_true, color=col, ls=ls, marker=mk, markevery=(10 * k, 50), ms=4, lw=1.4,
                    label=name)
        if getattr(m, "covariance", None) is not None:
            from ._band import _along

            _, lo, up = _along(m, dof, xs, np.zeros_like(xs), "restoring", 0.95)
            ax.fill_between(xs, lo, up, color=col, alpha=0.25, lw=0, label=f"{name}: 95 % band")
            ax_res.fill_between(xs, lo - f_m, up - f_m, color=col, alpha=0.25, lw=0)
    span = np.ptp(f_true)
    ax.set_ylim(f_true.min() - 0.3 * span, f_true.max() + 0.3 * span)
    for k, r in enumerate(recordings):
        lo, hi = np.min(r.x[:, dof]), np.max(r.x[:, dof])
        ax.axvspan(lo, hi, color="orange", alpha=0.35, lw=0, label="recorded x range" if k == 0 else None)
    for a in (ax, ax_res):
        a.axhline(0, color="0.7", lw=0.8)
    ax_res.set_xlabel(system.units[0])
    ax.set_ylabel("restoring force " + system.units[2])
    ax_res.set_ylabel("model - truth " + system.units[2], fontsize=8)
    ax.set_title("restoring force")
    ax.legend(fontsize=7)
    ax_res.set_title("model - truth (shaded: the model's 95 % band)", fontsize=8)
    maps = [damping_error_map(m, truth, dof, xr, vr, n=121) for m in models.values()]
    vals = np.concatenate([np.ravel(e[2])[np.isfinite(np.ravel(e[2]))] for e in maps]) if maps else np.zeros(1)
    vmin, vmax = (np.percentile(vals, [1, 99]) if vals.size else (-6.0, 3.0))
    vmax = max(vmax, vmin + 1e-6)
    for k, ((name, _), (xg, vg, e, _)) in enumerate(zip(models.items(), maps)):
        axm = fig.add_subplot(grid[:, 1 + k])
        im = axm.pcolormesh(xg, vg, e.T, shading="auto", cmap="viridis", vmin=vmin, vmax=vmax)
        for j, r in enumerate(recordings):
            axm.plot(r.x[::5, dof], r.v[::5, dof], ".", ms=1.5, color="w", alpha=0.6,
                     label="recorded (x, v)" if j == 0 else None)
        axm.set_xlabel(system.units[0])
        axm.set_ylabel(system.units[1])
        axm.set_title(f"{name}: damping error e_d (Eq. 22)")
        if recordings:
            axm.legend(fontsize=7, loc="upper right", markerscale=6, facecolor="0.3", labelcolor="w")
        unit = system.units[2].split("[")[-1].rstrip("]") if "[" in system.units[2] else "force units"
        fig.colorbar(im, ax=axm, label=f"e_d = log10 |F_d - F_d,true|, F in {unit}")
    if title:
        fig.suptitle(title)
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig
