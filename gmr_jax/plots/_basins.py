"""Basin picture: final configuration over the (f, A) grid, coloured by configuration."""

import matplotlib
import numpy as np
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from .._errors import GMRInputError
from ._save import save_with_pdf


def _digits(config: int, n_dof: int, base: int) -> list[int]:
    return [(config // base**i) % base for i in range(n_dof)]


def config_code(digits, base: int) -> int:
    """The configuration code of per-cell well indices (cell 0 first) in `base` (`_digits`' inverse; as
    `BasinMap.config` encodes them)."""
    return int(sum(int(k) * base**i for i, k in enumerate(digits)))


def config_label(config: int, n_dof: int, base: int = 2) -> str:
    """0-1-1-0-0 style name (cell 0 first) of a configuration code (`BasinMap.config`: a bit
    field for bistable cells; digits in `base` K with K wells per cell, e.g. 0-2 for a tri-stable
    cell 1 in its third well)."""
    if config < 0:
        return "not settled / failed"
    return "-".join(str(d) for d in _digits(int(config), n_dof, base))


def config_colour(config: int, n_dof: int, base: int = 2) -> tuple:
    """The colour of a configuration, the same in every figure of an `n_dof` structure (it does
    not depend on which configurations a map happens to contain); dark grey: not settled."""
    if config < 0:
        return (0.15, 0.15, 0.15, 1.0)
    n_all = base**n_dof
    if n_all <= 20:
        return matplotlib.colormaps["tab20"](config)
    return matplotlib.colormaps["nipy_spectral"](0.05 + 0.9 * config / (n_all - 1))


def well_base(wells) -> int:
    """The digit base of `BasinMap.config` for stable equilibria `wells` ((dof, k), NaN-padded):
    the most wells of any DOF (at least 2)."""
    w = np.asarray(wells, float)
    w = w.reshape(1, -1) if w.ndim < 2 else w
    return max(2, w.shape[1])


def well_label(config: int, n_dof: int, wells=None) -> str:
    """`config_label`, with the well's position for one DOF where `wells` ((dof, k) stable equilibria) is given:
    "1 (x = 1.131)"."""
    base = 2 if wells is None else well_base(wells)
    label = config_label(config, n_dof, base)
    if wells is None or n_dof != 1 or config < 0:
        return label
    w = np.asarray(wells, float).reshape(1, -1)[0]
    w = w[np.isfinite(w)]
    return f"{label} (x = {w[config]:.4g})" if config < w.size else label


def basin_figure(f, A, config, n_dof: int, path=None, title: str = "", *, ax=None, wells=None, load: str | None = None,
                 extrapolated_above: float | None = None) -> Figure:
    """The final configuration over the (f, A) grid, one colour per configuration (legend in
    the 0-1-1-0-0 style, cell 0 first; dark grey: not settled or failed). A configuration has
    the same colour in every figure of the structure (`config_colour`), so maps side by side
    (model vs truth) compare by eye. Draws into `ax` when given (a notebook's own layout), else
    a new figure. Saved to `path` when given (and as PDF beside it); returns the `Figure`. `wells`: the stable
    equilibria per DOF ((dof, k), NaN-padded), for a one-DOF legend that says where each well is,
    and the digit base of the configuration codes where a DOF has more than two wells (without
    them the codes are read as bit fields, and a code beyond 2^n_dof is refused). `load`: "tip" (A a force, N)
    or "base" (A a base acceleration, m/s^2), for the amplitude axis's unit (None: both named). `extrapolated_above`: the amplitude
    above which the load's static deflection alone leaves the range the model was fitted on; that part of the map
    is the model's extrapolation and is hatched. The frequency axis starts at 0 Hz."""
    config = np.asarray(config)
    base = 2 if wells is None else well_base(wells)
    if config.size and int(config.max()) >= base**n_dof:
        raise GMRInputError(f"configuration code {int(config.max())} is beyond the bit fields of {n_dof} bistable "
                            f"DOF(s): a DOF has more than two wells; pass wells=... (the sweep's wells) so that the "
                            f"codes are read in their base")
    values = sorted(set(config.ravel().tolist()))
    index = {v: k for k, v in enumerate(values)}
    img = np.vectorize(index.get)(config)
    colors = [config_colour(v, n_dof, base) for v in values]
    cmap = ListedColormap(colors)
    norm = BoundaryNorm(np.arange(len(values) + 1) - 0.5, len(values))
    if ax is None:
        fig = Figure(figsize=(7.5 if len(values) <= 16 else 10, 5), layout="constrained")
        ax = fig.subplots()
    else:
        fig = ax.figure
    ax.pcolormesh(np.asarray(f), np.asarray(A), img, cmap=cmap, norm=norm, shading="auto")
    handles = [Rectangle((0, 0), 1, 1, color=colors[k]) for k in range(len(values))]
    ax.legend(handles, [well_label(v, n_dof, wells) for v in values], title="final configuration",
              bbox_to_anchor=(1.02, 1), loc="upper left", fontsize=7, ncol=1 if len(values) <= 16 else 2)
    f_arr, A_arr = np.asarray(f, float), np.asarray(A, float)
    if extrapolated_above is not None and A_arr.size and extrapolated_above < A_arr.max():
        step = float(np.diff(A_arr).max()) if A_arr.size > 1 else 0.0
        top = float(A_arr.max()) + 0.5 * step
        lo = max(float(extrapolated_above), float(A_arr.min()) - 0.5 * step)
        ax.add_patch(Rectangle((0.0, lo), float(f_arr.max()) * 2 + 1.0, top - lo, fill=False, hatch="///",
                               edgecolor="w", lw=0.0))
        ax.axhline(lo, color="w", ls="--", lw=1.2)
        handles.append(Rectangle((0, 0), 1, 1, facecolor="0.5", hatch="///", edgecolor="w"))
        ax.legend(handles, [well_label(v, n_dof, wells) for v in values] + ["extrapolated (beyond the fitted x)"],
                  title="final configuration", bbox_to_anchor=(1.02, 1), loc="upper left", fontsize=7,
                  ncol=1 if len(values) <= 16 else 2)
    if f_arr.size:
        ax.set_xlim(0.0, float(f_arr.max()) + (0.5 * float(np.diff(f_arr).max()) if f_arr.size > 1 else 0.0))
    ax.set_xlabel("actuation frequency f [Hz]")
    ax.set_ylabel("actuation amplitude A " + {"base": "[m/s²] (base acceleration)", "tip": "[N] (tip force)"}.get(
        load, "[N] (tip force; m/s² for a base load)"))
    ax.set_title(title or "deployment basins (tip half-sine, Eq. 25)")
    if path is not None:  # PNG (or the suffix given) and a PDF beside it
        save_with_pdf(fig, path)
    return fig


def counts_figure(f, A, counts, path=None, title: str = "", *, ax=None, load: str | None = None) -> Figure:
    """A lattice's basin map: per (f, A) point the number of elements outside their first well
    (`BasinMap.counts`; dark grey: not settled or failed), one colour per count. Draws into `ax`
    when given, else a new figure; saved to `path` (and a PDF beside it) when given."""
    counts = np.asarray(counts)
    values = sorted(set(counts.ravel().tolist()))
    index = {v: k for k, v in enumerate(values)}
    img = np.vectorize(index.get)(counts)
    top = max(1, max(values))
    cm = matplotlib.colormaps["viridis"]
    colors = [(0.25, 0.25, 0.25, 1.0) if v < 0 else cm(v / top) for v in values]
    if ax is None:
        fig = Figure(figsize=(7.5, 5), layout="constrained")
        ax = fig.subplots()
    else:
        fig = ax.figure
    ax.pcolormesh(np.asarray(f), np.asarray(A), img, cmap=ListedColormap(colors),
                  norm=BoundaryNorm(np.arange(len(values) + 1) - 0.5, len(values)), shading="auto")
    handles = [Rectangle((0, 0), 1, 1, color=c) for c in colors]
    ax.legend(handles, ["not settled" if v < 0 else str(v) for v in values], title="elements switched",
              bbox_to_anchor=(1.02, 1), loc="upper left", fontsize=7, ncol=1 if len(values) <= 16 else 2)
    ax.set_xlabel("actuation frequency f [Hz]")
    ax.set_ylabel("actuation amplitude A " + ("[m/s²] (base acceleration)" if load == "base" else "[N] (node force)"))
    ax.set_title(title or "lattice basins (half-sine, Eq. 25)")
    if path is not None:
        save_with_pdf(fig, path)
    return fig
