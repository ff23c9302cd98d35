"""The figure `gmr fit` writes: a fitted model against the recordings it was fitted on."""

import numpy as np
from matplotlib.figure import Figure

from .._model._predict import forces
from .._recordings._recording import regression_targets
from .._recordings._integrate import remove_drift

#: one colour, line style and marker per recording (well), reused in every panel: lines that coincide or print in
#: grey stay apart
COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:pink", "tab:olive")
STYLES = ("-", "--", ":", "-.")
MARKERS = ("o", "s", "^", "v", "D", "P", "X", "*")


def _linear_band(model, columns: slice, basis, level: float):
    """A force linear in the coefficients `columns` of each DOF's flat block (stiffness, velocity damping, position
    damping): `basis(*args)` -> (n, dof, p) columns; returns `*args -> (lower, upper)` of its `level` band from the
    model's covariance, the same numbers as `force_band`, in NumPy (no JAX program to trace for a figure); None
    without a covariance."""
    cov = getattr(model, "covariance", None)
    if cov is None:
        return None
    from statistics import NormalDist

    z = NormalDist().inv_cdf(0.5 + level / 2)
    blocks = (model.stiffness, model.velocity_damping, model.position_damping)
    coef = np.concatenate([np.asarray(b, float) for b in blocks], axis=1)[:, columns]
    c = np.asarray(cov, float)[:, columns, columns]

    def band(*args):
        phi = basis(*(np.asarray(a, float) for a in args))
        mean = np.einsum("ndk,dk->nd", phi, coef)
        se = np.sqrt(np.maximum(np.einsum("ndj,djk,ndk->nd", phi, c, phi), 0.0))
        return mean - z * se, mean + z * se

    return band


def _model_band(model, level: float = 0.95):
    """x (n, dof) -> (lower, upper) of the `level` band of F_r (`_linear_band`; F_r is linear in the stiffness
    block, the first ones of each DOF's covariance); None without a covariance."""
    ns = np.asarray(model.stiffness).shape[1]
    return _linear_band(model, slice(0, ns), lambda x: x[:, :, None] ** np.arange(ns), level)


def _damping_band(model, level: float = 0.95):
    """(x, v) (n, dof) each -> (lower, upper) of the `level` band of F_d (`_linear_band`; sgn(v)|v|^j and x^j v
    columns, as `force_band(part="damping")`, with the exact sign, not the smoothed one); None without a
    covariance."""
    ns, nv = np.asarray(model.stiffness).shape[1], np.asarray(model.velocity_damping).shape[1]
    npd = np.asarray(model.position_damping).shape[1]

    def basis(x, v):
        vel = np.sign(v)[:, :, None] * np.abs(v)[:, :, None] ** np.arange(nv)
        return np.concatenate([vel, x[:, :, None] ** np.arange(npd) * v[:, :, None]], axis=2)

    return _linear_band(model, slice(ns, ns + nv + npd), basis, level)


def _dress(ax, xlabel: str, ylabel: str, title: str) -> None:
    """The zero line, labels, title and legend every panel of the figure carries."""
    ax.axhline(0.0, color="0.7", lw=0.8)
    ax.locator_params(axis="x", nbins=5)  # labels of mm-scale data in m ('-0.015') overlapped at the default 7+
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, loc="best")


def fit_figure(model, recordings, path=None, *, title: str = "", x_unit: str = "x", force_unit: str = "force",
               band="auto", unit: str | None = None) -> Figure:
    """The fitted model against its training recordings, one row per DOF (cell):

    - restoring force F_r(x) over the data's span and a quarter of it beyond, with the
      displacement range each recording covered shaded in its colour and the model's
      equilibria (zeros of F_r) marked;
    - damping force F_d(x_i, v) at each recording's mean displacement x_i, over 1.5x the
      speeds it reached (recorded speed range shaded);
    - residual: measured force carried by the DOF (the regression target, Eq. 8) minus the
      model's F(x, v), against time, with its NRMSE per recording (an x integrated from v or a: above its drift
      cut-off, the band the fit uses).

    `recordings`: the `Recording`s the model was fitted on (v and a are estimated where
    missing, as `reconstruct` does). `band`: "auto" (default) draws the model's 95 % bands of
    F_r and F_d (`force_band`) when it carries a covariance (`reconstruct` sets one); None draws none;
    or a callable `x (n, dof) -> (lower, upper)`, each (n, dof), for F_r (then no band on F_d). The band's
    half-width is also drawn on its own axis (right), where it is too narrow to see beside the force. `unit`: the
    recordings' length unit ("mm"), written on every axis (default: the recordings' own, where their files named
    one). Saved (PNG, or PDF by suffix) to `path` when given; returns the matplotlib `Figure`."""
    if unit is None:
        unit = next((r.length_unit for r in recordings if getattr(r, "length_unit", None)), None)
    lu = f" [{unit}]" if unit else ""
    if unit and force_unit == "force":  # the model's forces are mass x length / s^2 in the recordings' units
        force_unit = f"mass x {unit}/s²"
    vu = f" [{unit}/s]" if unit else f" ({x_unit}/s)"
    masses = np.asarray(model.masses, float)
    recs = [r.complete(model.topology) for r in recordings]
    targets = [regression_targets(r, masses, model.topology) for r in recs]  # from a and the inputs, not x
    auto = isinstance(band, str) and band == "auto"
    band = _model_band(model) if auto else band
    damping_band = _damping_band(model) if auto else None
    d = model.n_dof
    height = 3.0 * d + 0.7
    fig = Figure(figsize=(13.5, height))  # fixed margins: a constrained layout doubles the time to save
    fig.subplots_adjust(left=0.06, right=0.99, wspace=0.55, hspace=0.55, top=1 - 0.62 / height,
                        bottom=0.5 / height)
    axes = np.atleast_2d(fig.subplots(d, 3, squeeze=False))
    for i in range(d):
        ax_r, ax_d, ax_e = axes[i]
        lo = min(float(np.min(r.x[:, i])) for r in recs)
        hi = max(float(np.max(r.x[:, i])) for r in recs)
        pad = 0.25 * max(hi - lo, 1e-12)
        xs = np.linspace(lo - pad, hi + pad, 400)
        X = np.zeros((xs.size, d))
        X[:, i] = xs
        fr = forces(model, X, parts=True)[0][:, i]
        ax_r.plot(xs, fr, "k-", lw=1.8, label="model F_r")
        if band is not None:
            blo, bhi = (np.asarray(b)[:, i] for b in band(X))
            half = 0.5 * float(np.max(bhi - blo))
            ax_r.fill_between(xs, blo, bhi, color="0.6", alpha=0.4, lw=0, label=f"95 % band (half-width <= {half:.2g})")
            tw = ax_r.twinx()  # the band beside a force 100-1000 times its width is a line: its half-width on its own
            tw.plot(xs, 0.5 * (bhi - blo), color="tab:red", ls="--", lw=1.0)
            tw.set_ylim(0.0, 1.15 * max(half, 1e-300))
            tw.set_ylabel("95 % band half-width", color="tab:red", fontsize=7)
            tw.tick_params(axis="y", labelcolor="tab:red", labelsize=7)
            ax_r.plot([], [], color="tab:red", ls="--", lw=1.0, label="band half-width (right axis)")
        for k, r in enumerate(recs):
            col = COLOURS[k % len(COLOURS)]
            ax_r.axvspan(float(np.min(r.x[:, i])), float(np.max(r.x[:, i])), color=col, alpha=0.25, lw=0,
                         label=f"{r.name}: data range")
        sign = np.sign(fr)
        for z in np.nonzero(sign[:-1] * sign[1:] < 0)[0]:
            xz = xs[z] - fr[z] * (xs[z + 1] - xs[z]) / (fr[z + 1] - fr[z])
            stable = fr[z + 1] > fr[z]
            ax_r.plot([xz], [0.0], "o", ms=6, mfc="k" if stable else "w", mec="k")
        _dress(ax_r, f"{x_unit} (DOF {i}){lu}", f"restoring force ({force_unit})",
               "restoring force (filled o: stable, open: saddle)")

        for k, r in enumerate(recs):
            col = COLOURS[k % len(COLOURS)]
            vmax = float(np.max(np.abs(r.v[:, i]))) or 1.0
            vs = np.linspace(-1.5 * vmax, 1.5 * vmax, 300)
            Xv = np.tile(np.mean(r.x, axis=0), (vs.size, 1))
            V = np.zeros_like(Xv)
            V[:, i] = vs
            fd = forces(model, Xv, V, parts=True)[1][:, i]
            ax_d.plot(vs, fd, STYLES[k % len(STYLES)], color=col, lw=1.5, marker=MARKERS[k % len(MARKERS)],
                      markevery=(k * 7, 40), ms=4, label=f"{r.name} (x = {np.mean(r.x[:, i]):.3g}{lu})")
            if damping_band is not None:
                dlo, dhi = (np.asarray(b)[:, i] for b in damping_band(Xv, V))
                ax_d.fill_between(vs, dlo, dhi, color=col, alpha=0.35, lw=0)
            ax_d.axvspan(float(np.min(r.v[:, i])), float(np.max(r.v[:, i])), color=col, alpha=0.15, lw=0)
        _dress(ax_d, f"velocity{vu}", f"damping force ({force_unit})",
               "damping force at each well (light: recorded speeds" + ("; 95 % band)" if damping_band is not None
                                                                        else ")"))

        for k, r in enumerate(recs):
            col = COLOURS[k % len(COLOURS)]
            y = targets[k][:, i]
            fr_, fd_ = forces(model, r.x, r.v, parts=True)
            res = y - (fr_ + fd_)[:, i]
            # an x integrated from v or a lost its content below the drift cut-off: so does the residual shown
            cuts = (r.integration or {}).get("f_highpass_hz") if "x" in r.derived else None
            cut = float(cuts[i]) if cuts is not None and len(cuts) > i and cuts[i] else None
            if cut is not None:
                res, y = (remove_drift(a, float(r.dt), cut, keep_mean=True) for a in (res, y))
            nrmse = float(np.sqrt(np.sum(res**2) / max(np.sum((y - y.mean()) ** 2), 1e-300)))
            # envelope (min and max per bin of ~20 samples, 400 bins at most): every excursion
            # shows, and the figure stays light (a 10^5-sample line makes PDFs slow and heavy)
            nb = min(400, r.t.size)
            edges = np.linspace(0, r.t.size, nb + 1).astype(int)
            lo_, hi_ = np.minimum.reduceat(res, edges[:-1]), np.maximum.reduceat(res, edges[:-1])
            ax_e.fill_between(r.t[edges[:-1]], lo_, hi_, facecolor=col, alpha=0.5, lw=0, step="post",
                              hatch=(None, "////", "\\\\", "xx")[k % 4], edgecolor="w",
                              label=f"{r.name}: NRMSE {nrmse:.3g}" + (f" (above {cut:.2g} Hz, as fitted)"
                                                                         if cut is not None else ""))
        _dress(ax_e, "time (s)", f"measured - model ({force_unit})",
               "force residual: target (Eq. 8) - model (envelope)")
    if title:
        fig.suptitle(title)
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig
