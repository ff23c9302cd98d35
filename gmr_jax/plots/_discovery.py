"""Figures of a discovery report: where the residual sits, before and after."""

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from .._discover._report import _cell
from ._save import save_with_pdf


def discovery_figures(report, out_dir) -> list[str]:
    """Residual maps on the (x, v) plane per cell (before/after), residual vs time and its
    spectrum, and the holdout before/after, each as PNG and PDF. Returns the PNG names."""
    from scipy.signal import welch

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    names = []
    d = report.given.n_dof
    fig = Figure(figsize=(9, 3.6 * d))
    axes = fig.subplots(d, 2, squeeze=False)
    for i in range(d):
        for k, key in enumerate(("before", "after")):
            m = report.location[i][key]["map"]
            arr = np.array(m["mean"], float)
            lim = np.nanmax(np.abs(np.array(report.location[i]["before"]["map"]["mean"], float)))
            ax = axes[i, k]
            im = ax.imshow(arr, origin="lower", aspect="auto", cmap="RdBu_r", vmin=-lim, vmax=lim,
                           extent=[m["x_edges"][0], m["x_edges"][-1], m["v_edges"][0], m["v_edges"][-1]])
            ax.set_title(f"{_cell(report, i)}: mean residual force, {key}")
            ax.set_xlabel("x")
            ax.set_ylabel("v")
            fig.colorbar(im, ax=ax, label="mean residual force (recording's force units)")
    fig.tight_layout()
    save_with_pdf(fig, out / "residual_map.png")
    names.append("residual_map.png")

    s = report.series
    fig = Figure(figsize=(11, 3.2 * d))
    axes = fig.subplots(d, 2, squeeze=False)
    for i in range(d):
        rb, ra = s["resid_before"][i], s["resid_after"][i]
        t = np.arange(rb.size) * s["dt"]
        axes[i, 0].plot(t, rb, lw=0.5, label="given model")
        axes[i, 0].plot(t, ra, lw=0.5, label="augmented")
        axes[i, 0].set_xlabel("time (s, estimation rows concatenated)")
        axes[i, 0].set_ylabel("residual force")
        axes[i, 0].legend(fontsize=8)
        for r, lab in ((rb, "given model"), (ra, "augmented")):
            f, p = welch(r, fs=1 / s["dt"], nperseg=min(1024, r.size))
            axes[i, 1].semilogy(f, p, label=lab)
        axes[i, 1].set_xlabel("frequency (Hz)")
        axes[i, 1].set_ylabel("residual PSD")
        axes[i, 1].set_title(_cell(report, i))
    fig.tight_layout()
    save_with_pdf(fig, out / "residual_time_frequency.png")
    names.append("residual_time_frequency.png")

    sims_b, sims_a = s.get("sims", (None, None))
    hold = s.get("holdout")
    if hold:
        r0 = hold[0]
        fig = Figure(figsize=(10, 2.8 * d))
        axes = fig.subplots(d, 1, squeeze=False)
        for i in range(d):
            ax = axes[i, 0]
            if report.before["kind"] == "output":
                src = (r0.integration or {}).get("from")
                ax.plot(r0.t, r0.x[:, i] - (r0.x[:, i].mean() if src else 0.0), "k", lw=0.8,
                        label=f"integrated from {src} (drift removed)" if src else "measured")
                ax.plot(r0.t[r0.t.size - sims_b[0].shape[0]:], sims_b[0][:, i], lw=0.7, label=f"given model ({100 * report.before['nrmse']:.3g} %)")
                ax.plot(r0.t[r0.t.size - sims_a[0].shape[0]:], sims_a[0][:, i], lw=0.7, label=f"augmented ({100 * report.after['nrmse']:.3g} %)")
                ax.set_ylabel("x")
            else:
                from .._discover._equation import dof_rows

                st = report.settings
                rb = dof_rows(r0, report.given, i, [], form="strong", decimate=st["decimate"])
                ra = dof_rows(r0, report.model, i, [], form="strong", decimate=st["decimate"])
                tt = np.arange(rb.y.size) * s["dt"]
                ax.plot(tt, rb.target, "k", lw=0.8, label="measured force")
                ax.plot(tt, rb.target - rb.y, lw=0.7, label=f"given model ({100 * report.before['nrmse']:.3g} %)")
                ax.plot(tt, ra.target - ra.y, lw=0.7, label=f"augmented ({100 * report.after['nrmse']:.3g} %)")
                ax.set_ylabel("force")
            ax.set_title(f"holdout {r0.name}, {_cell(report, i)} ({report.before['kind']} error)")
            ax.legend(fontsize=8)
        axes[-1, 0].set_xlabel("t (s)")
        fig.tight_layout()
        save_with_pdf(fig, out / "holdout_before_after.png")
        names.append("holdout_before_after.png")
    return names
