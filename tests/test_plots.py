"""Figures: basin maps keep one colour per configuration across maps; `ax=` draws into a notebook's axes."""

import numpy as np
from matplotlib.figure import Figure

import gmr_jax as gmr


def _colour_of(fig, label):
    ax = fig.axes[0]
    leg = ax.get_legend()
    for text, handle in zip(leg.get_texts(), leg.legend_handles):
        if text.get_text() == label:
            return tuple(np.round(handle.get_facecolor(), 6))
    raise AssertionError(label)


def test_basin_colours_stable_across_maps_and_ax():
    f, A = np.linspace(1, 2, 4), np.linspace(0.1, 0.2, 3)
    full = np.array([[0, 1, 2, 3], [3, 2, 1, 0], [-1, 0, 1, 2]])
    part = np.array([[2, 2, 3, 3], [3, 3, 2, 2], [2, 3, 2, 3]])  # configurations 0, 1 absent
    a = gmr.plots.basin_figure(f, A, full, 2)
    host = Figure()
    ax = host.subplots()
    b = gmr.plots.basin_figure(f, A, part, 2, ax=ax)
    assert b is host and len(host.axes) == 1
    for label in ("0-1", "1-1"):  # configs 2 and 3
        assert _colour_of(a, label) == _colour_of(b, label)
    assert _colour_of(a, "not settled / failed") == tuple(np.round((0.15, 0.15, 0.15, 1.0), 6))
    assert gmr.plots.config_colour(5, 3) != gmr.plots.config_colour(6, 3)
