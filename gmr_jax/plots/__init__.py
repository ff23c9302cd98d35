"""Figures (matplotlib `Figure` objects, built without pyplot: importing this module does not
change the matplotlib backend). Each function saves to `path` when given and returns the
figure, which a notebook displays."""

from ._band import band_figure as band_figure
from ._basins import (basin_figure as basin_figure, config_colour as config_colour, config_label as config_label,
                      counts_figure as counts_figure)
from ._discovery import discovery_figures as discovery_figures
from ._figures import case_figure as case_figure
from ._fit import fit_figure as fit_figure
from ._free_run import free_run_figure as free_run_figure
