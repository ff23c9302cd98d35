"""Figure of a free run (`gmr_jax.free_run`): simulated over measured displacement, and the
residual (model - data) below, per DOF."""

from matplotlib.figure import Figure

from ._save import save_with_pdf


def free_run_figure(run, path=None, *, x_unit: str = "recording units", title: str = "") -> Figure:
    """Two panels per DOF: measured and simulated x against time, and the residual
    x_model - x_measured, with its NRMSE in the legend. `path` (optional): the PNG to write; a
    PDF is written beside it."""
    d = run.x.shape[1]
    fig = Figure(figsize=(10, 3.9 * d), layout="constrained")
    axes = fig.subplots(2 * d, 1, sharex=True, squeeze=False, height_ratios=[2.2, 1] * d)[:, 0]
    for i in range(d):
        ax, ar = axes[2 * i], axes[2 * i + 1]
        ax.plot(run.t, run.x_measured[:, i], color="0.25", lw=1.0, label="measured")
        ax.plot(run.t, run.x[:, i], color="tab:red", lw=0.9, ls="--", marker="o", ms=3,
                markevery=max(run.t.size // 40, 1), label="model (free run)")
        ax.set_ylabel(f"$x_{{{i}}}$ ({x_unit})")
        ax.legend(loc="upper right", fontsize=8, ncols=2)
        extra = ""
        if run.horizon_nrmse is not None:
            extra = f"; runs of {run.horizon:.3g} s from the recorded state: {100 * run.horizon_nrmse[i]:.3g} %"
            if run.crossings is not None and run.crossings[0, i] >= 0:
                model = "-" if run.crossings[1, i] < 0 else int(run.crossings[1, i])
                extra += f"; well crossings {int(run.crossings[0, i])} measured, {model} free run"
        ax.set_title(f"DOF {i}: free-run NRMSE {100 * run.nrmse[i]:.3g} %{extra}", fontsize=10, loc="left")
        ax.grid(alpha=0.3)
        ar.plot(run.t, run.residual[:, i], color="tab:blue", lw=0.8, label="model - data")
        ar.axhline(0.0, color="0.5", lw=0.6)
        ar.set_ylabel(f"model - data\n({x_unit})")
        ar.grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(title or f"free run on {run.name}: model vs measurement", fontsize=11)
    if path is not None:
        from pathlib import Path

        save_with_pdf(fig, Path(path).with_suffix(".png"), dpi=120)
    return fig
